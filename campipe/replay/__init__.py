"""Replays: selected cases of an archive or a running study, as rerun recordings.

- :mod:`~campipe.replay.sketch`: the mechanism as 2-D line strips, pure functions of q.
- :mod:`~campipe.replay.cases`: which cases, their histories and q (rebuilt and run again
  when the archive did not record q).
- :mod:`~campipe.replay.record`: what a recording shows of each case (parameters, the
  sketch at every sample), and ``campipe replay``: an archive's cases into one recording.
- :mod:`~campipe.replay.live`: the study hook that logs a spec's ``replay:`` selection while
  the study runs.

The rerun file itself is written by :mod:`campipe.io.rerun_replay` from plain arrays; rerun is
imported only there, where it is used, so ``import campipe.replay`` stays light.
"""
