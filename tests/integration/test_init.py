"""Starting without the repository: campipe init writes the packaged example specs (the
repository's studies/ is a copy of them), campipe schema prints the packaged schema."""

import json

from click.testing import CliRunner
from study_helpers import ROOT, STUDIES

from campipe.cli import main
from campipe.cli.model import packaged_specs
from campipe.study import load_study


def test_studies_is_a_copy_of_the_packaged_specs():
    """One source: campipe/specs/ ships in the package; studies/ must hold the same files
    (after editing one, copy it over, or run: campipe init studies --force)."""
    packaged = packaged_specs()
    in_repository = {
        p.name: p.read_bytes() for p in STUDIES.iterdir() if p.suffix in (".yaml", ".md")
    }
    assert packaged == in_repository
    assert {"quickstart.yaml", "separation-map.yaml", "thesis-seat.yaml", "README.md"} <= set(
        packaged
    )
    assert len([n for n in packaged if n.startswith("thesis-")]) == 6


def test_the_package_data_declares_the_specs():
    text = (ROOT / "pyproject.toml").read_text()
    assert 'campipe = ["py.typed", "specs/*.yaml", "specs/*.md"]' in text


def test_init_writes_the_specs_and_refuses_to_overwrite(tmp_path):
    target = tmp_path / "mine"
    runner = CliRunner()
    result = runner.invoke(main, ["init", str(target)])
    assert result.exit_code == 0, result.output
    written = sorted(p.name for p in target.iterdir())
    assert written == sorted(packaged_specs())
    assert result.stdout.splitlines() == [str(target / n) for n in sorted(packaged_specs())]
    assert f"next: campipe study {target / 'quickstart.yaml'}" in result.stderr
    for path in target.glob("*.yaml"):
        study = load_study(path)  # every example checks and expands
        assert study.cases and study.name == path.stem
    assert runner.invoke(main, ["init", str(target)]).exit_code == 0  # identical: left
    (target / "quickstart.yaml").write_text("name: edited\n")
    (target / "README.md").write_text("notes\n")
    again = runner.invoke(main, ["init", str(target)])
    assert again.exit_code == 2
    assert (
        f"DIRECTORY: {target / 'README.md'} exists and is a file that is not the example "
        "campipe wrote; choose another path (DIRECTORY), or replace it with --overwrite "
        "(and 1 more of the example files)"
    ) in again.output
    assert (target / "quickstart.yaml").read_text() == "name: edited\n"
    forced = runner.invoke(main, ["init", str(target), "--force"])  # --overwrite's old name
    assert forced.exit_code == 0
    assert (target / "quickstart.yaml").read_bytes() == packaged_specs()["quickstart.yaml"]


def test_schema_prints_the_study_and_model_schemas():
    runner = CliRunner()
    study = runner.invoke(main, ["schema"])
    assert study.exit_code == 0
    assert study.output == (ROOT / "schemas" / "study.schema.json").read_text()
    model = runner.invoke(main, ["schema", "model"])
    assert json.loads(model.output) == json.loads(
        (ROOT / "schemas" / "model.schema.json").read_text()
    )
    assert json.loads(study.output)["properties"]["plots"]["type"] == "array"
