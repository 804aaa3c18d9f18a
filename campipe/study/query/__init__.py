"""Reading an archive's cases: tables, ``--where`` selections, the summary, the units shown.

Imports the archive's layout and the spec's declarations, never the run.
"""
