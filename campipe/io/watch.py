"""Reads of a netCDF file that a damaged file cannot hang for ever.

A changed byte in the part of an HDF5 file that carries no checksum (a global heap, where
the archive's strings are: one object's size) can send HDF5's reader round a loop that
never ends. ``netCDF4.Dataset(path)`` then runs at 100 % of a core inside C, where Ctrl-C
does not reach it, and every command reading the file waits for ever.

So campipe reads a file in a thread of its own (:func:`watched`) while the calling thread
waits for it: Ctrl-C stops the wait (KeyboardInterrupt, as anywhere), and a read that has
made no progress for :data:`STALL_SECONDS` raises :class:`ReadStalled`. The read's thread
first takes :data:`NETCDF_LOCK` (netCDF-C and HDF5 are not thread-safe: every netCDF call of
campipe holds it), and its time starts then: a read waiting behind another thread's write or
verification is not stalled. It marks its progress with :func:`progress` (each block it
hashes or reads); opening a file and reading its attributes take milliseconds.

The read's thread cannot be stopped: it stays inside HDF5, holding the library and
:data:`NETCDF_LOCK`, until the process ends. Nothing can read or write netCDF in that
process afterwards (a later watched read is refused at once), so :class:`ReadStalled` is a
BaseException, as KeyboardInterrupt is: a handler that takes a damaged file as one to compute
again (``except Exception``) would go on to write with the library held. The command line
ends its process at once after such a read (:func:`stuck`): the interpreter's own exit tears
HDF5 down under the thread, a segmentation fault.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import ParamSpec, TypeVar

#: Seconds a watched read may go without progress before it is given up as stalled.
STALL_SECONDS = 30.0

#: Seconds between the waiting thread's checks (and how soon it sees a finished read's end:
#: an Event's ``wait`` returns as soon as it is set).
POLL_SECONDS = 0.5

log = logging.getLogger(__name__)

#: Serialises netCDF4 calls from this process's threads (``campipe.io.archive.LOCK``).
NETCDF_LOCK = threading.RLock()

P = ParamSpec("P")
R = TypeVar("R")


class ReadStalled(BaseException):
    """A read of ``path`` that made no progress for ``seconds``, given up (see the module's
    notes: its thread goes on inside HDF5, and no more netCDF can be used in this process)."""

    def __init__(self, path: str, seconds: float, earlier: bool = False) -> None:
        self.path = path
        self.seconds = seconds
        if earlier:
            message = (
                f"{path}: an earlier read of it made no progress for {seconds:.0f} s and is "
                "still inside HDF5, which no other file can use in this process; start "
                "again in a new process, without that file"
            )
        else:
            message = (
                f"{path}: reading it made no progress for {seconds:.0f} s: its structure is "
                "damaged (a changed byte can send HDF5's reader round a loop that never "
                "ends) or its disk is not answering. Restore it from a copy, or delete it "
                "and run the study again (campipe study SPEC)"
            )
        super().__init__(message)


class _Read:
    """One watched read's result and progress, shared with its thread."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.done = threading.Event()
        self.holding = False  # its thread holds NETCDF_LOCK: its time runs
        self.last = time.monotonic()
        self.value: object = None
        self.error: BaseException | None = None


_local = threading.local()
#: Reads given up on (stalled, or their wait interrupted) whose thread still runs.
_abandoned: list[tuple[threading.Thread, _Read]] = []


def progress() -> None:
    """Mark progress of the watched read running in this thread (none: nothing)."""
    read = getattr(_local, "read", None)
    if read is not None:
        read.last = time.monotonic()


def stuck() -> list[str]:
    """The files of reads given up on whose thread is still inside the library."""
    return [read.path for thread, read in _abandoned if thread.is_alive()]


def watched(fn: Callable[P, R]) -> Callable[P, R]:
    """``fn(path, ...)``, a read of the file ``path``, run in a thread of its own while the
    caller waits: Ctrl-C stops the wait, and no progress (:func:`progress`) for
    :data:`STALL_SECONDS` raises :class:`ReadStalled`. Within a watched read (a read that
    calls another) it runs directly."""

    @functools.wraps(fn)
    def run_watched(*args: P.args, **kwargs: P.kwargs) -> R:
        if getattr(_local, "read", None) is not None:
            return fn(*args, **kwargs)
        path = str(args[0] if args else next(iter(kwargs.values()), ""))
        for _, earlier in _abandoned:
            if not earlier.done.is_set():
                raise ReadStalled(earlier.path, time.monotonic() - earlier.last, earlier=True)
        read = _Read(path)
        log.debug("reading %s (watched)", path)

        def body() -> None:
            _local.read = read
            try:
                with NETCDF_LOCK:
                    read.last, read.holding = time.monotonic(), True
                    read.value = fn(*args, **kwargs)
            except BaseException as exc:  # handed to the waiting thread, raised there
                read.error = exc
            finally:
                read.done.set()

        thread = threading.Thread(target=body, name=f"campipe read of {Path(path).name}")
        thread.daemon = True
        thread.start()
        try:
            while not read.done.wait(POLL_SECONDS):
                idle = time.monotonic() - read.last
                if read.holding and idle > STALL_SECONDS:
                    raise ReadStalled(path, idle)
        except BaseException:  # stalled, or Ctrl-C: the thread is left where it is
            if not read.done.is_set():
                _abandoned.append((thread, read))
            raise
        error, read.error = read.error, None
        if error is not None:
            raise error
        return read.value  # type: ignore[return-value]

    return run_watched
