"""I/O at the edges: study specs (YAML), lift tables (CSV) and archives (netCDF).

Nothing here computes; the numerics never import from here. Each module imports its file
format's library itself, so ``import campipe.io`` stays light.
"""
