"""What an archive holds: its variables, axes, coordinates and attributes laid out from the
spec's declarations (:mod:`~campipe.study.archive.layout`), and an archive read back as a grid
(:mod:`~campipe.study.archive.open`).

Imports the spec, never the run or the queries; the netCDF files themselves are
:mod:`campipe.io.archive`'s.
"""
