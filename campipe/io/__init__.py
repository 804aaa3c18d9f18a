"""I/O at the edges: study specs (YAML), lift tables (CSV) and archives (netCDF).

Nothing here computes; the numerics never import from here. Each module imports its file
format's library itself, so ``import campipe.io`` stays light.
"""

import os
import stat
from pathlib import Path

from campipe.errors import CampipeError

#: How a netCDF file begins: netCDF-4's (HDF5's signature) and the classic formats'.
NETCDF_MAGIC = (b"\x89HDF\r\n\x1a\n", b"CDF\x01", b"CDF\x02", b"CDF\x05")


def read_text(path: Path, what: str, error: type[CampipeError], limit: int) -> str:
    """The UTF-8 text of ``path``, or ``error`` naming the file (its ``key``) and what it was
    to hold (``what``: "the spec", "the lift table").

    Only a regular file is read (a device such as /dev/zero, a pipe or a folder is refused
    before opening it), and only up to ``limit`` bytes: a larger file is refused.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise error.at(str(path), f"cannot read {what} ({exc.strerror})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise error.at(
                str(path), f"not a regular file; {what} is a text file", expected="a text file"
            )
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise error.at(str(path), f"cannot read {what} ({exc.strerror})") from None
    finally:
        os.close(fd)
    if len(data) > limit:
        raise error.at(
            str(path),
            f"larger than {limit / 2**20:g} MiB; {what} is expected to be smaller",
            expected=f"at most {limit} bytes",
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        why = (
            f"a netCDF file (an archive?), not {what}: a command that reads archives takes "
            "it (campipe query, plot, export, replay)"
            if data.startswith(NETCDF_MAGIC)
            else f"not UTF-8 text; {what} is a text file"
        )
        raise error.at(str(path), why, expected="UTF-8 text") from None
