"""Running a study: each batch through the engine, batches on dask, the batch files, resuming,
the archive assembled as the batches finish, the progress line and the run's estimate.

Imports the spec and the archive's layout, never the queries.
"""
