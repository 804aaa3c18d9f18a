"""The developer's benchmark of campipe's own latencies and study layer; not installed.

``campipe bench`` (``campipe.bench``, in the package) is the speed-against-error suite a user
runs. This folder times campipe itself, as xarray's ``asv_bench/`` or PyBaMM's
``benchmarks/`` do: ``campipe study`` end to end against the engine, start-up, the first run
on empty caches, ``campipe validate`` at scale, the client's ceiling on a cluster, local
worker processes, the study layer's scaling.

- :mod:`~benchmarks.study`: the measurements and the command (``python -m benchmarks.study``).
- :mod:`~benchmarks.scaling`: ``campipe bench``'s scaling cases through the study layer.
- :mod:`~benchmarks.goals`: each goal with its figure, reached or not.
- :mod:`~benchmarks.pages`: docs/bench.md's ``study-…`` blocks from ``docs/bench/study.json``.

Run from the repository's root (``python -m benchmarks.study``); it imports campipe, and
nothing in campipe imports it.
"""
