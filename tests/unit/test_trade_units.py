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
