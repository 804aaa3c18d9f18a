"""What a user writes and what it asks for: a study spec checked, and expanded into cases.

The lowest of the study's packages: it imports none of :mod:`~campipe.study.archive`,
:mod:`~campipe.study.run` or :mod:`~campipe.study.query`, so checking a spec (``campipe
validate``) loads neither the archive nor the query tables. Its ``where`` expressions
(``replay.where``, a plot's ``where``) are written in :mod:`campipe.study.where`.
"""
