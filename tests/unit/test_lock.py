"""The archive's lock: exclusive to take, exclusive to take over, never stolen from the living."""

import json
import multiprocessing
import os
import socket

import pytest

from campipe.io.lock import ArchiveBusyError, lock_path, read_holder, writing

CONTENDERS = 6
ROUNDS = 200


def _dead_pid() -> int:
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
    return pid


def _stale(lock, pid: int) -> str:
    text = json.dumps({"pid": pid, "host": socket.gethostname(), "started": "2026-01-01T00:00:00Z"})
    lock.write_text(text)
    return text


def _contend(archive, rounds, start, tried, done, wins, index):
    for r in range(rounds):
        start.wait()
        try:
            with writing(archive):
                wins[r * CONTENDERS + index] = 1
                tried.wait()  # hold the lock until every contender has tried
        except ArchiveBusyError:
            tried.wait()
        done.wait()


def test_racing_takeovers_of_a_stale_lock_leave_exactly_one_holder(tmp_path):
    """200 rounds: a lock left by a dead process, six processes taking it over at once."""
    archive = tmp_path / "a.nc"
    lock = lock_path(archive)
    dead = _dead_pid()
    ctx = multiprocessing.get_context("fork")
    start, tried, done = (ctx.Barrier(CONTENDERS + 1, timeout=60) for _ in range(3))
    wins = ctx.Array("b", ROUNDS * CONTENDERS)
    procs = [
        ctx.Process(target=_contend, args=(archive, ROUNDS, start, tried, done, wins, i))
        for i in range(CONTENDERS)
    ]
    for p in procs:
        p.start()
    try:
        holders = []
        for r in range(ROUNDS):
            _stale(lock, dead)
            start.wait()
            tried.wait()
            holders.append(sum(wins[r * CONTENDERS : (r + 1) * CONTENDERS]))
            done.wait()
        assert holders == [1] * ROUNDS
        assert not lock.exists()  # each round's holder removed its lock
    finally:
        for p in procs:
            p.join(timeout=30)
            if p.is_alive():
                p.kill()
    assert [p.exitcode for p in procs] == [0] * CONTENDERS


def test_a_live_holders_lock_is_never_taken_over(tmp_path):
    archive = tmp_path / "a.nc"
    with writing(archive) as lock:
        mine = read_holder(lock)
        assert mine["pid"] == os.getpid()
        with pytest.raises(ArchiveBusyError, match=f"process {os.getpid()}"):
            with writing(archive):
                pass
        assert read_holder(lock) == mine
    assert not lock.exists()


@pytest.mark.parametrize("pid", [10**20, 0, -1, "12", 1.5, True])
def test_a_lock_naming_an_impossible_process_is_refused_with_a_message(tmp_path, pid):
    """Not taken over (it is not a lock campipe wrote), and no traceback: the message says to
    remove it."""
    archive = tmp_path / "a.nc"
    lock = lock_path(archive)
    text = _stale(lock, pid)
    with pytest.raises(ArchiveBusyError, match=r"does not name a process.*remove .*a\.nc\.lock"):
        with writing(archive):
            pass
    assert lock.read_text() == text


def test_a_stale_lock_is_taken_over_and_released(tmp_path):
    archive = tmp_path / "a.nc"
    lock = lock_path(archive)
    _stale(lock, _dead_pid())
    with writing(archive):
        assert read_holder(lock)["pid"] == os.getpid()
    assert not lock.exists()


def test_a_lock_replaced_by_another_run_is_not_removed_at_release(tmp_path):
    archive = tmp_path / "a.nc"
    with writing(archive) as lock:
        other = _stale(lock, 1)  # as if another run had (wrongly) taken it
    assert lock.read_text() == other


def test_a_symbolic_link_to_the_archive_shares_its_lock(tmp_path):
    """Two names of one archive (a symbolic link to it, or to its folder) hold one lock: the
    second run through the link stops at once. Broken copy: the lock beside the link's name
    (a helper's two runs both started, one failing mid-run)."""
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    (tmp_path / "real" / "a.nc").write_bytes(b"")
    (tmp_path / "b.nc").symlink_to(tmp_path / "real" / "a.nc")
    for other in (tmp_path / "link" / "a.nc", tmp_path / "b.nc"):
        with writing(tmp_path / "real" / "a.nc"):
            with pytest.raises(ArchiveBusyError):
                with writing(other):
                    pass
    assert lock_path(tmp_path / "b.nc") == tmp_path / "real" / "a.nc.lock"
