"""Lift tables from CSV: units from the header, clear refusals naming file and line."""

import math

import pytest
from numpy.testing import assert_allclose, assert_array_equal

from campipe.io.lift_table import LiftTableError, read_lift_table


def write(tmp_path, text):
    path = tmp_path / "cam.csv"
    path.write_text(text)
    return path


def test_units_come_from_the_header(tmp_path):
    path = write(tmp_path, "# cam 17\n\nangle [deg],lift [in]\n0,0\n90,0.5\n180,1\n270,0.5\n")
    angles, lifts, units = read_lift_table(path)
    assert_allclose(angles, [0, math.pi / 2, math.pi, 3 * math.pi / 2], rtol=1e-15)
    assert_array_equal(lifts, [0, 0.5 * 0.0254, 0.0254, 0.5 * 0.0254])
    assert units == "in"
    angles, lifts, units = read_lift_table(write(tmp_path, "angle [rad], lift [mm]\n0,1\n1,2\n"))
    assert_array_equal(angles, [0, 1])
    assert_allclose(lifts, [1e-3, 2e-3], rtol=1e-15)
    assert units == "mm"


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("", "empty"),
        ("angle,lift\n0,0\n", "where 'angle [units]' belongs"),
        ("lift [in],angle [deg]\n0,0\n", "where 'angle [units]' belongs"),
        ("angle [m],lift [in]\n0,0\n", "angle"),
        ("angle [deg],lift [deg]\n0,0\n", "lift"),
        ("angle [deg],lift [in],x [in]\n0,0,0\n", "expected a header"),
        ("angle [deg],lift [in]\n0,0\n10,zero\n", "cam.csv:3: found 'zero' in column 2"),
        ("angle [deg],lift [in]\n0,0\n10,nan\n", "cam.csv:3: found 'nan'"),
        ("angle [deg],lift [in]\n0,0\n10\n", "cam.csv:3: expected 2 values"),
    ],
)
def test_bad_files_are_refused_with_file_and_line(tmp_path, text, words):
    with pytest.raises(LiftTableError, match="cam.csv") as info:
        read_lift_table(write(tmp_path, text))
    assert words in str(info.value)


def test_a_missing_file_is_refused(tmp_path):
    with pytest.raises(LiftTableError, match="cannot read"):
        read_lift_table(tmp_path / "none.csv")


@pytest.mark.parametrize(
    "text",
    [
        "root:$6$saltsalt$abcdefghijklmnop:19000:0:99999:7:::\ndaemon:*:19000::::::\n",
        "angle [deg],lift [in]\n0,0\n10,hunter2!secret:password\n",
        "user=admin;pass=s3cr3t!,x\n0,0\n",
    ],
)
def test_a_file_that_is_no_table_is_refused_without_its_content(tmp_path, text):
    """Issue 39, item 11: a path such as /etc/shadow given as a lift table: the error names
    the file and line, never the text in it. Broken copy, _read_header: the first line
    quoted (the excerpt of the header): the secret is in the message."""
    with pytest.raises(LiftTableError, match="cam.csv") as info:
        read_lift_table(write(tmp_path, text))
    message = str(info.value).replace(str(tmp_path), "")
    assert "(not shown)" in message
    for secret in ("root", "saltsalt", "hunter2", "s3cr3t", "admin"):
        assert secret not in message
