"""Plots a scientist would put in a talk: a second swept parameter as colour (legend or colour bar),
log axes where a parameter spans a decade or more, a legend on every curve plot. Synthetic
ensembles (no run): the figures only read the Dataset; the space-time maps read small recorded runs
(N = 21, through a file, as `warpfric plot` does)."""

import warnings

import numpy as np
import pytest
import xarray as xr
from conftest import run
from matplotlib.contour import ContourSet

import warpfric as wf
from warpfric import plots
from warpfric.io import open_ensemble, write_ensemble


@pytest.fixture(autouse=True)
def close_figures():
    """Each test's figures closed after it (matplotlib warns from the 21st open figure on)."""
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


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


def test_small_linear_values_share_a_power_of_ten_instead_of_long_tick_labels():
    """A disc velocity swept over [-1e-4, 1e-4] m/s: its ticks were written out (-0.000100,
    -0.000075, ...) and overlapped; now short numbers and a x 10^-4 beside the axis."""
    velocity = np.array([-1e-4, -5e-5, 0.0, 5e-5, 1e-4])
    ds = ensemble(np.full(5, 1000.0), np.zeros(5)).assign(
        disc_velocity=("member", velocity, {"units": "m s-1"}))
    ds.attrs["varying_parameters"] = "disc_velocity"
    fig = plots.mu_s_figure(ds, "disc_velocity")
    ax = fig.axes[0]
    fig.canvas.draw()
    labels = [t.get_text().replace("$\\mathdefault{", "").replace("}$", "") for t in ax.get_xticklabels()]
    assert ax.get_xscale() == "linear" and labels, labels
    assert max(len(t) for t in labels) <= 5, labels  # e.g. -1.00 (a minus sign and three digits)
    assert "10^{" in ax.xaxis.get_offset_text().get_text() and "4" in ax.xaxis.get_offset_text().get_text()
    fig = plots.mu_s_figure(ds.assign(disc_velocity=("member", velocity * 1e3 + 0.5)), "disc_velocity")
    fig.canvas.draw()  # values near 0.5 m/s: written out, no power of ten
    assert fig.axes[0].xaxis.get_offset_text().get_text() == ""


def test_one_member_is_one_member_in_legends_and_titles():
    ds = ensemble(np.array([1000.0, 2000.0]), np.zeros(2))
    ds["status"] = ("member", np.array([0, 1], np.int32), {"flag_values": np.array([0, 1], np.int32),
                                                          "flag_meanings": "ok max_steps_reached"})
    ds.attrs["varying_parameters"] = "normal_force"
    ax = plots.mu_s_figure(ds, "normal_force").axes[0]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["1 ok member",
                                                                   "1 member not ok (no mu_s), on the axis"]
    # the member not ok is marked at its x on the axis (a figure of the ok members' x alone hid its value)
    marks = [line for line in ax.get_lines() if line.get_marker() == "x"]
    assert len(marks) == 1 and list(marks[0].get_xdata()) == [2000.0] and list(marks[0].get_ydata()) == [0.0]
    assert ax.get_xlim()[0] < 1000.0 and ax.get_xlim()[1] > 2000.0
    speeds = plots.front_speeds_figure(ds, "normal_force").axes[0]
    assert speeds.get_title().endswith("(1 ok member; 1 max_steps_reached)") and "v_middle (1 member)" in [
        t.get_text() for t in speeds.get_legend().get_texts()]


def test_a_third_swept_parameter_is_named_in_the_titles(grid):
    """Three swept parameters: x and colour show two, the third's members share the axes; the titles
    say so, with its number of values (a constant one is not named)."""
    three = grid.assign(disc_velocity=("member", np.tile([1e-4, 1e-3, 1e-2], 5), {"units": "m s-1"}),
                        damping=("member", np.zeros(grid.sizes["member"]), {"units": "Pa s m-1"}))
    note = "also varying, not told apart: v (3 values)"
    fig = plots.mu_s_figure(three, "normal_force", "eccentricity", mixed=("disc_velocity", "damping"))
    assert fig.axes[0].get_title().endswith("\n" + note)
    fig = plots.front_speeds_figure(three, "normal_force", "eccentricity", mixed=("disc_velocity",))
    assert fig._suptitle.get_text() == "detachment front speeds, first front's segments (15 ok members)\n" + note
    assert "also varying" not in plots.mu_s_figure(grid, "normal_force", "eccentricity").axes[0].get_title()


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
    # short panel titles (they overlapped beside a colour bar); the figure's title says whose segments
    assert [ax.get_title().split(" segment")[0] for ax in panels] == ["left", "middle", "right"]
    assert fig._suptitle.get_text().startswith("detachment front speeds, first front's segments")
    # v_left is absent at 2e/L = 0.2; the legend (on the last panel) still names it
    texts = [t.get_text() for t in panels[-1].get_legend().get_texts()]
    assert texts == ["2e/L = -0.2", "2e/L = 0", "2e/L = 0.2"]
    single = plots.front_speeds_figure(grid, "normal_force")
    assert len(single.axes) == 1 and len(single.axes[0].get_legend().get_texts()) == 3


def test_a_second_front_gets_its_own_panel_where_a_member_has_one(grid):
    """v_second is drawn where some ok member has a second front (4 panels), not where none has."""
    two = grid.assign(v_second=("member", np.where(grid.eccentricity.values < 0, 30.0, np.nan), {"units": "m s-1"}))
    fig = plots.front_speeds_figure(two, "normal_force", colour_by="eccentricity")
    assert [ax.get_title() for ax in fig.axes][3] == "second front, 5 members"
    single = plots.front_speeds_figure(two, "normal_force")
    assert [t.get_text() for t in single.axes[0].get_legend().get_texts()][-1] == "v_second (5 members)"
    none = grid.assign(v_second=("member", np.full(grid.sizes["member"], np.nan), {"units": "m s-1"}))
    assert len(plots.front_speeds_figure(none, "normal_force", colour_by="eccentricity").axes) == 3


def test_arrival_time_curves_have_a_legend_with_their_swept_values(grid):
    fig = plots.arrival_times_figure(grid)
    ax = fig.axes[0]
    legend = ax.get_legend()
    assert legend is not None and len(ax.get_lines()) == len(legend.get_texts()) == plots.MAX_CURVES
    assert legend.get_texts()[0].get_text() == "F = 100 N, 2e/L = -0.2"
    assert "8 of the 15 ok members with a front" in ax.get_title()
    assert {line.get_linestyle() for line in ax.get_lines()} == {"-", "--", ":"}  # eccentricity as the line style


def test_quick_look_writes_every_figure(grid, tmp_path):
    written = plots.quick_look(grid, tmp_path)
    assert sorted(p.name for p in written) == sorted([
        "mu_s_vs_normal_force.png", "front_speeds_vs_normal_force.png", "mu_s_vs_eccentricity.png",
        "front_speeds_vs_eccentricity.png", "arrival_times.png"])
    assert all(p.stat().st_size > 10_000 for p in written)
    one = grid.assign_attrs(varying_parameters="")
    assert [p.name for p in plots.quick_look(one, tmp_path / "none")] == ["mu_s_histogram.png", "arrival_times.png"]


def recorded_run(path, fronts, end_time=20.3):
    """Two recorded members through a file: member 0 detaches at t ~ 20.13 s; member 1's disc stops
    at 20.03 s, 30 ms after it started and long before a node yields, so it has no front (status
    no_peak, every arrival time NaN). The run ends at ``end_time``, after the detachment of the
    contact and strength fronts (20.27-20.28 s); the velocity front's ends at 20.48 s."""
    ds = run({"stop_time": [np.inf, 20.03]}, scene=wf.Parameters(end_time=end_time), nodes=21, fronts=fronts,
             record=wf.Record.window(20.05, end_time, int(round((end_time - 20.05) / 0.005)) + 1, members=(0, 1)))
    write_ensemble(ds, path)
    return open_ensemble(path)


@pytest.fixture(scope="module")
def contact_run(tmp_path_factory):
    return recorded_run(tmp_path_factory.mktemp("contact") / "rec.nc", wf.Fronts())  # the default front


MEETS = "where the first front meets another"


def arrival_lines(ax):
    """{legend label: (x, y)} of the curves on a space-time map (not the meeting-point markers)."""
    return {line.get_label(): tuple(np.asarray(d, dtype=float) for d in line.get_data()) for line in ax.get_lines()
            if MEETS not in line.get_label()}


def meeting_marks(ax):
    """{legend label: (x, t)} of the meeting-point markers on a space-time map."""
    return {line.get_label(): tuple(float(np.asarray(d)[0]) for d in line.get_data()) for line in ax.get_lines()
            if MEETS in line.get_label()}


def contours(ax):
    return [c for c in ax.collections if isinstance(c, ContourSet)]


def test_the_space_time_map_draws_the_contact_fronts_arrival_times(contact_run):
    ds = contact_run
    assert ds.attrs["fronts_event"] == "contact" and "event_max_velocity" not in ds  # only the velocity event has it
    ta = ds.arrival_time.values[0]
    assert np.isfinite(ta).all()
    fig = plots.space_time_figure(ds, 0)
    ax = fig.axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (mm)", "t (s)")
    lines = arrival_lines(ax)
    assert list(lines) == ["contact front: arrival time t_a"]
    x, t = lines["contact front: arrival time t_a"]
    np.testing.assert_array_equal(x, ds.x.values * 1e3)  # x along the horizontal axis, in mm
    np.testing.assert_array_equal(t, ta)  # t_a (s) along the vertical one
    lo, hi = ax.get_ylim()
    assert lo <= ta.min() and ta.max() <= hi  # inside the recorded window, not stretching it
    assert (lo, hi) == pytest.approx((20.05 - 0.0025, 20.3 + 0.0025))
    # the default scene's two contact fronts meet: a marker at the meeting point, named in the legend
    marks = meeting_marks(ax)
    assert list(marks) == [f"contact front: {MEETS}"]
    assert marks[f"contact front: {MEETS}"] == pytest.approx(
        (float(ds.collision_position.values[0]) * 1e3, float(ds.collision_time.values[0])))
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["contact front: arrival time t_a",
                                                                        f"contact front: {MEETS}"]
    # the legend lies below the map: inside it covered the later fronts' curves (an audit's figure)
    fig.canvas.draw()
    assert ax.get_legend().get_window_extent().y1 < ax.get_window_extent().y0
    assert not contours(ax)  # the threshold contour belongs to the velocity event
    # the default scene's contact front is two fronts: the meeting point is marked on the curve
    ax = plots.arrival_times_figure(ds).axes[0]
    assert int(ds.front_count.values[0]) == 2
    assert ax.get_title() == ("contact front arrival times (1 of the 1 ok member with a front; 1 no_peak; "
                              "\u25bd where two fronts meet: 1)")
    (mx, my), = [line.get_data() for line in ax.get_lines() if line.get_label() == "_meeting"]
    assert mx[0] == pytest.approx(float(ds.collision_position.values[0]) * 1e3)
    assert my[0] == pytest.approx((float(ds.collision_time.values[0]) - ta.min()) * 1e3)
    assert my[0] == pytest.approx((ta.max() - ta.min()) * 1e3)  # the latest arrival, where the fronts meet


def test_the_curve_skips_nodes_the_front_did_not_reach_and_keeps_the_recorded_window(contact_run):
    ta = contact_run.arrival_time.values.copy()
    ta[0, 8:12] = np.nan  # a front that reached both ends but not the middle
    ds = contact_run.assign(arrival_time=contact_run.arrival_time.copy(data=ta))
    (x, t), = arrival_lines(plots.space_time_figure(ds, 0).axes[0]).values()
    assert np.isnan(x).sum() == np.isnan(t).sum() == 1  # one break in the line, not a line across the gap
    reached = np.isfinite(ta[0])
    np.testing.assert_array_equal(x[np.isfinite(x)], ds.x.values[reached] * 1e3)
    np.testing.assert_array_equal(t[np.isfinite(t)], ta[0, reached])
    later = contact_run.assign_coords(time=contact_run.time + 1.0)  # a window after the front
    ax = plots.space_time_figure(later, 0).axes[0]
    assert list(arrival_lines(ax)) == ["contact front: arrival time t_a (outside the recorded times)"]
    assert ax.get_ylim() == pytest.approx((21.05 - 0.0025, 21.3 + 0.0025))


def test_a_member_without_a_front_gets_no_curve(contact_run, tmp_path):
    ds = contact_run
    assert np.isnan(ds.arrival_time.values[1]).all()
    ax = plots.space_time_figure(ds, 1).axes[0]
    assert not ax.get_lines() and not contours(ax)
    # no_peak: its front outputs are NaN whether or not a front ran (fig11's stopped member shows one
    # on the map), so not "no contact front"
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["contact front: not given (status no_peak)"]
    # an ok member whose run saw its detachment through (detachment_end_time given) reached no node
    ok = ds.assign(status=ds.status.copy(data=np.zeros(ds.sizes["member"], np.int32)),
                   detachment_end_time=ds.final_time.copy())
    ax = plots.space_time_figure(ok, 1).axes[0]
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["no contact front"]
    # one whose run ended before it (an explicit end_time inside the front) has its fronts NaN: not "no front"
    cut = ok.assign(detachment_end_time=ok.detachment_end_time.copy(data=np.full(ok.sizes["member"], np.nan)))
    ax = plots.space_time_figure(cut, 1).axes[0]
    assert [text.get_text() for text in ax.get_legend().get_texts()] == [
        "contact front: not given (the run ended before the detachment was over)"]
    # and the arrival times of a file of it alone said "no ok member has a contact front"
    ax = plots.arrival_times_figure(cut.isel(member=[1])).axes[0]
    assert "(no ok member with a known front" in ax.get_title()
    assert [t.get_text() for t in ax.texts] == [
        "no ok member's contact front is known: 1 run ended before the detachment was over"]
    # beside a member that saw its detachment through without a front, that one has none
    first = np.arange(cut.sizes["member"]) == 0
    mixed = cut.assign(detachment_end_time=cut.detachment_end_time.where(~first, cut.final_time),
                       arrival_time=cut.arrival_time.where(~first[:, None])).isel(member=[0, 1])
    ax = plots.arrival_times_figure(mixed).axes[0]
    assert "(no ok member with a known front" in ax.get_title()
    assert [t.get_text() for t in ax.texts] == [
        "no ok member has a known contact front: 1 of 2 ended before the detachment was over, the others have none"]
    # so is one stopped by max_end_time under the automatic end (it said "no contact front")
    n = ok.sizes["member"]
    capped = ok.assign(end_time=("member", np.full(n, np.inf)), max_end_time=ok.final_time.copy())
    ax = plots.space_time_figure(capped, 1).axes[0]
    assert [text.get_text() for text in ax.get_legend().get_texts()] == [
        "contact front: not given (the run ended before the detachment was over)"]
    failed = ds.copy()
    failed["status"] = failed.status.copy(data=np.where(np.arange(failed.sizes["member"]) == 1,
                                                          failed.status.attrs["flag_meanings"].split().index("stalled"),
                                                          failed.status.values))
    ax = plots.space_time_figure(failed, 1).axes[0]
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["contact front: not given (status stalled)"]
    written = plots.quick_look(ds, tmp_path)
    assert {"space_time_member0.png", "space_time_member1.png"} <= {p.name for p in written}
    # a run without fronts at all: the map alone
    bare = ds.drop_vars([name for name in ds.data_vars if "member" in ds[name].dims and "x" in ds[name].dims])
    ax = plots.space_time_figure(bare, 0).axes[0]
    assert not ax.get_lines() and ax.get_legend() is None


def test_the_velocity_event_adds_its_threshold_contour(tmp_path):
    """Velocity first (its outputs unprefixed), contact second (``contact_arrival_time``): both curves,
    and the contour of threshold x event_max_velocity on the recorded field."""
    ds = recorded_run(tmp_path / "rec.nc", wf.Fronts(event=("velocity", "contact")), end_time=20.5)
    assert np.isfinite(ds.event_max_velocity.values[0]) and np.isfinite(ds.contact_arrival_time.values[0]).all()
    ax = plots.space_time_figure(ds, 0).axes[0]
    lines = arrival_lines(ax)
    assert sorted(lines) == ["contact front: arrival time t_a", "velocity front: arrival time t_a"]
    ta = ds.arrival_time.values[0]
    np.testing.assert_array_equal(lines["velocity front: arrival time t_a"][1], ta[np.isfinite(ta)])
    np.testing.assert_array_equal(lines["contact front: arrival time t_a"][1], ds.contact_arrival_time.values[0])
    assert len(contours(ax)) == 1 and contours(ax)[0].levels == pytest.approx([0.4 * ds.event_max_velocity.values[0]])
    assert "velocity front: 0.4 x event maximum (recorded)" in [text.get_text() for text in ax.get_legend().get_texts()]
    assert list(meeting_marks(ax)) == [f"contact front: {MEETS}"]  # the velocity front here is one front
    ax = plots.space_time_figure(ds, 1).axes[0]
    assert not ax.get_lines() and not contours(ax)
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["velocity front: not given (status no_peak)",
                                                                        "contact front: not given (status no_peak)"]


def legend_texts(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_an_infinite_parameter_value_is_a_legend_entry_and_counted_off_the_axis(grid):
    """stop_time = inf (no stop) against 20.5: the inf members were dropped from the figures while
    the title counted them (a sweep of end_time with inf gave empty figures)."""
    stops = np.where(np.arange(grid.sizes["member"]) % 2 == 0, np.inf, 20.5)
    ds = grid.assign(stop_time=("member", stops, {"units": "s"}))
    ds.attrs["varying_parameters"] = "normal_force stop_time"
    ax = plots.mu_s_figure(ds, "normal_force", "stop_time").axes[0]
    assert legend_texts(ax) == ["t_stop = 20.5 s", "t_stop = inf s"]
    assert sum(line.get_xdata().size for line in ax.get_lines()) == ds.sizes["member"]  # every member drawn
    ax = plots.mu_s_figure(ds, "stop_time", "normal_force").axes[0]
    assert "; 8 members at stop_time = inf not on the axis)" in ax.get_title()


def test_all_negative_velocities_spanning_decades_get_a_log_axis_of_their_magnitude(grid):
    """-1e-3, -1e-4, -1e-5 m/s on a linear axis put the last two on top of each other at 0."""
    ds = grid.isel(member=[0, 1, 2]).assign(disc_velocity=("member", [-1e-3, -1e-4, -1e-5], {"units": "m s-1"}))
    ax = plots.mu_s_figure(ds, "disc_velocity").axes[0]
    assert ax.get_xscale() == "log" and ax.get_xlabel() == "|disc velocity v| (m/s), all negative"
    np.testing.assert_allclose(np.sort(ax.get_lines()[0].get_xdata()), [1e-5, 1e-4, 1e-3])


def test_figures_with_nothing_to_show_say_why(grid):
    """All members failed: the figures had made-up axes (-0.04..0.04) and said '0 of 3 members ok'
    only; they say which statuses and that there is nothing to show, with no axes."""
    failed = grid.assign(status=grid.status.copy(data=np.ones(grid.sizes["member"], np.int32)))
    failed.status.attrs["flag_meanings"] = "ok max_steps_reached"
    for fig in (plots.mu_s_figure(failed, "normal_force"), plots.front_speeds_figure(failed, "normal_force"),
                plots.arrival_times_figure(failed)):
        ax = fig.axes[0]
        assert "; 15 max_steps_reached" in ax.get_title() and not ax.get_xticks().size
        assert [t.get_text() for t in ax.texts][0].startswith("no ")
    # quick_look's histogram (no swept parameter) had an empty panel with axes -0.04..0.04
    ax = plots.mu_s_histogram_figure(failed.assign_attrs(varying_parameters="")).axes[0]
    assert ax.get_title() == "mu_s of 15 members (0 ok; 15 max_steps_reached)" and not ax.get_xticks().size
    assert [t.get_text() for t in ax.texts] == ["no member has a mu_s to show"] and not ax.patches
    ax = plots.mu_s_histogram_figure(grid.assign_attrs(varying_parameters="")).axes[0]
    assert sum(p.get_height() for p in ax.patches) == 15 and ax.get_title() == "mu_s of 15 members (15 ok)"


def test_a_file_opened_with_xarray_itself_plots_by_member_number(contact_run, tmp_path):
    """xr.open_dataset leaves a file's members as string labels ('<run id>:0000000000') and its
    recorded fields in the group 'recorded': the arrival-time curves of a file without a swept
    parameter raised "invalid literal for int()", and the recorded figures said to run with
    record=. The curves are labelled by member number; the recorded figures say how to open the
    file."""
    path = write_ensemble(contact_run.sel(member=[0]).isel(recorded=[0]).assign_attrs(varying_parameters=""),
                          tmp_path / "one.nc")
    with xr.open_dataset(path) as raw:
        assert raw.member.dtype.kind in "OSU"
        ax = plots.arrival_times_figure(raw).axes[0]
        assert [line.get_label() for line in ax.get_lines()] == ["member 0", "_meeting"]
        memory = plots.arrival_times_figure(contact_run.sel(member=[0])).axes[0]
        np.testing.assert_array_equal(ax.get_lines()[0].get_ydata(), memory.get_lines()[0].get_ydata())
        for figure in (plots.friction_history_figure, plots.space_time_figure):
            with pytest.raises(ValueError, match="group 'recorded'; open the file with warpfric.io.open_ensemble"):
                figure(raw, 0)
        # quick_look draws what the root group holds, and says where the recorded fields are
        with pytest.warns(UserWarning, match="recorded fields are not drawn .*group 'recorded'.*open_ensemble"):
            assert [p.name for p in plots.quick_look(raw, tmp_path / "raw")] == ["arrival_times.png"]
        # the group merged in by hand: still the file's string labels, refused with the same advice
        with xr.open_dataset(path, group="recorded") as group:
            merged = xr.merge([raw, group])
            with pytest.raises(ValueError, match="a file opened with xarray itself.*open_ensemble"):
                plots.friction_history_figure(merged, 0)
            with pytest.warns(UserWarning, match="recorded fields are not drawn"):
                plots.quick_look(merged, tmp_path / "merged")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a file without recorded fields: nothing to say
        plain = write_ensemble(contact_run.sel(member=[0]).drop_dims(["recorded", "time"]).assign_attrs(
            varying_parameters=""), tmp_path / "plain.nc")
        with xr.open_dataset(plain) as raw:
            assert [p.name for p in plots.quick_look(raw, tmp_path / "plain")] == ["arrival_times.png"]


def test_misuse_is_named(grid, contact_run):
    """by_parameters views, a DataArray, a wrong name, a run without fronts and a wrong recorded
    index raised KeyError, AttributeError or IndexError without naming the problem."""
    with pytest.raises(ValueError, match="a by_parameters view"):
        plots.mu_s_figure(wf.io.by_parameters(grid), "normal_force")
    with pytest.raises(ValueError, match=r"got dimensions \('member', 'x'\) without the variable status"):
        plots.mu_s_figure(grid.drop_vars("status").assign(member_number=grid.member), "normal_force")
    with pytest.raises(ValueError, match="quick_look: expects the ensemble's xarray Dataset .* got DataArray"):
        plots.quick_look(grid.mu_s, "unused")
    with pytest.raises(ValueError, match=r"'ecc' is not a parameter of the ensemble; valid: .* normal_force, eccentricity"):
        plots.mu_s_figure(grid, "ecc")
    with pytest.raises(ValueError, match="no front outputs"):
        plots.front_speeds_figure(grid.drop_vars(["v_left", "v_middle", "v_right", "arrival_time"]), "normal_force")
    with pytest.raises(ValueError, match=r"recorded_index = 5; valid: 0..1, .*numbers 0, 1"):
        plots.space_time_figure(contact_run, 5)


def test_a_selection_without_a_recorded_member_and_times_after_the_end(contact_run, tmp_path):
    """quick_look on ds.sel(member=[...]) that leaves a recorded member out raised IndexError; times
    after a member's end (NaN) were white, the colour of zero velocity: grey, and said so."""
    written = plots.quick_look(contact_run.sel(member=[0]), tmp_path)
    assert "space_time_member0.png" in {p.name for p in written} and "space_time_member1.png" not in {p.name for p in written}
    v = contact_run.velocity_history.values.copy()
    v[0, 30:] = np.nan  # the member ended before the window's end
    ds = contact_run.assign(velocity_history=contact_run.velocity_history.copy(data=v))
    ax = plots.space_time_figure(ds, 0).axes[0]
    end = float(ds.final_time.values[0])
    assert f"not recorded: after the run's end (t = {end:.6g} s)" in legend_texts(ax)
    mesh = ax.collections[0]
    assert mesh.cmap.get_bad()[:3] == pytest.approx((0.8, 0.8, 0.8))
    assert ax.get_title() == "member 0: pad velocity (t_stop = inf s)"


def test_write_ensemble_keeps_integer_outputs_integer(tmp_path):
    """ds.where(..., drop=True) turns status and the step counts into floats, and the file broke CF
    (flag_values int against a float variable); a where() without drop leaves NaN statuses: refused."""
    ds = run({"eccentricity": [0.0, 0.1, 0.2]}, nodes=11, rtol=1e-4, fronts=wf.Fronts())
    picked = ds.where(ds.eccentricity > 0.05, drop=True)
    assert picked.status.dtype.kind == "f"
    back = open_ensemble(write_ensemble(picked, tmp_path / "w.nc"))
    assert (back.status.dtype, back.steps_accepted.dtype, back.nucleation_edge.dtype) == (np.int32, np.int32, np.int8)
    np.testing.assert_array_equal(back.steps_accepted.values, ds.steps_accepted.values[1:])
    with pytest.raises(ValueError, match="'status' is float64 with 1 NaN values .*drop=True"):
        write_ensemble(ds.where(ds.eccentricity > 0.05), tmp_path / "x.nc")
    with pytest.raises(ValueError, match=r"'steps_accepted' holds values that are not whole numbers \(e.g. [0-9]+\.5\)"):
        write_ensemble(ds.assign(steps_accepted=ds.steps_accepted / 1.0 + 0.5), tmp_path / "x.nc")
    with pytest.raises(ValueError, match="expects the ensemble's Dataset along the dimension member .* got DataArray"):
        write_ensemble(ds.mu_s, tmp_path / "x.nc")


def test_members_at_inf_beside_a_colour_bar_are_counted():
    """More colour values than a legend holds: a colour bar, which has no colour for inf; those
    members were left out without a word."""
    rng = np.random.default_rng(3)
    ds = ensemble(rng.uniform(200, 5000, 20), np.zeros(20))
    stops = np.where(np.arange(20) < 4, np.inf, 20.2 + 0.01 * np.arange(20))
    ds = ds.assign(stop_time=("member", stops, {"units": "s"}))
    ax = plots.mu_s_figure(ds, "normal_force", "stop_time").axes[0]
    assert ax.get_title().endswith("; 4 members at stop_time = inf not shown (no colour for inf))")
    fig = plots.front_speeds_figure(ds, "normal_force", "stop_time")
    assert "4 members at stop_time = inf not shown" in fig._suptitle.get_text()


def test_members_not_ok_are_in_the_legend_of_a_coloured_mu_s_figure(grid):
    """With a colour per eccentricity (two swept parameters: quick_look's case) the legend listed the
    colour levels only, so the grey marks of the members not ok on the axis were not explained."""
    failed = grid.copy()
    status = np.zeros(failed.sizes["member"], np.int32)
    status[[2, 7]] = 1
    failed["status"] = ("member", status, {"flag_values": np.array([0, 1], np.int32),
                                           "flag_meanings": "ok max_steps_reached"})
    fig = plots.mu_s_figure(failed, "normal_force", colour_by="eccentricity")
    ax = fig.axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts[-1] == "2 members not ok (no mu_s), on the axis" and len(texts) == 4  # 3 eccentricities + it
    marks = [line for line in ax.get_lines() if line.get_marker() == "x"]
    assert len(marks) == 1 and sorted(marks[0].get_xdata()) == sorted(failed.normal_force.values[[2, 7]])


def test_a_second_title_line_sits_above_the_panels_titles(grid):
    """With a third swept parameter the front-speed figure's two-line title ran over its panels'
    titles ('also varying, not told apart' over 'middle segment')."""
    three = grid.assign(disc_velocity=("member", np.tile([1e-4, 1e-3, 1e-2], 5), {"units": "m s-1"}))
    fig = plots.front_speeds_figure(three, "normal_force", "eccentricity", mixed=("disc_velocity",))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    foot = fig._suptitle.get_window_extent(renderer).y0
    tops = [ax.title.get_window_extent(renderer).y1 for ax in fig.axes if ax.get_title()]
    assert len(tops) == 3 and foot >= max(tops), (foot, tops)


def test_a_log_axis_over_many_decades_is_labelled_in_powers_of_ten():
    """F from 316 N to 1e9 N: every decade was labelled as a plain number up to 1e7 ('10000100000')
    and then as '1e+07'; now powers of ten, at most MAX_LOG_TICKS of them."""
    ds = ensemble(np.logspace(2.5, 9, 8), np.zeros(8))
    ds.attrs["varying_parameters"] = "normal_force"
    fig = plots.mu_s_figure(ds, "normal_force")
    ax = fig.axes[0]
    fig.canvas.draw()
    lo, hi = ax.get_xlim()
    labels = [t.get_text() for t in ax.get_xticklabels() if t.get_text() and lo <= t.get_position()[0] <= hi]
    assert 3 <= len(labels) <= plots.MAX_LOG_TICKS and all("10^{" in t for t in labels), labels
    assert not any("e+" in t or "0000" in t for t in labels), labels


def test_a_series_line_breaks_at_a_member_that_is_not_ok():
    """The line of the ok members joined 300 N to 3000 N across the member at 1000 N that failed,
    drawing a trend where there is no value."""
    ds = ensemble(np.array([100.0, 300.0, 1000.0, 3000.0, 10000.0]), np.zeros(5))
    ds["status"] = ("member", np.array([0, 0, 1, 0, 0], np.int32), {"flag_values": np.array([0, 1], np.int32),
                                                                     "flag_meanings": "ok max_steps_reached"})
    ds.attrs["varying_parameters"] = "normal_force"
    ax = plots.mu_s_figure(ds, "normal_force").axes[0]
    line = next(line for line in ax.get_lines() if line.get_label() == "4 ok members")
    np.testing.assert_array_equal(line.get_xdata(), [100.0, 300.0, np.nan, 3000.0, 10000.0])
    assert np.isnan(line.get_ydata()[2]) and np.isfinite(np.delete(line.get_ydata(), 2)).all()


def test_velocities_of_both_signs_over_decades_get_a_symmetric_log_axis():
    """+-1e-5, +-1e-4 and +-1e-3 m/s on a linear axis: the four smallest lay on top of each other at 0."""
    velocity = np.array([-1e-3, -1e-4, -1e-5, 1e-5, 1e-4, 1e-3])
    ds = ensemble(np.full(6, 1000.0), np.zeros(6)).assign(disc_velocity=("member", velocity, {"units": "m s-1"}))
    ds.attrs["varying_parameters"] = "disc_velocity"
    ax = plots.mu_s_figure(ds, "disc_velocity").axes[0]
    assert ax.get_xscale() == "symlog"
    shown = ax.transData.transform(np.column_stack([velocity, np.full(6, 0.51)]))[:, 0]
    assert np.diff(shown).min() > 0.08 * (shown[-1] - shown[0])  # evenly apart, none on top of another
    small = plots.mu_s_figure(ds.assign(disc_velocity=("member", velocity * 0 + [-2, -1, -0.5, 0.5, 1, 2],
                                                       {"units": "m s-1"})), "disc_velocity")
    assert small.axes[0].get_xscale() == "linear"  # less than two decades: linear
    grid = ensemble(np.full(7, 1000.0), np.arange(-0.3, 0.31, 0.1))  # its "0" is 5.6e-17: round-off, not a decade
    grid.attrs["varying_parameters"] = "eccentricity"
    assert plots.mu_s_figure(grid, "eccentricity").axes[0].get_xscale() == "linear"


def test_arrival_curves_that_would_look_alike_get_colours_of_their_own(grid):
    """Coloured by the first swept parameter and styled by the second only up to four values: a
    second of more values (or a third) gave curves of the same colour and style."""
    swapped = grid.copy()
    swapped.attrs["varying_parameters"] = "eccentricity normal_force"  # 3 colours, F's 5 values no styles
    ax = plots.arrival_times_figure(swapped).axes[0]
    looks = [(line.get_color(), line.get_linestyle()) for line in ax.get_lines() if line.get_label() != "_meeting"]
    assert len(looks) == plots.MAX_CURVES and len(set(looks)) == len(looks), looks


def test_one_far_member_runs_off_the_arrival_axis_instead_of_flattening_the_others(grid):
    arrival = grid.arrival_time.values.copy()
    arrival[7] = 20.2 + 100 * (arrival[7] - 20.2)  # its front 100 times slower
    ds = grid.assign(arrival_time=grid.arrival_time.copy(data=arrival))
    ax = plots.arrival_times_figure(ds, max_curves=15).axes[0]  # every member a curve
    spans = np.nanmax(arrival, axis=1) - np.nanmin(arrival, axis=1)
    others = np.delete(spans, 7)
    assert ax.get_ylim()[1] == pytest.approx(1.1 * others.max() * 1e3)
    off = [t for t in legend_texts(ax) if "off the axis" in t]
    assert len(off) == 1 and f"to {spans[7] * 1e3:.3g} ms" in off[0]


def test_a_histogram_of_one_value_shows_that_value():
    """Six equal mu_s: numpy's automatic bins were the value +- 0.5, one bar from 0.01 to 1.01."""
    ds = ensemble(np.full(6, 1000.0), np.zeros(6)).assign(mu_s=("member", np.full(6, 0.5104), {"units": "1"}))
    ax = plots.mu_s_histogram_figure(ds).axes[0]
    (bar,) = ax.patches
    assert bar.get_x() < 0.5104 < bar.get_x() + bar.get_width() and bar.get_width() < 1e-2 and bar.get_height() == 6
    assert legend_texts(ax) == ["6 ok members, all at 0.5104"]


def test_a_map_with_nothing_recorded_has_no_colour_scale(contact_run):
    """A member that ended before its recording window got an all-grey map with a colour bar of
    +-1e9 nm/s, a scale of nothing."""
    ds = contact_run.assign(velocity_history=contact_run.velocity_history * np.nan)
    fig = plots.space_time_figure(ds, 0)
    assert not colour_bar(fig) and any("nothing recorded" in t.get_text() for t in fig.axes[0].texts)
    assert len(colour_bar(plots.space_time_figure(contact_run, 0))) == 1


def test_a_front_has_one_colour_in_both_figures_of_a_member(contact_run):
    """The contact front was black on the space-time map and green in mu(t), where green is the
    strength front's colour on the map."""
    from matplotlib.colors import to_rgb

    span = next(p for p in plots.friction_history_figure(contact_run, 0).axes[0].patches
                if "contact front" in p.get_label())
    curve = next(line for line in plots.space_time_figure(contact_run, 0).axes[0].get_lines()
                 if line.get_label().startswith("contact front: arrival"))
    assert to_rgb(span.get_facecolor()) == to_rgb(curve.get_color())


def test_figures_leave_pyplot_and_its_backend_alone(grid, contact_run):
    """The figures chose pyplot's Agg backend, which in a notebook switched its inline display off for
    the session; they are Figures of their own now, with no pyplot figure to close."""
    import matplotlib
    import matplotlib.pyplot as plt

    before = matplotlib.get_backend()
    plt.close("all")
    matplotlib.use("pdf")  # a backend of the user's, not Agg
    try:
        figures = [plots.mu_s_figure(grid, "normal_force", "eccentricity"), plots.arrival_times_figure(grid),
                   plots.space_time_figure(contact_run, 0), plots.friction_history_figure(contact_run, 0)]
        assert matplotlib.get_backend() == "pdf" and plt.get_fignums() == []
        assert all(type(fig.canvas).__name__ == "FigureCanvasAgg" for fig in figures)
    finally:
        matplotlib.use(before)


def test_a_map_of_round_off_velocities_says_so(contact_run):
    """A member that failed before the disc moved recorded velocities of +-2e-23 m/s; the colour bar
    stretched to +-2e-14 nm/s, true but read as structure. The map says they are round-off; a real
    run's map does not."""
    ds = contact_run.assign(velocity_history=contact_run.velocity_history * 1e-20)
    texts = [t.get_text() for t in plots.space_time_figure(ds, 0).axes[0].texts]
    assert any(t.startswith("round-off only: |v| <= ") for t in texts), texts
    ds = contact_run.assign(velocity_history=contact_run.velocity_history * 0.0)  # (its colours: +-1 m/s)
    assert "round-off only: v = 0" in [t.get_text() for t in plots.space_time_figure(ds, 0).axes[0].texts]
    assert not any("round-off" in t.get_text() for t in plots.space_time_figure(contact_run, 0).axes[0].texts)
