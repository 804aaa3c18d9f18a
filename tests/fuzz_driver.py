"""Runs in a subprocess of tests/integration/test_fuzz.py, so its peak memory can be measured alone:
``python tests/fuzz_driver.py known|specs|where DIR``.

Every input goes through the command line (click's runner, in this process) and must end in
a message and an exit status — 0, 1 or 2 — within its time bound: never a traceback, never a
hang. A failure prints what went wrong and exits with status 3.
"""

from __future__ import annotations

import sys
import textwrap
import time
import traceback
from pathlib import Path

import numpy as np
import xarray as xr
import yaml
from click.testing import CliRunner

from campipe.cli import main

#: Seconds any one input may take (validate --no-estimate, query).
TIME_BOUND = 10.0
#: Small limits, so a generated spec within them stays fast to expand.
LIMITS = ["--max-cases", "2000"]

BASE = {
    "name": "fuzz",
    "profile": {"kind": "harmonic", "lift": "1 in"},
    "speed": "9000 rpm",
    "run": {"revolutions": 1},
}


def laughs(levels: int = 9) -> str:
    lines = ["name: laughs", 'a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, levels):
        p, q = chr(96 + i), chr(97 + i)
        lines.append(f"{q}: &{q} [" + ", ".join([f"*{p}"] * 9) + "]")
    return "\n".join(lines) + "\n"


def spec_text(**changes) -> str:
    raw = {**BASE, **changes}
    return yaml.safe_dump(raw, sort_keys=False)


#: The inputs the adversarial run found, as (name, spec text, extra arguments).
KNOWN = [
    ("billion laughs", laughs(), []),
    (
        "laughs in an error message",
        spec_text() + "sweep: {speed: " + "[" * 20 + "]" * 20 + "}\n",
        [],
    ),
    ("deep nesting", "name: deep\nprofile: " + "[" * 2000 + "]" * 2000 + "\n", []),
    ("9**9**9 rpm", spec_text(speed="9**9**9 rpm"), []),
    ("rpm**9**9", spec_text(speed="9 rpm**9**9"), []),
    (
        "1000 x 1000 grid",
        spec_text(
            sweep={
                "speed": {"from": "1000 rpm", "to": "9000 rpm", "num": 1000},
                "seat": {"from": "0 in", "to": "0.1 in", "num": 1000},
            }
        ),
        [],
    ),
    (
        "1e7 grid",
        spec_text(
            sweep={
                "speed": {"from": "1000 rpm", "to": "9000 rpm", "num": 10000},
                "seat": {"from": "0 in", "to": "0.1 in", "num": 1000},
            }
        ),
        [],
    ),
    (
        "num 1e11",
        spec_text(sweep={"speed": {"from": "1000 rpm", "to": "9000 rpm", "num": 10**11}}),
        [],
    ),
    (
        "num 1e11 float",
        spec_text(sweep={"speed": {"from": "1000 rpm", "to": "9000 rpm", "num": 1e11}}),
        [],
    ),
    (
        "sample n 1e9",
        spec_text(
            sample={
                "method": "latin-hypercube",
                "n": 10**9,
                "seed": 1,
                "ranges": {"speed": {"from": "1000 rpm", "to": "2000 rpm"}},
            }
        ),
        [],
    ),
    (
        "dt 1e-15 s",
        spec_text(run={"revolutions": 1, "integrator": "newmark-linear", "dt": "1e-15 s"}),
        [],
    ),
    ("dt 1e-15 s modal", spec_text(run={"revolutions": 1, "dt": "1e-15 s"}), []),
    (
        "0.001 rpm newmark",
        spec_text(speed="0.001 rpm", run={"revolutions": 1, "integrator": "newmark-linear"}),
        [],
    ),
    ("output_every 1e-9 deg", spec_text(run={"revolutions": 1, "output_every": "1e-9 deg"}), []),
    (
        "output_every beyond the run",
        spec_text(run={"revolutions": 1, "output_every": "400 deg"}),
        [],
    ),
    ("max_events 1e12", spec_text(run={"revolutions": 1, "max_events": 10**12}), []),
    ("lift table /dev/zero", spec_text(profile={"kind": "table", "file": "/dev/zero"}), []),
    ("lift table a folder", spec_text(profile={"kind": "table", "file": "/"}), []),
    ("speed 1e308 rpm", spec_text(), ["--set", "sweep.speed=[1e308 rpm]"]),
    ("lift 1e300 in", spec_text(profile={"kind": "harmonic", "lift": "1e300 in"}), []),
    ("lift 1e400 in", spec_text(profile={"kind": "harmonic", "lift": "1e400 in"}), []),
    ("spring 1e300", spec_text(model={"spring_rate": "1e300 lbf/in"}), []),
    ("damping list of 10**6", spec_text(model={"damping_ratios": list(range(1000))}), []),
    (
        "flat 272 to 268",
        spec_text(defects=[{"kind": "flat", "from": "272 deg", "to": "268 deg"}]),
        [],
    ),
    (
        "duplicate axis values",
        spec_text(sweep={"speed": ["9000 rpm", "9000.0 rpm", "6000 rpm"]}),
        [],
    ),
    ("duplicate cases", spec_text(cases=[{"seat": "0.1 in"}, {"seat": "0.1 in"}]), []),
    (
        "a range of equal ends",
        spec_text(sweep={"speed": {"from": "9000 rpm", "to": "9000 rpm", "num": 3}}),
        [],
    ),
    ("an int of 5000 digits", "name: big\nspeed: " + "9" * 5000 + "\n", []),
    ("a list key", "name: k\n[a, b]: 1\n", []),
    ("a replay of text against a number", spec_text(replay={"where": "profile > 3"}), []),
    ("a replay of an unknown column", spec_text(replay={"where": "sped_rpm > 3"}), []),
    ("--set a laugh", spec_text(), ["--set", "speed=" + "[" * 100 + "]" * 100]),
    ("--set a huge value", spec_text(), ["--set", "speed=" + "x" * 10**6]),
]


def _check(result, what: str, started: float) -> list[str]:
    problems = []
    elapsed = time.monotonic() - started
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        tb = "".join(traceback.format_exception(result.exception))
        problems.append(f"{what}: traceback\n{tb[-3000:]}")
    if result.exit_code not in (0, 1, 2):
        problems.append(f"{what}: exit status {result.exit_code}")
    if "Traceback" in result.output:
        problems.append(f"{what}: a traceback in the output\n{result.output[-2000:]}")
    if len(result.output) > 20_000:
        problems.append(f"{what}: {len(result.output)} characters of output")
    if elapsed > TIME_BOUND:
        problems.append(f"{what}: {elapsed:.1f} s, beyond {TIME_BOUND} s")
    return problems


def validate(directory: Path, text: str, extra: list[str], what: str) -> list[str]:
    path = directory / "spec.yaml"
    path.write_text(text)
    started = time.monotonic()
    result = CliRunner().invoke(main, ["validate", str(path), "--no-estimate", *LIMITS, *extra])
    return _check(result, what, started)


def known(directory: Path) -> list[str]:
    problems = []
    for what, text, extra in KNOWN:
        problems += validate(directory, text, extra, what)
    return problems


def specs(directory: Path) -> list[str]:
    """Generated specs: a valid base with keys replaced by values from a pool of the awkward
    (huge, tiny, non-finite, wrong type, deep, long, repeated)."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    awkward = st.one_of(
        st.integers(min_value=-(10**30), max_value=10**30),
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from(
            [
                "9**9**9 rpm",
                "1e400 in",
                "1e308 rpm",
                "0.001 rpm",
                "1e-15 s",
                "1e-9 deg",
                "none",
                "default",
                "x" * 3000,
                "1 rpm**99",
                "(((rpm)))",
                "268",
                "1 Hz",
                "-5 in",
                "0 in",
                "720 deg",
                "1e-300 in",
                "\x00",
                "\udcff",
                "1 in in in",
                "harmonic",
                "newmark-linear",
                "reduced",
            ]
        ),
        st.text(max_size=40),
        st.lists(st.integers(-5, 5), max_size=8),
        st.recursive(st.none(), lambda c: st.lists(c, max_size=3), max_leaves=30),
        st.dictionaries(
            st.sampled_from(["from", "to", "num", "kind", "lift"]),
            st.integers(-3, 10**12),
            max_size=3,
        ),
    )
    keys = st.sampled_from(
        [
            ("speed",),
            ("seat",),
            ("closure",),
            ("profile", "lift"),
            ("profile", "kind"),
            ("profile", "rise"),
            ("run", "dt"),
            ("run", "revolutions"),
            ("run", "output_every"),
            ("run", "max_events"),
            ("run", "integrator"),
            ("run", "tolerance"),
            ("run", "record"),
            ("model", "spring_rate"),
            ("model", "damping_ratios"),
            ("sweep", "speed"),
            ("sweep", "seat"),
            ("zip", "speed"),
            ("defects",),
            ("sample", "n"),
            ("cases",),
            ("replay", "where"),
            ("name",),
            ("bogus",),
        ]
    )
    problems: list[str] = []

    @settings(
        max_examples=400,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(st.lists(st.tuples(keys, awkward), min_size=1, max_size=4))
    def run(changes):
        raw = yaml.safe_load(yaml.safe_dump(BASE))
        for path, value in changes:
            node = raw
            for part in path[:-1]:
                node = (
                    node.setdefault(part, {})
                    if isinstance(node.get(part), dict) or part not in node
                    else {}
                )
            node[path[-1]] = value
        try:
            text = yaml.safe_dump(raw, allow_unicode=True)
        except yaml.YAMLError:
            return
        problems.extend(validate(directory, text, [], f"generated spec {changes!r:.300}"))

    run()
    return problems


def _archive(directory: Path) -> Path:
    """A small archive of the layout campipe query reads (written here: no engine needed)."""
    n = 6
    ds = xr.Dataset(
        {
            "separation_deg_per_rev": ("case", np.array([0, 0, 5.0, 0, 12.0, np.nan])),
            "cam_impacts": ("case", np.arange(n, dtype=np.int32)),
            "status": ("case", np.array([0, 0, 0, 2, 0, 3], dtype=np.int8)),
        },
        coords={
            "case": ("case", np.array([f"{i:016x}" for i in range(n)], dtype=object)),
            "speed_rpm": ("case", np.array([6000, 9000, 11000, 6000, 9000, 11000.0])),
            "seat": ("case", np.array([-np.inf] * 3 + [0.00254] * 3), {"units": "m"}),
            "closure": ("case", np.array(["force"] * n, dtype=object)),
        },
        attrs={
            "study_name": "fuzz",
            "revolutions": 1.0,
            "record": "-",
            "study_axes": '[{"key": "speed", "name": "speed_rpm", "kind": "sweep", "size": 3}]',
        },
    )
    path = directory / "q.nc"
    ds.to_netcdf(path)
    return path


KNOWN_WHERE = [
    "speed_rpm > 0 and true",
    "1",
    "speed_rpm > " + "9" * 400,
    "speed_rpm > 1e400",
    "\udcff",
    'closure == "\udcff"',
    "seat is none or " * 120 + "true",
    "seat == 0.1 in or seat < 3 lbf",
    "speed_rpm > 150 Hz",
    "seat > 0.001",
    "1 in == seat",
    "not " * 400 + "true",
    "-" * 1500 + "1",
    "(" * 300 + ")" * 300,
    "speed_rpm == 'a' and closure > 3",
    "__import__('os').system('true')",
    "x" * 5000,
    "speed_rpm in [1, 2, [3]]",
    "damping_ratios > 1",
]


def where(directory: Path) -> list[str]:
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    archive = _archive(directory)
    problems: list[str] = []

    def query(expr: str, summary: bool) -> None:
        started = time.monotonic()
        args = ["query", str(archive), "--where", expr] + (["--summary"] if summary else [])
        result = CliRunner().invoke(main, args)
        problems.extend(_check(result, f"--where {expr!r:.200}", started))

    for expr in KNOWN_WHERE:
        query(expr, False)
        query(expr, True)
    token = st.sampled_from(
        [
            "speed_rpm",
            "seat",
            "closure",
            "status",
            "case",
            "cam_impacts",
            "0.1 in",
            "lbf",
            "rpm",
            "nan",
            "none",
            "true",
            "false",
            "inf",
            "and",
            "or",
            "not",
            "in",
            "is",
            "==",
            "!=",
            "<",
            "<=",
            ">",
            ">=",
            "(",
            ")",
            "[",
            "]",
            ",",
            "-",
            "1",
            "9000",
            "1e400",
            "'force'",
            '"x"',
            "9" * 50,
            "@",
            "**",
            ".",
            "lambda",
            "if",
            "else",
        ]
    )

    @settings(
        max_examples=250,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(
        st.one_of(st.lists(token, min_size=1, max_size=12).map(" ".join), st.text(max_size=30)),
        st.booleans(),
    )
    def run(expr, summary):
        if expr.strip():
            query(expr, summary)

    run()
    return problems


if __name__ == "__main__":
    mode, directory = sys.argv[1], Path(sys.argv[2])
    directory.mkdir(parents=True, exist_ok=True)
    found = {"known": known, "specs": specs, "where": where}[mode](directory)
    for problem in found[:20]:
        print(textwrap.shorten(problem, 4000) if "traceback" not in problem else problem)
    print(f"{len(found)} problems")
    sys.exit(3 if found else 0)
