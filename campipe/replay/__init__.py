"""Replays: selected cases of an archive or a running study, as rerun recordings.

- :mod:`~campipe.replay.sketch`: the mechanism as 2-D line strips, pure functions of q.
- :mod:`~campipe.replay.cases`: which cases, their histories and q (rebuilt and run again
  when the archive did not record q).
- :mod:`~campipe.replay.live`: the study hook that logs a spec's ``replay:`` selection while
  the study runs.

The rerun recording itself is written by :mod:`campipe.io.rerun_replay`; nothing here imports
rerun, so ``import campipe.replay`` stays light.
"""
