"""campipe plot spectrum: the order spectrum of a history over the last turn, against the
closed-form steady state (a second method) for a harmonic cam, whose only order is the
first."""

import math

import numpy as np
import pytest
from click.testing import CliRunner
from study_helpers import write_spec

from campipe.cli import main
from campipe.constants import INCH, RPM
from campipe.engine import Case
from campipe.engine import periodic as P
from campipe.model import thesis_train
from campipe.plot import plot_archive
from campipe.plot.spectrum import order_spectrum
from campipe.profiles import harmonic
from campipe.study import load_study
from campipe.study.run.execute import run_study
from campipe.study.spec.plots import PlotError, PlotRequest

SPEC = """
name: spectra
model: {preset: thesis-1971}
profile: {kind: harmonic, lift: 1 in}
run: {revolutions: 2, output_every: 1 deg}
sweep:
  speed: [3000 rpm, 6000 rpm]
"""


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    d = tmp_path_factory.mktemp("spectrum")
    run_study(load_study(write_spec(d, SPEC)), d / "spectra.nc", scheduler="synchronous")
    return d / "spectra.nc"


def test_order_spectrum_of_cosines():
    """A sum of cosines of amplitudes 3 (order 2) and 0.5 (order 7) on a mean of 1 reads
    back as those amplitudes at those orders and nothing elsewhere. Broken copy: the
    amplitude without the factor 2 (half) or the mean doubled: off by 2x."""
    theta = np.arange(360) * 2 * np.pi / 360
    signal = 1.0 + 3.0 * np.cos(2 * theta + 0.3) + 0.5 * np.cos(7 * theta)
    amp = order_spectrum(signal[None, :])[0]
    assert amp[0] == pytest.approx(1.0) and amp[2] == pytest.approx(3.0)
    assert amp[7] == pytest.approx(0.5)
    assert np.max(np.delete(amp, [0, 2, 7])) < 1e-12


def test_a_harmonic_cam_s_valve_acceleration_is_its_first_order(archive, tmp_path):
    """At 6000 rpm (below the onset, following the cam) the harmonic cam drives a linear
    train with its first order only: the spectrum's order-1 bar equals the closed-form
    steady state's valve acceleration amplitude to 0.1 %, every other order is under 1e-3
    of it. Broken copy: the spectrum over all recorded samples (two turns with the end
    point: a leaking window) puts several per cent into orders 2 and beyond."""
    path, fig = plot_archive(archive, PlotRequest("spectrum", where="speed_rpm == 6000",
                                                  units="si"), tmp_path / "s.png")  # fmt: skip
    assert path.exists()
    bars = [p for p in fig.axes[0].patches]
    heights = np.array([b.get_height() for b in bars])
    orders = np.array([b.get_x() + b.get_width() / 2 for b in bars])
    st = P.steady_state([Case(thesis_train(), harmonic(INCH), 6000 * RPM)], math.radians(1.0))
    acc = st.acc[0, :-1, 1]  # q7's acceleration: the valve opening's
    first = heights[np.argmin(np.abs(orders - 1))]
    assert first == pytest.approx(0.5 * np.ptp(acc), rel=1e-3)
    assert np.max(heights[np.abs(orders - 1) > 0.5]) < 1e-3 * first
    assert fig.axes[0].get_xlabel() == "Order of the cam's rotation [-]"
    # titled as every figure: the study, what, and the selection
    assert fig.get_suptitle().endswith(
        "order spectrum of valve acceleration, last turn — where speed_rpm == 6000"
    )


def test_the_command_draws_it_and_refuses_a_non_history(archive, tmp_path):
    """`campipe plot spectrum` writes the figure; --y naming a per-case value (not a
    history) is refused at --y, listing the histories."""
    args = ["plot", "spectrum", str(archive), "--where", "speed_rpm == 3000"]
    out = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "a.png")])
    assert out.exit_code == 0, out.output
    assert (tmp_path / "a.png").stat().st_size > 1000
    with pytest.raises(PlotError) as info:
        plot_archive(archive, PlotRequest("spectrum", y="max_cam_force"), tmp_path / "b.png")
    assert info.value.key == "--y" and "valve_acceleration" in str(info.value)


def test_a_map_s_colour_scale_reads_small_values():
    """No-follow from 0 to 30° a turn with cells at 0.002 and 0.02: a logarithmic scale
    (linear below the least positive value) puts them a fifth of the bar apart, where a
    linear one puts them 0.0006 apart; a span of one decade stays linear. Broken copy:
    colour_norm always linear: the two cells' colours are the same."""
    from matplotlib.colors import SymLogNorm

    from campipe.plot.style import colour_norm

    z = np.array([0.0, 0.002, 0.02, 0.5, 30.0, np.nan])
    norm = colour_norm(z)
    assert isinstance(norm, SymLogNorm)
    assert norm(0.02) - norm(0.002) > 0.15 and norm(0.0) == 0.0 and norm(30.0) == 1.0
    assert not isinstance(colour_norm(np.array([1.0, 5.0, 9.0])), SymLogNorm)
    assert not isinstance(colour_norm(np.array([-1.0, 0.001, 9.0])), SymLogNorm)
