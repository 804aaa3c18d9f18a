"""The allocator of campipe's own processes: glibc keeps a run's freed output arrays for the
next run's (``mallopt``).

A setting of the whole process, so the library never makes it: ``campipe``'s commands do
(:func:`campipe.cli.base.main`), whose process is the command's own, as the bench does.
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys

#: glibc's allocator (``mallopt``): arrays below MMAP_BELOW bytes come from the heap, and up
#: to KEEP_FREED bytes freed at its top stay there for the next call's arrays.
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_BELOW = 32 * 2**20
KEEP_FREED = 128 * 2**20


@functools.cache
def reuse_freed_memory() -> bool:
    """Have glibc keep a run's freed output arrays for the next run's, once a process (a
    command's own: see the module).

    A batch's outputs (its samples: 7.4 MB for 32 cases of 4 turns) are fresh memory each
    call. glibc hands an array above its threshold back to the system when it is freed, or
    trims its heap once more than twice that threshold is free at its top, so the next call's
    arrays are new pages the system must fault in and clear: a third of a 32-case sweep's time.
    With the thresholds fixed here the heap keeps them. Not on another C library, nor with
    ``CAMPIPE_MALLOC=system`` in the environment; returns whether the thresholds were set."""
    if not sys.platform.startswith("linux") or os.environ.get("CAMPIPE_MALLOC") == "system":
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # no mallopt: not glibc
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_BELOW)) and bool(
        mallopt(M_TRIM_THRESHOLD, KEEP_FREED)
    )
