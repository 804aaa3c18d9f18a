"""The documentation tells the truth: its bench figures are those the committed bench.json
holds."""

import re

import pytest
from study_helpers import ROOT

from campipe.bench import pages, report

BENCH_JSON = ROOT / pages.BENCH_JSON
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
    assert pages.block_names(README.read_text()) == ["bench-verdict"]
    assert sorted(pages.block_names(BENCH_PAGE.read_text())) == sorted(pages.BLOCKS)


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
    issue3 = next(line for line in lines if "case-steps/s on 2 workers" in line)
    assert issue3.startswith("- **not reached** (issue 3)") and "**1.23e7 case-steps/s**" in issue3
    first = bench.checks[0]["scene"]
    assert f"- cross-check on {first}: **disagrees**" in changed


def test_the_pages_command_checks_and_rewrites(tmp_path, capsys):
    folder = tmp_path / "bench"
    folder.mkdir()
    json_path = folder / "bench.json"
    json_path.write_bytes(BENCH_JSON.read_bytes())
    page = tmp_path / "page.md"
    stale = "Intro.\n\n<!-- generated: bench-issue4 -->\n1.17×\n<!-- end generated -->\nEnd.\n"
    page.write_text(stale)
    args = ["--json", str(json_path), str(page)]
    assert pages.main(["--check", *args]) == 1
    assert page.read_text() == stale and not (folder / "bench.csv").exists()
    assert f"{page}: differs from {json_path}" in capsys.readouterr().out
    assert pages.main(args) == 0
    assert pages.main(["--check", *args]) == 0
    head, body, tail = page.read_text().split("generated")
    assert head == "Intro.\n\n<!-- " and tail == " -->\nEnd.\n"
    assert body.startswith(": bench-issue4 -->\nOn separation-11000 the default reaches")
    assert "**1.17×**" in body  # the committed run's figure, now from the json
    assert (folder / "bench.csv").read_bytes() == (BENCH_JSON.parent / "bench.csv").read_bytes()
    page.write_text("<!-- generated: no-such-block -->\n<!-- end generated -->\n")
    with pytest.raises(KeyError, match="unknown generated block 'no-such-block'"):
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
