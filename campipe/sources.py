"""Digests of campipe's own source files: of what computes the numbers
(``campipe.study.run.results.numerics_fingerprint``) and of what the kernels compile from
(``campipe.kernel_cache``)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator
from pathlib import Path

#: The campipe package's folder.
PACKAGE = Path(__file__).resolve().parent


def source_files(names: Iterable[str], root: Path = PACKAGE) -> Iterator[Path]:
    """Each of ``names`` under the package folder ``root`` (a folder: its ``*.py`` files,
    sorted)."""
    for name in names:
        top = root / name
        yield from sorted(top.rglob("*.py")) if top.is_dir() else [top]


def source_digest(names: Iterable[str], root: Path = PACKAGE, prefix: str = "") -> str:
    """SHA-256 (hex) of ``prefix``, then of each of ``names`` under the package folder
    ``root`` (:func:`source_files`), each file's path relative to ``root`` before its
    bytes."""
    h = hashlib.sha256(prefix.encode())
    for path in source_files(names, root):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()
