"""I/O at the edges: study specs (YAML), lift tables (CSV) and archives (netCDF).

Nothing here computes; the numerics never import from here. Each module imports its file
format's library itself, so ``import campipe.io`` stays light.
"""

from pathlib import Path

from campipe.errors import CampipeError


def read_text(path: Path, what: str, error: type[CampipeError]) -> str:
    """The UTF-8 text of ``path``, or ``error`` naming the file (its ``key``) and what it was
    to hold (``what``: "the spec", "the lift table")."""
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise error.at(str(path), f"cannot read {what} ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise error.at(str(path), "not UTF-8 text", expected="UTF-8 text") from None
