"""A damaged archive that sends HDF5's reader round a loop never hangs a command
(``campipe.io.watch``): the reading commands give it up after ``STALL_SECONDS`` without
progress, naming the file and the fix (exit status 1), and Ctrl-C stops them.

The damage is the one a reliability helper found by flipping one byte of a small archive: an
object's size in the global heap (where the archive's strings are; HDF5 keeps no checksum of
it) grown, so that HDF5's walk of the heap lands in its free space and never ends.
``netCDF4.Dataset(path)`` itself then loops in C at 100 % of a core, where Ctrl-C does not
reach it.

Broken copy (every test below): reads run in the calling thread (``watched`` returning ``fn``
itself): the commands never end and each test's time limit stops them.
"""

import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time

import pytest
from study_helpers import write_spec

import campipe.io.watch as watch
from campipe.study import load_study
from campipe.study.run.execute import run_study

SPEC = """
name: loop
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 2, output_every: 4 deg}
sweep:
  speed: [6000 rpm, 11000 rpm]
"""

#: The stall limit the commands run with here (seconds).
STALL = 2.0
#: Seconds a command may take at most, import and stall included, on a loaded machine.
LIMIT = 90


def _looping_copy(archive, folder):
    """A copy of ``archive`` whose global heap's last object claims 96 bytes more than it
    holds: HDF5's walk of the heap then lands on the free space's zeros (an object of index 0
    and size 0, which it never steps past)."""
    data = bytearray(archive.read_bytes())
    heap = data.find(b"GCOL")
    assert heap > 0 and data.count(b"GCOL") == 1, "one global heap collection"
    (size,) = struct.unpack_from("<Q", data, heap + 8)
    pos, last = heap + 16, None
    while True:
        index, _, _, length = struct.unpack_from("<HHIQ", data, pos)
        if index == 0:
            break
        last, pos = (pos, length), pos + 16 + -(-length // 8) * 8
    assert last is not None
    free = heap + size - pos  # the free space's header and its zeros
    assert free >= 16 + 96 + 16, f"free space of {free} bytes: the step lands past it"
    struct.pack_into("<Q", data, last[0] + 8, last[1] + 96)
    copy = folder / archive.name
    copy.write_bytes(bytes(data))
    return copy


@pytest.fixture(scope="module")
def looping(tmp_path_factory):
    """(spec, archive) of a two-case study whose archive loops HDF5's reader."""
    d = tmp_path_factory.mktemp("loop")
    spec = write_spec(d, SPEC)
    run_study(load_study(spec), d / "loop.nc", scheduler="synchronous")
    damaged = tmp_path_factory.mktemp("loop-damaged")
    shutil.copy(spec, damaged / spec.name)
    return damaged / spec.name, _looping_copy(d / "loop.nc", damaged)


def _campipe(*args, cwd, **popen):
    """``campipe ARGS`` in a process of its own, its stall limit :data:`STALL`."""
    code = (
        "import sys, campipe.io.watch as w\n"
        f"w.STALL_SECONDS = {STALL}\n"
        "from campipe.cli import main\n"
        "main(sys.argv[1:], prog_name='campipe')\n"
    )
    return subprocess.Popen(
        [sys.executable, "-c", code, *map(str, args)],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )


@pytest.mark.parametrize(
    "command",
    [
        ("query", "{archive}", "--summary"),
        ("query", "{archive}", "--no-verify"),
        ("replay", "{archive}", "--where", "speed_rpm > 0", "-o", "r.rrd"),
        ("study", "{spec}"),
    ],
    ids=["query", "query-no-verify", "replay", "study-rerun"],
)
def test_a_read_that_loops_in_hdf5_is_given_up_naming_the_file(looping, command):
    """Each command ends with exit status 1 within :data:`LIMIT` s (its stall limit 2 s),
    saying the file is damaged and to restore it or delete it and run the study again; a
    rerun of the study leaves the file as it was. Broken copy: each runs until the limit."""
    spec, archive = looping
    before = archive.read_bytes()
    args = [a.format(archive=archive.name, spec=spec.name) for a in command]
    started = time.monotonic()
    proc = _campipe(*args, cwd=archive.parent)
    try:
        _, err = proc.communicate(timeout=LIMIT)
    finally:
        proc.kill()
    assert proc.returncode == 1, err
    assert f"{archive.name}: reading it made no progress for 2 s" in err, err
    assert "delete it and run the study again" in err
    assert "Traceback" not in err and "Segmentation" not in err
    assert time.monotonic() - started < LIMIT
    assert archive.read_bytes() == before
    assert not (archive.parent / "r.rrd").exists()


def test_ctrl_c_stops_a_read_that_loops_in_hdf5(looping):
    """Ctrl-C (SIGINT) during the read ends the command with status 130 and says which file
    it was reading. The stall limit is set far off, so the interrupt is what ends it.
    Broken copy: SIGINT waits for the C loop, which never returns to Python."""
    _, archive = looping
    code = (
        "import logging, sys, campipe.io.watch as w\n"
        "w.STALL_SECONDS = 3600\n"
        "from campipe.cli import main\n"
        "main(sys.argv[1:], prog_name='campipe')\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "-vv", "query", archive.name, "--no-verify"],
        cwd=archive.parent,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.default_int_handler),
    )
    try:
        lines, deadline = [], time.monotonic() + LIMIT
        while time.monotonic() < deadline:  # the read's start, logged at debug level
            if not select.select([proc.stderr], [], [], 1.0)[0]:
                continue
            lines.append(proc.stderr.readline())
            if "reading" in lines[-1] and archive.name in lines[-1] or not lines[-1]:
                break
        time.sleep(1.0)  # inside HDF5's loop by now: opening the file takes milliseconds
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=LIMIT)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGINT, "".join(lines) + err
    assert f"interrupted (Ctrl-C) (while reading {archive.name}" in err, err


# -- the watch itself ---------------------------------------------------------------------------


@pytest.fixture
def quick(monkeypatch):
    monkeypatch.setattr(watch, "STALL_SECONDS", 0.3)
    monkeypatch.setattr(watch, "POLL_SECONDS", 0.02)


def test_a_watched_read_that_stops_progressing_is_given_up_and_blocks_later_reads(quick):
    """A read that waits (as one looping in C does, without the GIL) raises ReadStalled after
    the limit; while its thread runs, ``stuck`` names it and every later read is refused at
    once (the library is held); once it ends, reads run again."""
    release = threading.Event()
    stalls = watch.watched(lambda path: release.wait(30))
    quick_read = watch.watched(lambda path: f"read {path}")
    started = time.monotonic()
    with pytest.raises(watch.ReadStalled, match=r"a\.nc: reading it made no progress"):
        stalls("a.nc")
    assert 0.3 <= time.monotonic() - started < 5
    assert watch.stuck() == ["a.nc"]
    with pytest.raises(watch.ReadStalled, match=r"a\.nc: an earlier read of it"):
        quick_read("b.nc")
    release.set()
    for thread in threading.enumerate():
        if thread.name == "campipe read of a.nc":
            thread.join(5)
    assert watch.stuck() == []
    assert quick_read("b.nc") == "read b.nc"


def test_a_watched_read_that_progresses_runs_past_the_limit(quick):
    """Progress (a block read) restarts the limit: a read of 1 s, marking progress every
    0.05 s, returns its value under a 0.3 s limit; an error inside a read is raised as it
    was, and a watched read inside another runs in the same thread."""

    def blocks(path):
        for _ in range(20):
            time.sleep(0.05)
            watch.progress()
        return threading.current_thread().name, inner(path)

    inner = watch.watched(lambda path: threading.current_thread().name)
    outer = watch.watched(blocks)
    assert outer("c.nc") == ("campipe read of c.nc", "campipe read of c.nc")

    def fails(path):
        raise ValueError(f"no {path}")

    with pytest.raises(ValueError, match="no d.nc"):
        watch.watched(fails)("d.nc")
    assert watch.stuck() == []


def test_a_read_waiting_for_the_netcdf_lock_is_not_stalled(quick):
    """A read waits while another thread holds the netCDF lock (a write, another file's
    verification) for 1 s, over three times the 0.3 s limit: its time starts when it holds
    the lock, so it returns its value. Broken copy: the time counted from the call."""
    taken, release = threading.Event(), threading.Event()

    def writer():
        with watch.NETCDF_LOCK:
            taken.set()
            release.wait(5)

    holder = threading.Thread(target=writer)
    holder.start()
    taken.wait(5)
    threading.Timer(1.0, release.set).start()
    started = time.monotonic()
    assert watch.watched(lambda path: f"read {path}")("e.nc") == "read e.nc"
    assert time.monotonic() - started >= 0.9
    holder.join(5)


def test_every_reader_of_netcdf_is_watched():
    """Every function of campipe that opens a netCDF file for reading does it inside a
    watched read (``open_dataset`` and ``xr.open_dataset`` are called only from functions
    decorated with ``watched``). Broken copy: a reader added without the decorator."""
    import ast
    from pathlib import Path

    root = Path(watch.__file__).parents[1]
    unwatched = []
    for path in root.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            decorators = {ast.unparse(d) for d in fn.decorator_list}
            if "watched" in decorators or fn.name == "open_dataset":
                continue
            for call in ast.walk(fn):
                if isinstance(call, ast.Call):
                    name = ast.unparse(call.func)
                    if name in ("open_dataset", "xr.open_dataset", "netCDF4.Dataset") and not (
                        any(isinstance(a, ast.Constant) and a.value == "w" for a in call.args)
                    ):
                        unwatched.append(f"{path.relative_to(root)}:{call.lineno} {fn.name}")
    assert unwatched == [], os.linesep.join(unwatched)
