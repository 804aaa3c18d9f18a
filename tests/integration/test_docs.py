"""The documentation tells the truth: its bench figures are those the committed bench.json
and study.json hold, and the README's commands and analysis print what it shows."""

import contextlib
import functools
import io
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner
from study_helpers import ROOT

from campipe.bench import pages, report
from campipe.cli import main

if str(ROOT) not in sys.path:  # benchmarks/ is not installed: imported from the repository
    sys.path.insert(0, str(ROOT))

from benchmarks import pages as study_pages  # noqa: E402

BENCH_JSON = ROOT / pages.BENCH_JSON
STUDY_JSON = ROOT / study_pages.STUDY_JSON
README = ROOT / "README.md"
BENCH_PAGE = ROOT / "docs" / "bench.md"
DOCS = [README, *sorted((ROOT / "docs").glob("*.md")), ROOT / "examples" / "README.md"]


def test_the_committed_pages_are_generated_from_the_committed_bench_json():
    bench = report.read_json(BENCH_JSON)
    expected = pages.rendered(bench, BENCH_JSON, [README, BENCH_PAGE])
    folder = BENCH_JSON.parent
    assert set(expected) == {README, BENCH_PAGE, folder / "bench.md", folder / "bench.csv"}
    for path, text in expected.items():
        assert path.read_bytes() == text.encode(), (
            f"{path.relative_to(ROOT)} differs from what {pages.BENCH_JSON} gives: "
            "run python -m campipe.bench.pages"
        )
    assert pages.block_names(README.read_text()) == ["bench-onset", "bench-verdict"]
    names = pages.block_names(BENCH_PAGE.read_text())
    assert sorted(n for n in names if n.startswith("bench-")) == sorted(pages.BLOCKS)
    assert sorted(n for n in names if n.startswith("study-")) == sorted(study_pages.BLOCKS)
    assert len(names) == len(pages.BLOCKS) + len(study_pages.BLOCKS)


def test_the_developer_benchmarks_figures_are_generated_from_the_committed_study_json():
    """docs/bench.md's study blocks are what benchmarks.pages writes from study.json, and
    python -m benchmarks.pages --check, run from the root as documented, says so."""
    data = study_pages.read_json(STUDY_JSON)
    expected = study_pages.rendered(data, [BENCH_PAGE])
    assert BENCH_PAGE.read_bytes() == expected[BENCH_PAGE].encode(), (
        f"docs/bench.md differs from what {study_pages.STUDY_JSON} gives: "
        "run python -m benchmarks.pages"
    )
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.pages", "--check"],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
    )
    assert (done.returncode, done.stdout) == (0, ""), done.stderr
    # The figures moved from bench.json unchanged: the 1000-case goal's, from the json.
    at = next(r for r in data["study"]["sizes"] if r["n_cases"] == 1000)
    goal = next(
        line for line in expected[BENCH_PAGE].splitlines() if "1000-case study end to end" in line
    )
    assert f"**{pages.format_short(at['wall'], 2)} s against " in goal
    assert "study" not in json.loads(BENCH_JSON.read_text())
    assert {p["layer"] for p in report.read_json(BENCH_JSON).scaling} == {"engine"}
    assert {p["layer"] for p in data["scaling"]} == {"study"}


def test_a_study_figure_that_changes_in_its_json_changes_only_its_blocks():
    data = study_pages.read_json(STUDY_JSON)
    text = BENCH_PAGE.read_text()
    data["study"]["latencies"]["help"] = 0.61
    changed = study_pages.render(text, study_pages.blocks(data), study_pages.PREFIX)
    goal = next(line for line in changed.splitlines() if "campipe --help under" in line)
    assert goal.startswith("- **not reached** (study)") and "**0.61 s**" in goal
    assert "`campipe --help` 0.61 s;" in changed
    # campipe.bench.pages leaves the study blocks as they are, and the other way round
    bench_blocks = pages.blocks(report.read_json(BENCH_JSON))
    assert pages.render(changed, bench_blocks) == changed


def test_a_figure_that_changes_in_the_json_changes_the_pages():
    bench = report.read_json(BENCH_JSON)
    text = README.read_text()
    row = next(
        t for t in bench.throughput if t["integrator"] == "newmark-linear" and t["workers"] == 2
    )
    row["rate"] = 1.23e7
    bench.checks[0]["agrees"] = False
    changed = pages.render(text, pages.blocks(bench))
    assert changed != text
    lines = changed.splitlines()
    goal = next(line for line in lines if "case-steps/s on 2 workers" in line)
    assert goal.startswith("- **not reached** (throughput)") and "**1.23e7 case-steps/s**" in goal
    first = bench.checks[0]["scene"]
    assert f"- cross-check on {first}: **disagrees**" in changed


def test_the_pages_command_checks_and_rewrites(tmp_path, capsys):
    folder = tmp_path / "bench"
    folder.mkdir()
    json_path = folder / "bench.json"
    json_path.write_bytes(BENCH_JSON.read_bytes())
    page = tmp_path / "page.md"
    stale = "Intro.\n\n<!-- generated: bench-accuracy -->\n1.17×\n<!-- end generated -->\nEnd.\n"
    page.write_text(stale)
    args = ["--json", str(json_path), str(page)]
    assert pages.main(["--check", *args]) == 1
    assert page.read_text() == stale and not (folder / "bench.csv").exists()
    assert f"{page}: differs from {json_path}" in capsys.readouterr().out
    assert pages.main(args) == 0
    assert pages.main(["--check", *args]) == 0
    head, body, tail = page.read_text().split("generated")
    assert head == "Intro.\n\n<!-- " and tail == " -->\nEnd.\n"
    assert body.startswith(": bench-accuracy -->\nOn separation-11000 the default reaches")
    ratio = report.read_json(BENCH_JSON).accuracy_for_cost["ratio"]
    assert f"**{pages.format_short(ratio)}×**" in body  # the committed run's figure, from the json
    assert (folder / "bench.csv").read_bytes() == (BENCH_JSON.parent / "bench.csv").read_bytes()
    # another generator's block is left as it is; an unknown block of its own is refused
    other = "<!-- generated: study-verdict -->\nkept\n<!-- end generated -->\n"
    page.write_text(other)
    assert pages.main(args) == 0 and page.read_text() == other
    page.write_text("<!-- generated: bench-no-such-block -->\n<!-- end generated -->\n")
    with pytest.raises(KeyError, match="unknown generated block 'bench-no-such-block'"):
        pages.main(args)


def _prose(text: str) -> str:
    """``text`` without its generated blocks, code, link targets and comments."""
    text = pages.BLOCK.sub("", text)
    text = re.sub(r"```.*?```", "", text, flags=re.DOTALL)
    text = re.sub(r"`[^`]*`", "", text)
    text = re.sub(r"\]\([^)]*\)", "]", text)
    text = re.sub(r"<!--.*?-->", "", text, flags=re.DOTALL)
    return re.sub(r"\bissue \d+\b", "issue", text)


def test_the_bench_prose_carries_no_figure():
    """Figures of the bench come only from its json: none in the hand-written text around the
    generated blocks (the issue numbers aside)."""
    readme = README.read_text().split("\n## Speed against error\n")[1].split("\n## ")[0]
    for name, text in (("docs/bench.md", BENCH_PAGE.read_text()), ("README.md", readme)):
        figures = re.findall(r"\S*\d\S*", _prose(text))
        assert not figures, f"{name}: figures outside the generated blocks: {figures}"
    assert _prose("a 1.17× margin (issue 4) <!-- generated: x -->\n2e7\n<!-- end generated -->")
    assert re.findall(r"\S*\d\S*", _prose("a 1.17× margin")) == ["1.17×"]


def _slug(heading: str) -> str:
    """GitHub's anchor of a markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


@pytest.mark.parametrize("page", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_of_the_docs_resolves(page):
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
    links = re.findall(r"\]\(([^)\s]+)\)", text)
    assert links
    for link in links:
        if re.match(r"[a-z]+://", link):
            continue
        target, _, anchor = link.partition("#")
        path = (page.parent / target).resolve() if target else page
        assert path.exists(), f"{page.name}: {link}"
        if anchor:
            headings = re.findall(r"^#+ (.*)$", path.read_text(), flags=re.MULTILINE)
            assert anchor in {_slug(h) for h in headings}, f"{page.name}: {link}"


def test_the_readme_keeps_its_two_set_up_commands_and_its_length():
    """Tools find the set-up commands by these patterns; the README stays a first page."""
    lines = README.read_text().splitlines()
    run = [line for line in lines if re.match(r"^\s*python -m pip install [^[]*&& campipe ", line)]
    assert run[0] == "python -m pip install . && campipe study studies/quickstart.yaml"
    tests = [line for line in lines if re.search(r"pip install .*\[test\].*pytest", line)]
    assert tests[0] == 'python -m pip install ".[test]" && python -m pytest'
    assert next(line for line in lines if re.match(r"^\s*(\$ )?[^#]*pytest", line)) == tests[0]
    assert len(lines) <= 200


def _fenced_after(text: str, marker: str) -> str:
    """The body of the first fenced block after ``<!-- marker -->``."""
    after = text.split(f"<!-- {marker} -->\n", 1)[1]
    return after.split("```", 2)[1].split("\n", 1)[1]


@functools.cache
def readme_outputs():
    """``docs/readme_outputs.py`` as a module (the docs' script, not installed)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "readme_outputs", ROOT / "docs" / "readme_outputs.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


NUMBER = re.compile(r"^[-+]?(\d+\.?\d*(e[-+]?\d+)?|nan)$", re.IGNORECASE)


def test_the_readme_analysis_prints_what_the_readme_shows(quickstart_archive, monkeypatch):
    text = README.read_text()
    code = _fenced_after(text, "readme-analysis")
    shown = _fenced_after(text, "readme-analysis-output").split()
    assert len(code.strip().splitlines()) == 5
    monkeypatch.chdir(quickstart_archive.parents[1])  # the README's studies/quickstart.nc
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README.md", "exec"), {})
    printed = out.getvalue().split()
    assert [t for t in printed if not NUMBER.match(t)] == [t for t in shown if not NUMBER.match(t)]
    values = [float(t) for t in printed if NUMBER.match(t)]
    # the table: 4 speeds × (none, 0.1 in): no separation at 9000 rpm without a seat
    assert values[0] == 0.00254 and printed[:3] == ["seat", "none", "0.00254"]
    table = np.array(values[1:]).reshape(4, 3)
    assert table[:, 0].tolist() == [6000, 9000, 9524, 11000]
    assert table[1, 1] == 0 and 45 <= table[2, 1] <= 60 and np.all(table[:, 2] > 0)
    never = readme_outputs().never_repeating(quickstart_archive)
    assert readme_outputs().analysis_differences(out.getvalue(), " ".join(shown), never) == []


def test_the_readme_summary_is_what_campipe_query_prints(quickstart_archive):
    text = README.read_text()
    shown = text.split("$ campipe query studies/quickstart.nc --summary\n")[1].split("```")[0]
    archive = quickstart_archive
    result = CliRunner().invoke(main, ["query", str(archive), "--summary"])
    assert result.exit_code == 0, result.output
    # a never-repeating case's mean ± standard error follows the platform's round-off
    # (readme_outputs.never_repeating): the same text, the means within three standard errors
    assert readme_outputs().summary_differences(result.output, shown) == []


def test_the_known_disagreement_is_explained_while_the_json_shows_it():
    """docs/bench.md explains why polydyne-9000's cross-check disagrees; once a run agrees, the
    paragraph must go with it."""
    bench = report.read_json(BENCH_JSON)
    disagrees = {c["scene"] for c in bench.checks if not c["agrees"]}
    explained = (
        "**A known disagreement.** On the form-closed polydyne scene" in BENCH_PAGE.read_text()
    )
    assert explained == ("polydyne-9000" in disagrees)


def test_the_readme_damping_note_is_the_model_s():
    """The README's note on the preset's ζ1 is generated from the model (docs/readme_outputs.py);
    its dashpot is checked by hand: the first mode's generalised mass per unit valve motion
    times 2·ζ1·ω1 (modal damping's definition), and the drag at 9000 rpm is that dashpot
    times the valve's peak velocity, the rocker ratio times the cam's ω·h/2."""
    module = readme_outputs()
    note = module.damping_note()
    assert note in README.read_text()
    from campipe.constants import INCH, LBF
    from campipe.model import system_matrices, thesis_train

    train = thesis_train()
    sm = system_matrices(train)
    shape = sm.modes[:, 0] / sm.modes[6, 0]
    dashpot = 2 * train.damping_ratios[0] * sm.frequencies[0] * (shape @ sm.mass @ shape)
    drag = dashpot * 1.5 * 9000 * np.pi / 30 * INCH / 2 / LBF
    assert f"{dashpot:.0f} N·s/m" in note and 250 < drag < 260 and f"{drag:.0f} lbf" in note


def test_the_readme_figure_is_drawn_by_the_script_with_the_readmes_command():
    """docs/readme_outputs.py draws docs/quickstart-metric.png with `campipe plot metric`, the
    README's first plot command, on a fresh quickstart run (never by hand)."""
    module = readme_outputs()
    text = README.read_text()
    figure = module.FIGURE.relative_to(ROOT).as_posix()
    assert f"]({figure})" in text
    assert f"campipe {' '.join(module.PLOT)} studies/quickstart.nc" in text
    assert module.FIGURE.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
