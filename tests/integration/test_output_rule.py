"""One output rule for every command that writes (``campipe.io.outputs``): never the spec,
another study's archive, a netCDF file campipe did not write for the command, or any file
that is not of the kind the command writes, without ``--overwrite``; never the command's
own input; a spec's outputs inside the archive's folder. Each refusal leaves the file's bytes
as they were; the allowed cases (a rerun replacing its own output) still work."""

import os

import pytest
import xarray as xr
from click.testing import CliRunner
from study_helpers import write_spec

from campipe.cli import main

#: Two cases, one turn: an archive cheap enough for every test.
TINY = """
name: tiny
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 1}
sweep:
  speed: [6000 rpm, 9524 rpm]
"""

#: An onset spec named like the tiny study (its default onset archive is onsets-onset.nc,
#: and with search: its archive is onsets.nc).
ONSET = """
name: NAME
model: {preset: thesis-1971}
profile: {kind: harmonic, lift: 1 in}
closure: force
sweep:
  speed: {from: 6000 rpm, to: 14000 rpm, num: 2}
"""


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A folder with the tiny study's spec and archive."""
    folder = tmp_path_factory.mktemp("tiny")
    spec = write_spec(folder, TINY)
    out = invoke("study", spec, "--scheduler", "synchronous", "--no-progress")
    assert out.exit_code == 0, out.output
    return spec, folder / "tiny.nc"


def refused(out, path, before, *words):
    """The command was refused (exit 2), its message names ``words``, and ``path`` holds
    ``before``."""
    assert out.exit_code == 2, out.output
    for w in words:
        assert w in out.output, (w, out.output)
    assert path.read_bytes() == before


# -- campipe onset ------------------------------------------------------------------------


def test_onset_never_writes_over_its_spec(tmp_path):
    """``campipe onset s.yaml -o s.yaml`` turned the spec into HDF5. Broken copy: without the
    spec in check_output's inputs (cli/onset.py) the spec is replaced, and with it named but
    replaceable under --overwrite the second call replaces it."""
    spec = write_spec(tmp_path, ONSET.replace("NAME", "onsets"))
    before = spec.read_bytes()
    out = invoke("onset", spec, "-o", spec, "--no-check")
    refused(out, spec, before, "-o:", "the spec, which this command reads")
    out = invoke("onset", spec, "-o", spec, "--no-check", "--overwrite")
    refused(out, spec, before, "-o:", "the spec")


def test_onset_refuses_another_study_s_archive_and_a_foreign_file(tiny, tmp_path):
    """Another study's archive and a text file at -o are refused without --overwrite (the
    message names the archive's study and the fix); with --overwrite the text file is
    replaced by the onset archive. Broken copy: an onset_kind that accepts any netCDF file
    (or check_output ignoring ``ours``) replaces the study's archive."""
    spec = write_spec(tmp_path, ONSET.replace("NAME", "onsets"))
    archive = tmp_path / "tiny.nc"
    archive.write_bytes(tiny[1].read_bytes())
    before = archive.read_bytes()
    out = invoke("onset", spec, "-o", archive, "--no-check")
    refused(out, archive, before, "the archive of the study tiny", "--overwrite", "(-o)")
    notes = tmp_path / "notes.nc"
    notes.write_text("my notes\n")
    out = invoke("onset", spec, "-o", notes, "--no-check")
    refused(out, notes, b"my notes\n", "a file that is not an onset archive", "--overwrite")
    out = invoke("onset", spec, "-o", notes, "--no-check", "--overwrite")
    assert out.exit_code == 0, out.output
    with xr.open_dataset(notes) as ds:
        assert ds.attrs["campipe_file"] == "onset" and ds.attrs["study_name"] == "onsets"
        assert ds.attrs["spec_file"] == "spec.yaml"


def test_onset_replaces_its_own_archive_not_another_spec_s(tmp_path):
    """A rerun replaces the onset archive of the same spec (exit 0, a new file renamed into
    place); a second spec of the same name in the folder is refused at that file. Broken copy: an
    onset_kind that ignores spec_file lets other.yaml replace spec.yaml's onset archive."""
    spec = write_spec(tmp_path, ONSET.replace("NAME", "onsets"))
    assert invoke("onset", spec, "--no-check").exit_code == 0
    onset = tmp_path / "onsets-onset.nc"
    first = onset.stat().st_ino
    again = invoke("onset", spec, "--no-check")
    assert again.exit_code == 0, again.output
    assert onset.stat().st_ino != first  # written anew and renamed into place
    other = write_spec(tmp_path, ONSET.replace("NAME", "onsets"), name="other.yaml")
    before = onset.read_bytes()
    out = invoke("onset", other, "--no-check")
    refused(out, onset, before, "the onset archive of onsets (spec.yaml)", "--overwrite")


def test_a_search_spec_does_not_write_over_another_study_s_archive(tiny, tmp_path):
    """``campipe study`` of a spec with ``search:`` writes <name>.nc: a study archive of that
    name (another spec's) is refused, unchanged, unless --overwrite. Broken copy: run_onset
    called from cli/study.py without the output check replaces it."""
    archive = tmp_path / "tiny.nc"
    archive.write_bytes(tiny[1].read_bytes())
    before = archive.read_bytes()
    spec = ONSET.replace("NAME", "tiny") + "search: {onset: no-follow, axis: speed}\n"
    path = write_spec(tmp_path, spec, name="search.yaml")
    out = invoke("study", path)
    refused(out, archive, before, "-o:", "the archive of the study tiny", "--overwrite")


# -- campipe replay -----------------------------------------------------------------------


def test_replay_never_writes_over_its_archive_or_spec(tiny, tmp_path):
    """``replay ARCHIVE -o ARCHIVE`` replaced the archive with a recording, ``-o spec.yaml``
    the spec: both refused even with --overwrite (the command's inputs). Broken copy: without
    check_recording's inputs, --overwrite replaces them."""
    spec, archive = tiny
    for target in (archive, spec):
        before = target.read_bytes()
        for extra in ((), ("--overwrite",)):
            out = invoke("replay", archive, "--where", "speed_rpm < 7000", "-o", target, *extra)
            refused(out, target, before, "-o:", "which this command reads")


def test_replay_replaces_a_recording_and_only_with_overwrite_another_file(tiny, tmp_path):
    """A previous recording is replaced (a rerun); a text file is refused without --overwrite
    and replaced with it. Broken copy: RECORDING's ``ours`` accepting any file replaces the
    text file without --overwrite."""
    _, archive = tiny
    rrd = tmp_path / "one.rrd"
    for _ in range(2):
        out = invoke("replay", archive, "--where", "speed_rpm < 7000", "-o", rrd)
        assert out.exit_code == 0, out.output
        assert rrd.read_bytes()[:3] == b"RRF"
    text = tmp_path / "notes.rrd"
    text.write_text("not a recording\n")
    out = invoke("replay", archive, "--where", "speed_rpm < 7000", "-o", text)
    refused(out, text, b"not a recording\n", "a file that is not a rerun recording", "--overwrite")
    out = invoke("replay", archive, "--where", "speed_rpm < 7000", "-o", text, "--overwrite")
    assert out.exit_code == 0 and text.read_bytes()[:3] == b"RRF"


# -- campipe plot and a spec's plots ------------------------------------------------------


def test_plot_refuses_its_archive_and_a_file_of_another_format(tiny, tmp_path):
    """``plot -o`` at the archive is refused even with --overwrite; a text file named x.png is
    refused without --overwrite; a PNG campipe drew is replaced. Broken copy: FIGURE's
    ``ours`` by suffix alone (not the first bytes) replaces the text file."""
    archive = tmp_path / "archive.png"  # an archive at a figure's name
    archive.write_bytes(tiny[1].read_bytes())
    before = archive.read_bytes()
    out = invoke("plot", "histories", archive, "-o", archive, "--overwrite")
    refused(out, archive, before, "-o:", "the archive drawn, which this command reads")
    png = tmp_path / "x.png"
    png.write_text("my notes\n")
    out = invoke("plot", "histories", archive, "-o", png)
    refused(out, png, b"my notes\n", "a file that is not a figure (not a png file)", "--overwrite")
    for extra in (("--overwrite",), ()):  # then a rerun replaces the figure it drew
        out = invoke("plot", "histories", archive, "-o", png, *extra)
        assert out.exit_code == 0, out.output
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("output", ["../precious.pdf", "/tmp/ABSOLUTE/precious.pdf"])
def test_a_spec_s_plot_outside_the_archive_s_folder_is_refused_before_running(tmp_path, output):
    """``plots[].output: ../precious.pdf`` replaced an existing file and an absolute path was
    written: both refused by validate and study before anything runs, naming the key, the
    file unchanged. Broken copy: check_plot without _leaves_folder."""
    folder = tmp_path / "study"
    folder.mkdir()
    precious = tmp_path / "precious.pdf"
    precious.write_bytes(b"%PDF-1.4 mine\n")
    output = output.replace("/tmp/ABSOLUTE", str(tmp_path))
    spec = write_spec(folder, TINY + f"plots:\n  - {{kind: histories, output: {output}}}\n")
    for command in ("validate", "study"):
        out = invoke(command, spec)
        refused(
            out, precious, b"%PDF-1.4 mine\n", "plots[0].output:", "inside the archive's folder"
        )
    assert not (folder / "tiny.nc").exists()


def test_a_spec_s_plot_through_a_link_out_of_the_folder_is_refused(tmp_path):
    """A link inside the folder pointing out of it (``out.pdf -> ../precious.pdf``) passes
    the spec's check but not the rule's: refused at plots[0].output, the file unchanged, the
    archive complete. Broken copy: write_plots without ``inside`` replaces precious.pdf."""
    folder = tmp_path / "study"
    folder.mkdir()
    precious = tmp_path / "precious.pdf"
    precious.write_bytes(b"%PDF-1.4 mine\n")
    (folder / "out.pdf").symlink_to(precious)
    spec = write_spec(folder, TINY + "plots:\n  - {kind: histories, output: out.pdf}\n")
    out = invoke("study", spec, "--overwrite")
    refused(out, precious, b"%PDF-1.4 mine\n", "plots[0].output:", "is outside the folder")
    assert "the archive" in out.output and "is complete" in out.output
    with xr.open_dataset(folder / "tiny.nc") as ds:
        assert ds.sizes["case"] == 2


def test_a_spec_s_plot_never_replaces_the_archive_just_written(tmp_path):
    """An archive written at a figure's name (``-o tiny.png``) and a plot of the same name:
    the plot is refused, even with --overwrite, and the archive stays a netCDF file with its
    two cases. Broken copy: plot_archive without the archive in its inputs."""
    spec = write_spec(tmp_path, TINY + "plots:\n  - {kind: histories, output: tiny.png}\n")
    archive = tmp_path / "tiny.png"
    out = invoke("study", spec, "-o", archive, "--overwrite", "--scheduler", "synchronous")
    assert out.exit_code == 2, out.output
    assert "plots[0].output:" in out.output and "the archive drawn" in out.output
    with xr.open_dataset(archive) as ds:
        assert ds.sizes["case"] == 2


# -- campipe init -------------------------------------------------------------------------


def test_init_never_follows_a_link_out_of_its_folder(tmp_path):
    """A dangling link ``mine/quickstart.yaml -> ../outside.yaml``: init followed it and
    wrote outside its folder. Refused (even with --overwrite), nothing created outside.
    Broken copy: _check_init without ``inside`` (or writing through the link)."""
    folder = tmp_path / "mine"
    folder.mkdir()
    outside = tmp_path / "outside.yaml"
    (folder / "quickstart.yaml").symlink_to(outside)
    for extra in ((), ("--overwrite",)):
        out = invoke("init", folder, *extra)
        assert out.exit_code == 2, out.output
        assert "DIRECTORY:" in out.output and "is outside the folder" in out.output
        assert not outside.exists()
    assert sorted(os.listdir(folder)) == ["quickstart.yaml"]


def test_init_replaces_a_link_inside_its_folder_only_with_overwrite(tmp_path):
    """A dangling link inside the folder is refused without --overwrite; with it the link
    itself is replaced by the example (its target never created); a rerun over identical
    files succeeds. Broken copy: a write through the link creates ``target.yaml``."""
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "quickstart.yaml").symlink_to(folder / "target.yaml")
    out = invoke("init", folder)
    assert out.exit_code == 2 and "a symbolic link to a missing file" in out.output
    assert "--overwrite" in out.output
    out = invoke("init", folder, "--overwrite")
    assert out.exit_code == 0, out.output
    assert not (folder / "quickstart.yaml").is_symlink()
    assert not (folder / "target.yaml").exists()
    again = invoke("init", folder)
    assert again.exit_code == 0, again.output


def test_a_figure_replaces_a_link_at_its_path_not_the_link_s_target(tiny, tmp_path):
    """``plot -o link.png`` where link.png links to another figure: the link is replaced by
    the new figure (written at a temporary name, renamed), the other figure's bytes are
    unchanged. Broken copy: write() saving straight to the path writes through the link."""
    _, archive = tiny
    other = tmp_path / "other.png"
    assert invoke("plot", "events", archive, "-o", other).exit_code == 0
    before = other.read_bytes()
    link = tmp_path / "link.png"
    link.symlink_to(other)
    out = invoke("plot", "histories", archive, "-o", link)
    assert out.exit_code == 0, out.output
    assert not link.is_symlink() and link.read_bytes()[:4] == b"\x89PNG"
    assert other.read_bytes() == before and link.read_bytes() != before
