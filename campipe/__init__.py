"""campipe: parametric studies of cam-driven valve-train dynamics.

``import campipe`` stays light: rerun and dask.distributed are imported only where used, and
:func:`open_study` (an archive with its sweep's axes as dimensions) is imported on first use.
"""

#: The version, written here only (pyproject.toml reads it).
__version__ = "0.1.0"

__all__ = ["__version__", "open_study"]


def __getattr__(name: str):
    # PEP 562: campipe.open_study without importing xarray and the study layer at import
    if name == "open_study":
        from campipe.study.archive.open import open_study

        return open_study
    raise AttributeError(f"module 'campipe' has no attribute {name!r}")
