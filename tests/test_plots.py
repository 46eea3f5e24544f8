"""Plots a scientist would put in a talk: a second swept parameter as colour (legend or colour bar),
log axes where a parameter spans a decade or more, a legend on every curve plot. Synthetic
ensembles (no run): the figures only read the Dataset."""

import numpy as np
import pytest
import xarray as xr

from warpfric import plots


def ensemble(force, ecc, nodes=11, seed=0):
    """Members over (force, ecc) pairs with made-up outputs of the right kinds."""
    rng = np.random.default_rng(seed)
    n = force.size
    x = np.linspace(-0.1, 0.1, nodes)
    arrival = 20.2 + 1e-3 * (x[None, :] - ecc[:, None] * 0.1) ** 2 + 1e-7 * force[:, None]
    ds = xr.Dataset(
        {"normal_force": ("member", force, {"units": "N"}), "eccentricity": ("member", ecc, {"units": "1"}),
         "status": ("member", np.zeros(n, np.int32)), "mu_s": ("member", 0.51 + 1e-4 * rng.random(n), {"units": "1"}),
         "v_left": ("member", np.where(ecc < 0.1, 5 + rng.random(n), np.nan), {"units": "m s-1"}),
         "v_middle": ("member", 10 + 300 * rng.random(n), {"units": "m s-1"}),
         "v_right": ("member", 1 + rng.random(n), {"units": "m s-1"}),
         "arrival_time": (("member", "x"), arrival, {"units": "s"})},
        coords={"member": np.arange(n), "x": ("x", x, {"units": "m"})},
        attrs={"varying_parameters": "normal_force eccentricity"})
    return ds


@pytest.fixture
def grid():
    force, ecc = np.meshgrid([100.0, 300.0, 1000.0, 3000.0, 10000.0], [-0.2, 0.0, 0.2], indexing="ij")
    return ensemble(force.ravel(), ecc.ravel())


def colour_bar(fig):
    return [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]


def test_a_decade_spanning_parameter_gets_a_log_axis_and_the_second_a_legend(grid):
    fig = plots.mu_s_figure(grid, "normal_force", colour_by="eccentricity")
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "linear"
    legend = ax.get_legend()
    assert legend is not None and legend.get_title().get_text() == "eccentricity 2e/L"
    assert [t.get_text() for t in legend.get_texts()] == ["2e/L = -0.2", "2e/L = 0", "2e/L = 0.2"]
    assert len(ax.get_lines()) == 3  # one line per eccentricity, joined along F
    fig.canvas.draw()
    labels = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
    assert {"100", "1000", "10000"} <= set(labels) and not any("10^" in t or "e+" in t for t in labels)
    other = plots.mu_s_figure(grid, "eccentricity", colour_by="normal_force")
    assert other.axes[0].get_xscale() == "linear"
    texts = [t.get_text() for t in other.axes[0].get_legend().get_texts()]
    assert texts == ["F = 100 N", "F = 300 N", "F = 1000 N", "F = 3000 N", "F = 10000 N"]


def test_many_values_of_the_second_parameter_get_a_colour_bar():
    rng = np.random.default_rng(1)
    ds = ensemble(np.exp(rng.uniform(np.log(200), np.log(5000), 40)), rng.uniform(-0.2, 0.2, 40))
    fig = plots.mu_s_figure(ds, "eccentricity", colour_by="normal_force")
    bars = colour_bar(fig)
    assert len(bars) == 1 and bars[0].get_ylabel() == "normal force F (N)" and bars[0].get_yscale() == "log"
    fig = plots.front_speeds_figure(ds, "normal_force", colour_by="eccentricity")
    assert len(colour_bar(fig)) == 1 and len(fig.axes) == 4  # three segments and the bar
    assert all(ax.get_xscale() == "log" and ax.get_yscale() == "log" for ax in fig.axes[:3])


def test_front_speeds_one_panel_per_segment_with_every_value_in_the_legend(grid):
    fig = plots.front_speeds_figure(grid, "normal_force", colour_by="eccentricity")
    panels = fig.axes
    assert [ax.get_title().split(" segment")[0] for ax in panels] == ["left", "middle", "right"]
    # v_left is absent at 2e/L = 0.2; the legend (on the last panel) still names it
    texts = [t.get_text() for t in panels[-1].get_legend().get_texts()]
    assert texts == ["2e/L = -0.2", "2e/L = 0", "2e/L = 0.2"]
    single = plots.front_speeds_figure(grid, "normal_force")
    assert len(single.axes) == 1 and len(single.axes[0].get_legend().get_texts()) == 3


def test_arrival_time_curves_have_a_legend_with_their_swept_values(grid):
    fig = plots.arrival_times_figure(grid)
    ax = fig.axes[0]
    legend = ax.get_legend()
    assert legend is not None and len(ax.get_lines()) == len(legend.get_texts()) == plots.MAX_CURVES
    assert legend.get_texts()[0].get_text() == "F = 100 N, 2e/L = -0.2"
    assert "8 of 15 members" in ax.get_title()
    assert {line.get_linestyle() for line in ax.get_lines()} == {"-", "--", ":"}  # eccentricity as the line style


def test_quick_look_writes_every_figure(grid, tmp_path):
    written = plots.quick_look(grid, tmp_path)
    assert sorted(p.name for p in written) == sorted([
        "mu_s_vs_normal_force.png", "front_speeds_vs_normal_force.png", "mu_s_vs_eccentricity.png",
        "front_speeds_vs_eccentricity.png", "arrival_times.png"])
    assert all(p.stat().st_size > 10_000 for p in written)
    one = grid.assign_attrs(varying_parameters="")
    assert [p.name for p in plots.quick_look(one, tmp_path / "none")] == ["mu_s_histogram.png", "arrival_times.png"]
