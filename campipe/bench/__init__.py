"""Speed against error: the bench suite, its converged references, the peers, the steady-state
path and the onset map.

- :mod:`~campipe.bench.suite`: the fixed cases and the ladders of steps and tolerances.
- :mod:`~campipe.bench.ivp`: the SciPy ``solve_ivp`` peer, an independent event-driven
  implementation of the same model.
- :mod:`~campipe.bench.measure`: timing, errors against a reference, the references and their
  check, time-to-error ratios.
- :mod:`~campipe.bench.onset`: the steady-state path against the engine on the scenes that
  follow the cam, and the onset map over many designs against the time-domain grid.
- :mod:`~campipe.bench.scaling`: the engine's time against number of cases and workers,
  and its throughput.
- :mod:`~campipe.bench.run`: the whole bench as one call; :mod:`~campipe.bench.report` writes
  its table and plot and reads its json back (the only module here that writes files, with
  :mod:`~campipe.bench.pages`).
- :mod:`~campipe.bench.verdict`: each goal reached or not, each reference cross-check agreeing
  or not, and why.
- :mod:`~campipe.bench.figures`: how a figure is written (significant digits), shared.
- :mod:`~campipe.bench.gate`: the regression gate, every timed figure more than 10 % slower than
  the previous run's on the same machine.
- :mod:`~campipe.bench.pages`: the documentation's bench figures, generated from a
  ``bench.json`` (``python -m campipe.bench.pages``).

Nothing here is imported by ``import campipe``. campipe's own latencies and study layer
(``campipe study`` end to end against the engine, start-up, ``validate`` at scale) are a
developer's benchmark outside the package, ``benchmarks/`` in the repository, which imports
this package and is imported by none of it.
"""
