"""The lock a run holds while it writes an archive: ``<archive>.lock`` beside it.

The lock is a small JSON file naming its holder (process, host, start time). Taking it and
taking it over are exclusive:

- **Taking**: the file is created with ``O_CREAT | O_EXCL``; of any number of runs that try
  at once, exactly one creates it.
- **Writing and reading its content** happen under an OS lock on the file (``fcntl.flock``),
  so a reader never sees half of it.
- **Taking over** the lock of a run that died on this host (its process is gone) happens under
  the same OS lock, after checking that the path still names the file that was locked and
  that the holder it names is still the dead one; the content is then rewritten in place. Of
  many runs racing to take over one stale lock, the first to hold the OS lock takes it over,
  and every later one reads a live holder and stops. The OS lock is held for microseconds and
  released by the kernel if its process dies, so it can never itself go stale.

A lock from another host cannot be checked and is never taken over; neither is a lock whose
content cannot be read (its creator died between creating and writing it, or it is not a
campipe lock): the error says to remove it by hand.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from campipe.errors import CampipeError

try:  # POSIX; elsewhere the lock is taken but a stale one is never taken over
    import fcntl
except ImportError:  # pragma: no cover - not on Linux
    fcntl = None  # type: ignore[assignment]

log = logging.getLogger(__name__)

#: Largest process id a lock may name (Linux's pid_max is at most 2**22).
MAX_PID = 2**31 - 1
#: How long to wait for the OS lock of a lock file another run is writing or reading [s]: it
#: is held for microseconds, so this is only reached on a hung file system.
OS_LOCK_TIMEOUT = 10.0
#: Largest lock file read [bytes]: a campipe lock holds about a hundred.
MAX_LOCK_BYTES = 4096


class ArchiveBusyError(CampipeError, RuntimeError):
    """Another run is writing the same archive (``key`` the archive, ``found`` its lock's
    holder: pid, host and start, or None if the lock cannot be read)."""


class LockFileError(CampipeError, RuntimeError):
    """The lock beside an archive cannot be created or read (``key`` the lock file): a folder
    that is not writable, a file system that refuses locks."""


def lock_path(archive: Path) -> Path:
    """The lock a run holds while it writes ``archive``: ``<archive>.lock`` beside it, the
    archive's path resolved (a symbolic link to it, or to its folder, gives the same lock:
    two runs through two names of one archive both started, a helper found)."""
    real = Path(archive).resolve()
    return real.with_name(real.name + ".lock")


def holder_record() -> dict[str, object]:
    """This process as a lock names it."""
    return {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "started": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


@contextmanager
def writing(archive: str | Path) -> Iterator[Path]:
    """Hold the archive's lock while a run writes it and its batch files.

    A second run on the same archive stops with :class:`ArchiveBusyError` before touching
    any file, so it never removes the first run's temporary or batch files. A lock left by a
    run that died on this host (its process is gone) is taken over, so a rerun after a kill
    resumes.

    Raises
    ------
    ArchiveBusyError
        If a live process (or one on another host, which cannot be checked) holds the lock,
        or its content cannot be read.
    LockFileError
        If the lock cannot be created at all (a read-only folder, say).
    """
    archive = Path(archive)
    lock = lock_path(archive)
    me = holder_record()
    take(lock, me, archive)
    try:
        yield lock
    finally:
        release(lock, me)


def take(lock: Path, me: dict[str, object], archive: Path) -> None:
    """Create ``lock`` naming ``me``, or take it over from a dead holder; see the module."""
    for _ in range(100):  # retried only when the lock vanished between two steps
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o644)
            created = True
        except FileExistsError:
            try:
                fd = os.open(lock, os.O_RDWR)
            except FileNotFoundError:
                continue  # released meanwhile: try to create it again
            except OSError as exc:
                raise _cannot(lock, exc) from None
            created = False
        except OSError as exc:
            raise _cannot(lock, exc) from None
        try:
            _os_lock(fd, lock)
            if not _same_file(fd, lock):
                continue  # released (and perhaps taken anew) while we waited: start over
            if created:
                _write(fd, me)
                return
            holder = _parse(_read(fd))
            if holder is not None and _is_dead(holder):
                log.warning(
                    "%s: taking over the lock of process %s, which is gone", archive, holder["pid"]
                )
                _write(fd, me)
                return
            raise _busy(archive, lock, holder)
        finally:
            os.close(fd)  # closing releases the OS lock
    raise _busy(archive, lock, None)


def release(lock: Path, me: dict[str, object]) -> None:
    """Remove ``lock`` if it still names ``me`` (never another run's)."""
    try:
        fd = os.open(lock, os.O_RDWR)
    except OSError:
        return
    try:
        _os_lock(fd, lock)
        if _same_file(fd, lock) and _parse(_read(fd)) == me:
            lock.unlink(missing_ok=True)
    except (OSError, CampipeError) as exc:
        log.warning("%s: cannot remove the lock (%s); remove it by hand", lock, exc)
    finally:
        os.close(fd)


def read_holder(lock: Path) -> dict | None:
    """The lock's holder, or None if there is no lock or its content cannot be read."""
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return None
    try:
        return _parse(_read(fd))
    except OSError:
        return None
    finally:
        os.close(fd)


def _os_lock(fd: int, lock: Path) -> None:
    if fcntl is None:  # pragma: no cover
        return
    deadline = time.monotonic() + OS_LOCK_TIMEOUT
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() > deadline:
                raise LockFileError.at(
                    str(lock),
                    f"still locked by another process after {OS_LOCK_TIMEOUT:g} s; "
                    "is its file system hung?",
                ) from None
            time.sleep(0.001)
        except OSError as exc:
            raise _cannot(lock, exc) from None


def _same_file(fd: int, lock: Path) -> bool:
    """The path still names the file open as ``fd`` (not removed, not replaced)."""
    try:
        a, b = os.fstat(fd), os.stat(lock)
    except FileNotFoundError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _write(fd: int, me: dict[str, object]) -> None:
    data = json.dumps(me).encode()
    os.ftruncate(fd, 0)
    os.pwrite(fd, data, 0)
    os.fsync(fd)


def _read(fd: int) -> bytes:
    return os.pread(fd, MAX_LOCK_BYTES + 1, 0)


def _parse(data: bytes) -> dict | None:
    """A lock's holder, or None unless it names a pid, a host and a start time."""
    if not data or len(data) > MAX_LOCK_BYTES:
        return None
    try:
        holder = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        return None
    if not isinstance(holder, dict) or not {"pid", "host", "started"} <= set(holder):
        return None
    return holder


def _valid_pid(pid: object) -> bool:
    return isinstance(pid, int) and not isinstance(pid, bool) and 0 < pid <= MAX_PID


def _is_dead(holder: dict) -> bool:
    """The lock's process is known to be gone: on this host, and no such process."""
    if holder["host"] != socket.gethostname() or not _valid_pid(holder["pid"]):
        return False
    if holder["pid"] == os.getpid():
        return False  # this process: another thread of it is writing the archive
    try:
        os.kill(holder["pid"], 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False  # alive, another user's
    return False


def _busy(archive: Path, lock: Path, holder: dict | None) -> ArchiveBusyError:
    if holder is not None and _valid_pid(holder["pid"]):
        who = f"process {holder['pid']} on {holder['host']} since {holder['started']}"
        return ArchiveBusyError(
            f"{archive} is being written by {who}: wait for that run to finish, or "
            f"write to another archive (-o); if that run is gone, remove {lock}",
            key=str(archive),
            found=holder,
        )
    return ArchiveBusyError(
        f"{archive} is being written by another run ({lock} exists, but does not name a "
        f"process that can be checked): wait for that run to finish, or write to another "
        f"archive (-o); if no run is writing it, remove {lock}",
        key=str(archive),
        found=holder,
    )


def _cannot(lock: Path, exc: OSError) -> LockFileError:
    why = exc.strerror or str(exc)
    hint = (
        "; choose a folder you can write to (-o)"
        if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS)
        else ""
    )
    return LockFileError.at(
        str(lock), f"cannot create or open the lock ({why}){hint}", found=exc.errno
    )
