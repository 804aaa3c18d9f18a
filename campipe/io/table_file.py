"""Tables of samples as files: CSV, Parquet and MATLAB ``.mat`` (``campipe export``).

A table is plain data: columns (name → a 1-D array, all of one length) and their units. Each
format carries the units and says campipe wrote it, so a rerun may replace its own file and
nothing else (the output rule, :mod:`campipe.io.outputs`):

- **CSV**: one header line, each column's name with its units in brackets
  (``valve_velocity [mm/deg]``), then one line per row; the first column is ``case``.
- **Parquet** (needs pyarrow, not a dependency of campipe): the header's names as column
  names, the units and the study in the schema's metadata (``campipe``, ``units``).
- **MATLAB** (``scipy.io.savemat``): one variable per column, named as the column (``case``,
  a MATLAB keyword, as ``case_id``), a struct ``units`` of each column's units, the cell
  ``columns`` of the header's names and the text ``campipe_export`` (the study's name).

Files are written at a temporary path and renamed into place.
"""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from campipe.errors import CampipeError
from campipe.io.outputs import Kind, head

#: The formats, by name, and the suffix each is written with by default.
FORMATS = {"csv": ".csv", "parquet": ".parquet", "mat": ".mat"}
#: The first header cells of an export's CSV: how a rerun tells its own file.
CSV_HEAD = "case,cam_angle ["
#: The schema metadata key of an export's Parquet file, and the MATLAB variable of a .mat.
MARK = "campipe_export"
#: MATLAB names for columns whose own name is a MATLAB keyword.
MAT_NAMES = {"case": "case_id"}


class TableFormatError(CampipeError, ValueError):
    """A table format that is not one, or cannot be written here (``key`` ``--format``)."""


def header(name: str, units: str) -> str:
    """A column's header: ``valve_velocity [mm/deg]``, ``contact_state`` without units."""
    return f"{name} [{units}]" if units and units != "1" else name


def format_of(path: str | Path, fmt: str | None = None) -> str:
    """The format ``fmt``, or the one ``path``'s suffix names."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise TableFormatError.at(
                "--format",
                f"found {fmt!r}, expected one of: {', '.join(FORMATS)}",
                found=fmt,
                expected=", ".join(FORMATS),
            )
        return fmt
    suffix = Path(path).suffix.lower()
    for name, ending in FORMATS.items():
        if suffix == ending or (name == "parquet" and suffix == ".pq"):
            return name
    raise TableFormatError.at(
        "--format",
        f"{Path(path).name} does not end in {', '.join(FORMATS.values())}: name the format "
        "(--format csv, parquet or mat)",
        found=suffix,
        expected=", ".join(FORMATS.values()),
    )


def pyarrow_parquet():
    """pyarrow's Parquet module, or a TableFormatError naming the fix."""
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise TableFormatError.at(
            "--format",
            "parquet needs pyarrow, which is not installed; install it "
            "(python -m pip install pyarrow), or write csv or mat",
            found="parquet",
            expected="pyarrow installed",
        ) from None
    return pq


def write_table(
    path: str | Path,
    fmt: str,
    columns: Mapping[str, np.ndarray],
    units: Mapping[str, str],
    study: str = "",
) -> Path:
    """Write ``columns`` (name → 1-D array) with their ``units`` to ``path`` as ``fmt``."""
    writer: dict[str, Callable[[Path, Mapping, Mapping, str], None]] = {
        "csv": _csv,
        "parquet": _parquet,
        "mat": _mat,
    }
    write = writer[format_of(path, fmt)]
    if fmt == "parquet":
        pyarrow_parquet()  # refused before anything is written
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write(tmp, columns, units, study)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _csv(path: Path, columns: Mapping, units: Mapping, study: str) -> None:
    names = list(columns)
    lists = [np.asarray(columns[n]).tolist() for n in names]  # floats print as repr
    with open(path, "w", newline="") as f:
        out = csv.writer(f, lineterminator="\n")
        out.writerow([header(n, units.get(n, "")) for n in names])
        out.writerows(zip(*lists, strict=True))


def _parquet(path: Path, columns: Mapping, units: Mapping, study: str) -> None:
    import pyarrow as pa

    pq = pyarrow_parquet()
    names = {n: header(n, units.get(n, "")) for n in columns}
    table = pa.table({names[n]: np.asarray(v) for n, v in columns.items()})
    table = table.replace_schema_metadata(
        {MARK: study, "units": json.dumps({n: units.get(n, "") for n in columns})}
    )
    pq.write_table(table, path)


def _mat(path: Path, columns: Mapping, units: Mapping, study: str) -> None:
    from scipy.io import savemat

    data: dict[str, object] = {MAT_NAMES.get(n, n): np.asarray(v) for n, v in columns.items()}
    data["units"] = {MAT_NAMES.get(n, n): units.get(n, "") for n in columns}
    data["columns"] = np.array([header(n, units.get(n, "")) for n in columns], dtype=object)
    data[MARK] = study
    savemat(path, data, do_compression=True, oned_as="column")


def is_export(path: Path, fmt: str | None = None) -> bool:
    """The file at ``path`` is a table ``campipe export`` wrote as ``fmt`` (default: the
    format its suffix names)."""
    try:
        fmt = format_of(path, fmt)
    except TableFormatError:
        return False
    if fmt == "csv":
        return head(path).startswith(CSV_HEAD.encode())
    if fmt == "parquet":
        return _parquet_mark(path)
    return _mat_mark(path)


def _parquet_mark(path: Path) -> bool:
    if not head(path).startswith(b"PAR1"):
        return False
    try:
        pq = pyarrow_parquet()
        metadata = pq.read_schema(path).metadata or {}
    except Exception:  # no pyarrow, or not a Parquet file after all
        return False
    return MARK.encode() in metadata


def _mat_mark(path: Path) -> bool:
    from scipy.io import whosmat

    try:
        return any(name == MARK for name, _, _ in whosmat(str(path)))
    except Exception:  # not a MATLAB file, or damaged
        return False


def export_kind(fmt: str) -> Kind:
    """What ``campipe export`` writes as ``fmt`` (the output rule's kind): a table of that
    format it wrote, which a rerun replaces."""
    return Kind(f"a {fmt} table campipe export wrote", lambda path: is_export(path, fmt))
