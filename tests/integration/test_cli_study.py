"""`campipe study`, `campipe validate` and `campipe query` from the command line."""

import re
import subprocess
import sys

import pytest
import xarray as xr
from click.testing import CliRunner
from study_helpers import STUDIES, write_spec

from campipe.cli import main


def invoke(*args):
    return CliRunner().invoke(main, list(args))


def test_validate_prints_cases_axes_and_estimates():
    out = invoke("validate", str(STUDIES / "separation-map.yaml"), "--workers", "2")
    assert out.exit_code == 0, out.output
    text = out.output
    assert "valid; study 'separation-map', 297 cases" in text
    assert re.search(r"speed_rpm\s+sweep\s+33 values: 6000 rpm … 14000 rpm", text)
    assert re.search(r"seat\s+sweep\s+3 values: none, 0 in, 0.1 in", text)
    assert re.search(r"spring_preload\s+sweep\s+3 values: 120 lbf, 151 lbf, 180 lbf", text)
    assert "batches: 8 of up to 38 cases" in text
    assert re.search(
        r"run time: about [\d.]+ s on 2 workers: the engine [\d.]+ s, storing and writing the "
        r"archive [\d.]+ s, loading the engine [\d.]+ s, the replay's 3 cases [\d.]+ s \(timed "
        r"on a run of \d+ of its 297 cases, scaled; 22.7 s simulated",
        text,
    )
    # run.revolutions: auto: a case runs until it repeats, guessed at a quarter of its cap
    # (12 turns; the timed sample run corrects the time), and one turn is stored
    assert "until each case repeats (at most 48 revolutions, the last 1 recorded)" in text
    size = float(re.search(r"archive: about ([\d.]+) MB", text).group(1))
    # 297 cases × 361 angles × (8 float64 histories + the int8 contact state) ≈ 6.97 MB, and
    # 48 revolutions × (9 float64 + 3 int32 per-revolution metrics + the int8 measured)
    # ≈ 1.2 MB
    assert 7.6 < size < 8.1
    assert "replay: 'speed_rpm == 11000 and seat is none'" in text


def _validated(tmp_path, rest: str):
    """campipe validate of the thesis's train on its harmonic cam, no seat, and ``rest``."""
    head = "name: v\nmodel: {preset: thesis-1971}\nprofile: {kind: harmonic, lift: 1 in}\n"
    return invoke("validate", str(write_spec(tmp_path, head + "seat: none\n" + rest, "v.yaml")))


def test_validate_estimates_a_quasi_static_start(tmp_path):
    """A spec with ``run.start: quasi-static`` (one warm-up turn by default) validates and
    gets its estimate: validate's kernel-loading run of a hundredth of a turn took the
    warm-up too and was refused (a helper's, and the quickstart's with the start changed),
    where campipe study runs the spec. Broken copy: the warm-up kept."""
    out = _validated(
        tmp_path,
        "run: {revolutions: 3, start: quasi-static}\nsweep: {speed: [3000 rpm, 6000 rpm]}\n",
    )
    assert out.exit_code == 0, out.output
    assert "run time: about" in out.output


def test_validate_shows_a_sampled_range_as_the_spec_wrote_it(tmp_path):
    """A sample's ranges read in the spec's own units (it showed 35025.4 … 52538.1 N/m for
    a spec that wrote 200 lbf/in … 300 lbf/in, and metres for inches), as a sweep's values
    do. Broken copy: the SI range."""
    out = _validated(
        tmp_path,
        "run: {revolutions: 2}\nspeed: 3000 rpm\n"
        "sample:\n  method: latin-hypercube\n  n: 3\n  seed: 1\n  ranges:\n"
        "    model.spring_rate: {from: 200 lbf/in, to: 300 lbf/in}\n"
        "    profile.lift: {from: 0.3 in, to: 0.4 in}\n",
    )
    assert out.exit_code == 0, out.output
    assert re.search(
        r"spring_rate\s+sample\s+3 values: latin-hypercube over 200 lbf/in … 300 lbf/in, seed 1",
        out.output,
    )
    assert "latin-hypercube over 0.3 in … 0.4 in, seed 1" in out.output


def test_validate_refuses_a_bad_spec_with_its_key_paths(tmp_path):
    path = write_spec(
        tmp_path,
        """
    name: bad
    profile: {kind: harmonic, lift: 1 in}
    speed: 9000
    sweep: {sped: [1 rpm]}
    """,
    )
    out = invoke("validate", str(path))
    assert out.exit_code == 2
    assert "2 problems" in out.output
    assert "speed: found the bare number 9000" in out.output
    assert "sweep.sped: unknown key 'sped'; did you mean 'speed'?" in out.output


def test_study_writes_the_archive_with_overrides_and_progress(tmp_path):
    out = CliRunner().invoke(
        main,
        [
            "study",
            str(STUDIES / "quickstart.yaml"),
            "-o",
            str(tmp_path / "q.nc"),
            "--set",
            "run.revolutions=1",
            "--set",
            "sweep.speed=[9000 rpm, 9524 rpm]",
            "--scheduler",
            "synchronous",
        ],
    )
    assert out.exit_code == 0, out.output + out.stderr
    assert out.stdout.strip() == str(tmp_path / "q.nc")
    assert "4 cases (0 reused, 4 computed in 1 batches)" in out.stderr
    assert re.search(r"\] 4/4 cases, writing the archive\n", out.stderr)
    ds = xr.open_dataset(tmp_path / "q.nc")
    assert ds.sizes["case"] == 4 and ds.sizes["cam_angle"] == 361
    assert '"run.revolutions": 1' in ds.attrs["spec_overrides"]
    assert "campipe study" in ds.attrs["history"]
    again = CliRunner().invoke(
        main,
        [
            "study",
            str(STUDIES / "quickstart.yaml"),
            "-o",
            str(tmp_path / "q.nc"),
            "--set",
            "run.revolutions=1",
            "--set",
            "sweep.speed=[9000 rpm, 9524 rpm]",
        ],
    )
    assert "up to date" in again.stderr


def test_study_refuses_an_unknown_scheduler(tmp_path):
    out = invoke(
        "study",
        str(STUDIES / "quickstart.yaml"),
        "-o",
        str(tmp_path / "q.nc"),
        "--scheduler",
        "thread",
    )
    assert out.exit_code == 2 and "expected one of threads, synchronous, processes" in out.output
    assert not (tmp_path / "q.nc").exists()


@pytest.mark.parametrize("address", ["tpc://127.0.0.1:8786", "http://127.0.0.1:8787"])
def test_study_refuses_a_scheme_dask_does_not_speak(tmp_path, address):
    """A typo'd or HTTP scheme is refused at once naming the schemes and the port (a helper's
    ``tpc://`` and ``http://`` read 'cannot reach ... within 10 s (ValueError)'); nothing is
    written. ``HOST:PORT`` without a scheme is an address, as dask reads it (it was refused as
    a local scheduler's name). Broken copy: check_scheduler telling addresses by '://'."""
    from campipe.study.run.execute import check_scheduler

    out = invoke(
        "study", str(STUDIES / "quickstart.yaml"), "-o", str(tmp_path / "q.nc"),
        "--scheduler", address,
    )  # fmt: skip
    assert out.exit_code == 2, out.output
    assert "dask.distributed speaks tcp, tls" in out.output and "tcp://HOST:PORT" in out.output
    assert not (tmp_path / "q.nc").exists()
    assert check_scheduler("127.0.0.1:8786") is False and check_scheduler("tcp://h:1") is False
    assert check_scheduler("threads") is True


def test_a_command_leaves_its_objects_to_the_operating_system_at_exit():
    """A command's process freezes the garbage collector at exit (``gc.freeze``), after the
    exit handlers registered since it started: the interpreter then does not collect numba's
    object graph. Broken copy: without ``cli._exit_without_collecting``, nothing is frozen."""
    code = (
        "import atexit, gc, sys\n"
        "atexit.register(lambda: print('frozen', gc.get_freeze_count(), file=sys.stderr))\n"
        "from campipe.cli import main\n"
        "main(['schema'], standalone_mode=False)\n"
        "print('unfrozen', gc.get_freeze_count(), file=sys.stderr)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    counts = dict(line.split() for line in out.stderr.splitlines())
    assert int(counts["unfrozen"]) == 0 and int(counts["frozen"]) > 0
    assert out.stdout.startswith("{")  # the command's output, whole


def test_a_reader_closing_the_output_early_ends_the_command_quietly():
    """`campipe validate spec | head -2`: the reader closes the pipe and the command's next
    write fails with EPIPE; the command stops without a message (click's own handling), as
    `git log | head` does. Broken copy: the group mapping BrokenPipeError, an OSError, to
    "Error: Broken pipe" on stderr."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "campipe", "schema"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    proc.stdout.close()  # before the interpreter has started: every write meets a closed pipe
    err = proc.stderr.read()
    assert proc.wait() == 1 and err == ""
