"""campipe: parametric studies of cam-driven valve-train dynamics.

``import campipe`` stays light: rerun and dask.distributed are imported only where used.
"""

#: The version, written here only (pyproject.toml reads it).
__version__ = "0.1.0"
