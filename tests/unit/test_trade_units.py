"""The speed units of the trade (issue 37): ``rpm``, ``rev/min`` and ``r/min`` read alike in
a spec, a ``--set`` and a ``--where``."""

from __future__ import annotations

import math

import pytest

from campipe.study.where import evaluate, parse_where
from campipe.units import parse_angular


@pytest.mark.parametrize("text", ["9000 rpm", "9000 rev/min", "9000 r/min", "150 rev/s"])
def test_a_speed_in_revolutions_per_minute_reads_as_its_radians_per_second(text):
    """9000 revolutions a minute is 9000·2π/60 rad/s (and 150 a second the same). Fails on a
    copy without the trade's aliases: pint knows neither ``rev`` nor ``r``."""
    assert parse_angular(text, "rad/s", "speed", "rpm") == pytest.approx(
        9000 * 2 * math.pi / 60, rel=1e-15
    )


def test_a_where_in_rev_per_min_selects_what_rpm_does():
    """``speed_rpm >= 9524 rev/min`` keeps the same rows as ``speed_rpm >= 9524``."""
    import numpy as np

    columns = {"speed_rpm": np.array([9000.0, 9524.0, 11000.0])}
    units = {"speed_rpm": "rpm"}
    for text in ("speed_rpm >= 9524 rev/min", "speed_rpm >= 9524 r/min"):
        kept = evaluate(parse_where(text), columns, 3, units)
        assert kept.tolist() == [False, True, True]


def test_a_converted_value_reads_at_its_precision_without_conversion_noise():
    """200 lbf, stored in newtons (889.6443230521002 N), reads back as 200.0 lbf in a query's
    table, CSV and JSON; a value stored in the units shown is untouched to the last bit.
    Fails on a copy that prints the conversion as it falls (200.00000000000009 lbf)."""
    import numpy as np

    from campipe.study.query.display import to_display
    from campipe.study.query.tables import CaseTable, displayed, format_rows
    from campipe.units import parse_quantity

    stored = parse_quantity("200 lbf", "N", "x", "lbf")
    assert to_display(np.array([stored]), "N", "lbf")[0] != 200.0  # the noise is there
    exact = 0.1 + 0.2  # 0.30000000000000004: stored as it is shown, kept whole
    table = CaseTable(
        {"spring_preload": np.array([stored]), "ratio": np.array([exact])},
        {"spring_preload": "N", "ratio": ""},
        ["spring_preload", "ratio"],
        1,
    )
    shown = displayed(table, {"spring_preload": "lbf"})
    assert shown.columns["spring_preload"][0] == 200.0
    assert shown.columns["ratio"][0] == exact
    csv = format_rows(shown, np.arange(1), ["spring_preload", "ratio"], "csv")
    assert csv.splitlines()[1] == "200.0,0.30000000000000004"


def test_per_degree_units_divide_by_the_cam_speed_in_degrees_per_second():
    """At 6000 rpm (36000 deg/s) 1 m/s is 1000/36000 mm/deg and 1 m/s² 1000/36000² mm/deg²,
    each row at its own speed; mm and MPa are pure scales. Fails on a copy that divides by ω
    in rad/s (a factor 180/π off) or squares nothing."""
    import numpy as np

    from campipe.units import UNIT_SYSTEMS, convert_values, per_degree

    mm_deg = UNIT_SYSTEMS["mm-deg"]
    assert (mm_deg["m/s"], mm_deg["m/s^2"], mm_deg["Pa"]) == ("mm/deg", "mm/deg^2", "MPa")
    assert per_degree("mm/deg") == ("mm", 1) and per_degree("mm/deg^2") == ("mm", 2)
    assert per_degree("mm") == ("mm", 0)
    v = np.array([[1.0, 2.0], [1.0, 2.0]])
    speeds = np.array([6000.0, 3000.0])
    got = convert_values(v, "m/s", "mm/deg", speeds)
    np.testing.assert_allclose(got, [[1 / 36, 2 / 36], [1 / 18, 2 / 18]], rtol=1e-15)
    acc = convert_values(np.array([1.0]), "m/s^2", "mm/deg^2", 6000.0)
    assert acc[0] == pytest.approx(1000 / 36000**2, rel=1e-15)
    assert convert_values(np.array([2.5e6]), "Pa", "MPa")[0] == pytest.approx(2.5, rel=1e-15)
    # the thesis's units give a contact pressure in psi (it stayed in Pa): 1 psi is
    # 0.45359237 kg × 9.80665 m/s² over (0.0254 m)², by definition
    assert UNIT_SYSTEMS["in-lbf"]["Pa"] == "psi"
    psi = 0.45359237 * 9.80665 / 0.0254**2
    assert convert_values(np.array([1e9]), "Pa", "psi")[0] == pytest.approx(1e9 / psi, rel=1e-12)
    with pytest.raises(ValueError, match="cam speed"):
        convert_values(v, "m/s", "mm/deg")
    with pytest.raises(ValueError, match="not a mm/s"):
        convert_values(v, "N", "mm/deg", speeds)


def test_a_where_per_degree_compares_at_each_case_s_own_speed():
    """``max_seating_velocity > 0.2 mm/deg`` (as ``--units mm-deg`` shows it) keeps the cases
    whose seating velocity over their own cam speed in degrees a second is above 0.2 mm/deg:
    1 m/s is 0.0278 mm/deg at 6000 rpm (36000 deg/s) and 0.139 at 1200 rpm, so the one m/s
    is kept at the slow speed only; ``mm/degCA`` at the engine's speed, ``mm/deg^2`` against
    an acceleration; without the speed it needs, refused naming the drive. Fails on a copy
    that converts at one speed for all, or reads degCA as a cam degree."""
    import numpy as np

    from campipe.study.where import QueryError

    v = np.array([1.0, 1.0, 9.0])  # m/s
    cols = {
        "v": v,
        "speed_rpm": np.array([6000.0, 1200.0, 6000.0]),
        "engine_speed_rpm": np.array([12000.0, 2400.0, 12000.0]),
        "a": np.array([1000.0, 1000.0, 1000.0]),  # m/s²
    }
    units = {"v": "m/s", "speed_rpm": "rpm", "engine_speed_rpm": "rpm", "a": "m/s^2"}

    def kept(text, columns=cols):
        return evaluate(parse_where(text), columns, 3, units).tolist()

    # in mm/deg: 0.0278, 0.139, 0.25
    assert kept("v > 0.1 mm/deg") == [False, True, True]
    assert kept("v > 0.0002 m/deg") == kept("v > 0.2 mm/deg") == [False, False, True]
    # per degree of crank angle, half as much: 0.0139, 0.0694, 0.125
    assert kept("v > 0.1 mm/degCA") == [False, False, True]
    assert kept("v > 0.05 mm/degCA") == [False, True, True]
    # 1000 m/s² is 1e6/36000² = 7.7e-4 mm/deg² at 6000 rpm, 0.0193 at 1200 rpm
    assert kept("a < 0.001 mm/deg^2") == [True, False, True]
    assert kept("a < 0.001 mm/deg**2") == [True, False, True]
    no_drive = {k: c for k, c in cols.items() if k != "engine_speed_rpm"}
    with pytest.raises(QueryError, match="engine_speed_rpm"):
        kept("v > 0.1 mm/degCA", no_drive)
    with pytest.raises(QueryError, match="cannot be compared"):
        kept("v > 0.1 mm/deg^2")


def test_a_limit_line_per_degree_is_drawn_in_the_shown_units_or_refused():
    """A metric's limit line in a length per degree is converted to the column's shown
    per-degree units (0.0002 m/deg on a column in mm/deg: 0.2); against a column shown per
    second (or per degree of the other angle) it is refused naming the units to write, not
    with pint's bare error. Fails on a copy that draws 0.0002 as it is."""
    from types import SimpleNamespace

    from campipe.plot.values import shown_value
    from campipe.study.spec.plots import PlotError

    def view(units):
        return SimpleNamespace(shown=SimpleNamespace(units={"v": units}))

    assert shown_value("0.0002 m/deg", view("mm/deg"), "v", "--limit") == pytest.approx(0.2)
    assert shown_value("0.3 mm/degCA", view("mm/degCA"), "v", "--limit") == pytest.approx(0.3)
    assert shown_value("0.5 m/s", view("mm/s"), "v", "--limit") == pytest.approx(500)
    for value, units in [("0.5 m/s", "mm/deg"), ("0.2 mm/degCA", "mm/deg"), ("1 mm/deg", "m/s")]:
        with pytest.raises(PlotError, match=f"write it in {units}"):
            shown_value(value, view(units), "v", "--limit")


def test_a_label_s_en_dash_matches_the_hyphen_a_designer_types():
    """``defects == "flat 268-272 deg"`` (typed with a hyphen) selects the label campipe
    writes with an en dash (``flat 268–272 deg``), and ``!=`` the others; other text still
    compares exactly. Fails on a copy that compares the text as stored (0 rows, silently)."""
    import numpy as np

    cols = {"defects": np.array(["none", "flat 268–272 deg", "flat 268–270 deg"], dtype=object)}

    def kept(text):
        return evaluate(parse_where(text), cols, 3, {"defects": ""}).tolist()

    assert kept('defects == "flat 268-272 deg"') == [False, True, False]
    assert kept('defects == "flat 268–272 deg"') == [False, True, False]
    assert kept('defects != "flat 268-272 deg"') == [True, False, True]
    assert kept('defects in ["none", "flat 268-270 deg"]') == [True, False, True]
    assert kept('defects == "flat 268 272 deg"') == [False, False, False]


@pytest.mark.parametrize(
    "sweep",
    [
        "  profile.lift: [0.9 in, 1 in]",
        "  profile: [{kind: harmonic, lift: 0.9 in}, {kind: harmonic, lift: 1 in}]",
        "  model: [{preset: thesis-1971, spring_preload: 151 lbf}]",
    ],
)
def test_a_spec_writing_inches_only_in_a_sweep_of_whole_blocks_shows_in_inches(sweep):
    """A spec whose only lengths are inches inside a sweep is an inch spec (`--units spec`
    shows in-lbf), whether it sweeps a key or whole profiles (a helper's was shown in SI).
    Broken copy: the sweep's list of mappings left unread."""
    from campipe.study.query.display import spec_system, written_units

    text = "name: s\nmodel: {preset: thesis-1971}\nspeed: 6000 rpm\nsweep:\n" + sweep + "\n"
    assert spec_system(written_units({"spec": text})) == "in-lbf"
