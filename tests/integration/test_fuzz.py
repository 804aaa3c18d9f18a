"""Small inputs that used to exhaust the machine, and generated ones (hypothesis): every spec
and every --where expression ends in a message and an exit status, within its time bound and
within a bound on memory measured in a subprocess (``os.wait4`` gives that child's peak RSS,
as ``getrusage(RUSAGE_CHILDREN)`` would)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from campipe.cli.base import DEFAULT_LIMITS
from campipe.study.spec.limits import Limits

HERE = Path(__file__).parents[1]  # tests/: fuzz_driver.py and the helpers
ROOT = HERE.parent


#: Runs its arguments and reports their peak RSS. The measured command is a child of this
#: small process, not of pytest's: a child forked from a large process counts that process's
#: pages in its peak.
WRAPPER = """
import resource, subprocess, sys
proc = subprocess.run(sys.argv[1:], stdout=sys.stdout, stderr=subprocess.STDOUT)
sys.stdout.flush()
print(f"\\npeak-kb {resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}")
sys.exit(proc.returncode)
"""


def peak_of(args: list[str], timeout: float, cwd: Path | None = None):
    """(exit status, output, peak RSS [MB]) of a subprocess."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(HERE)])}
    try:
        proc = subprocess.run(
            [sys.executable, "-c", WRAPPER, *args],
            capture_output=True,
            text=True,
            errors="replace",
            env=env,
            cwd=cwd,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"{args[1:4]}: still running after {timeout} s\n{exc.stdout!s:.2000}")
    out, _, peak = proc.stdout.rpartition("\npeak-kb ")
    return proc.returncode, out + proc.stderr, int(peak) / 1024


def test_the_clis_default_limits_are_the_studys():
    d = Limits()
    assert DEFAULT_LIMITS == {
        "cases": d.cases,
        "steps": d.steps,
        "samples": d.samples,
        "events": d.events,
        "archive_gb": d.archive_bytes / 1e9,
    }


@pytest.mark.parametrize("mode", ["known", "specs", "where"])
def test_no_input_gives_a_traceback_a_hang_or_500_mb(tmp_path, mode):
    """known: the inputs the adversarial run found (billion laughs, 9**9**9 rpm, a 1e7 grid,
    dt 1e-15 s, a lift table at /dev/zero, ...); specs: generated specs; where: generated
    --where expressions, with and without --summary."""
    status, out, peak = peak_of(
        [sys.executable, str(HERE / "fuzz_driver.py"), mode, str(tmp_path)], timeout=240
    )
    assert status == 0, out[-6000:]
    assert out.strip().endswith("0 problems")
    assert peak < 500, f"peak RSS {peak:.0f} MB"


GRID = """
name: huge
profile: {kind: harmonic, lift: 1 in}
speed: 9000 rpm
sweep:
  speed: {from: 1000 rpm, to: 20000 rpm, num: 10000}
  seat: {from: 0 in, to: 0.1 in, num: 1000}
"""


@pytest.mark.parametrize("command", ["validate", "study"])
def test_a_1e7_case_grid_is_refused_before_any_case_is_built(tmp_path, command):
    spec = tmp_path / "huge.yaml"
    spec.write_text(textwrap.dedent(GRID))
    status, out, peak = peak_of(
        [sys.executable, "-m", "campipe", command, str(spec)], timeout=120, cwd=tmp_path
    )
    assert status == 2, out
    assert "cases (sweep.speed 10000 × sweep.seat 1000): 1e+07, beyond the limit of 1e+05" in out
    assert "--max-cases" in out and "Traceback" not in out
    assert peak < 300, f"peak RSS {peak:.0f} MB"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["huge.yaml"]
