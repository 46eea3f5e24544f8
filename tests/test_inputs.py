"""Every invalid input raises ValueError naming the parameter, the value and the valid range,
before any kernel runs."""

import dataclasses

import numpy as np
import pytest
from conftest import DEVICE, run

import warpfric as wf
from warpfric.members import resolve_members


def simulate(members=None, device=DEVICE, **kw):
    return wf.simulate(members, device=device, progress=False, **kw)


@pytest.mark.parametrize(
    "members, words",
    [
        ({"length": 0.0}, ["length", "0.0", "(0, inf)"]),
        ({"normal_force": np.inf}, ["normal_force", "inf", "(0, inf)"]),  # inf is not a force
        ({"disc_velocity": -np.inf}, ["disc_velocity", "-inf"]),
        ({"length": -0.1}, ["length", "-0.1"]),
        ({"poisson_ratio": 0.5}, ["poisson_ratio", "0.5", "(-1, 0.5)"]),
        ({"poisson_ratio": -1.0}, ["poisson_ratio", "-1.0"]),
        ({"normal_force": -10.0}, ["normal_force", "-10.0"]),
        ({"hardness": [5e8, -1.0]}, ["hardness", "-1.0"]),
        ({"density": np.nan}, ["density", "nan"]),
        ({"eccentricity": 1.0}, ["eccentricity", "1.0", "[-0.6, 0.6]"]),
        ({"eccentricity": -0.8}, ["eccentricity", "-0.8", "[-0.6, 0.6]"]),  # lifts off and stalls: refused
        ({"end_time": 19.0}, ["end_time", "19.0", "rest_until"]),
        ({"viscous_coefficient": -1.0}, ["viscous_coefficient", "-1.0", "[0, inf)"]),
        ({"frobnication": 1.0}, ["frobnication", "valid names"]),
        ({"normal_force": [1.0, 2.0], "eccentricity": [0.0, 0.1, 0.2]}, ["broadcast", "normal_force", "eccentricity"]),
        ({"normal_force": []}, ["empty"]),
        ({"normal_force": "lots"}, ["normal_force", "lots"]),
        ({"normal_forc": [500.0]}, ["normal_forc", "did you mean 'normal_force'?", "valid names"]),
        ({"eccentricity": [True]}, ["eccentricity", "True", "not a real number", "[-0.6, 0.6]"]),  # not 1.0
        ({"eccentricity": np.array([False, True])}, ["eccentricity", "not a real number"]),
        ({"normal_force": [True, 500.0]}, ["normal_force", "True", "not a real number"]),  # numpy: [1.0, 500.0]
        ({"normal_force": [[500.0], [False]]}, ["normal_force", "not a real number"]),
    ],
)
def test_bad_parameters(members, words):
    with pytest.raises(ValueError) as err:
        simulate(members)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(nodes=2), ["nodes", "2", "[3, 2147483647]"]),
        (dict(dtype="float16"), ["dtype", "float16", "float32 or float64"]),
        (dict(rtol=0.0), ["rtol", "0.0"]),
        (dict(dtype="float32", rtol=1e-7), ["rtol", "1e-07", "float32"]),
        (dict(max_steps=0), ["max_steps"]),
        # the kernels count steps in int32: 2**32 + 5 ran 5 steps, 10**12 none
        (dict(max_steps=2**32 + 5), ["max_steps", "4294967301", "[1, 2147483647]"]),
        (dict(stall_min_steps=2**31), ["stall_min_steps", "[1, 2147483647]"]),
        (dict(min_step=1.0, initial_step=1e-6), ["initial_step"]),
        (dict(min_step=2.0), ["'min_step' = 2.0", "'max_step' = 1.0", "min_step <= max_step"]),  # not initial_step
        (dict(max_step=1e-15), ["'min_step' = 1e-14", "'max_step' = 1e-15", "min_step <= max_step"]),
        (dict(step_safety=1.5), ["step_safety", "1.5", "(0, 1)"]),
        (dict(failure_factor=0.0), ["failure_factor", "0.0"]),
        (dict(error_filter_nodes=2), ["error_filter_nodes", "2", "0 (every grid its own filter)", "[3, 2147483647]"]),
        (dict(error_filter_nodes=200.5), ["error_filter_nodes", "200.5"]),
        (dict(error_filter_nodes=None), ["error_filter_nodes", "None"]),
    ],
)
def test_bad_solver_settings(kw, words):
    with pytest.raises(ValueError) as err:
        wf.Solver(**kw)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_bad_model_switch_and_device():
    with pytest.raises(ValueError, match="inertia"):
        wf.Model(inertia="yes")
    with pytest.raises(ValueError, match="cuda:7"):
        simulate(device="cuda:7")
    with pytest.raises(ValueError) as err:  # the name's case, not a missing GPU
        simulate(device="CPU")
    assert "device names are lower case: 'cpu'" in str(err.value) and "no CUDA GPU" not in str(err.value)


def test_members_from_xarray_dataset_and_broadcasting():
    import xarray as xr

    members = xr.Dataset({"eccentricity": ("member", [0.0, 0.1])})
    ds = simulate(members, solver=wf.Solver(nodes=10, rtol=1e-4), scene=wf.Parameters(end_time=20.5))
    assert ds.sizes["member"] == 2
    grid = simulate({"normal_force": [[500.0], [1000.0]], "eccentricity": [0.0, 0.1, 0.2]},
                    solver=wf.Solver(nodes=10, rtol=1e-4), scene=wf.Parameters(end_time=20.5))
    assert grid.sizes["member"] == 6
    np.testing.assert_array_equal(grid.normal_force.values, [500, 500, 500, 1000, 1000, 1000])
    np.testing.assert_array_equal(grid.eccentricity.values, [0, 0.1, 0.2, 0, 0.1, 0.2])
    assert grid.mu_s.attrs["units"] == "1" and grid.normal_force.attrs["units"] == "N"


@pytest.mark.parametrize("cls, typo, right", [(wf.Parameters, "normal_forse", "normal_force"), (wf.Solver, "rtoll", "rtol"),
                                             (wf.Model, "relaxation_gates", "relaxation_gate"),
                                             # one word of a single name (an audit's 'gate' had no suggestion)
                                             (wf.Model, "gate", "relaxation_gate"), (wf.Parameters, "arm", "torque_arm")])
def test_unknown_keyword_names_the_valid_ones(cls, typo, right):
    with pytest.raises(TypeError, match=f"unknown parameter '{typo}' \\(did you mean '{right}'\\?\\); valid names: .*{right}"):
        cls(**{typo: 1})


@pytest.mark.parametrize("line, words", [
    ("normal_force = ['500']", ["[grid] normal_force = \"500\"", "expected a number in (0, inf) N"]),
    ("eccentricity = [true]", ["[grid] eccentricity = true", "expected a number in [-0.6, 0.6]"]),
    ("normal_force = {start = '1', stop = 5000, num = 3}", ["[grid] normal_force.start = \"1\"", "(0, inf) N"]),
])
def test_a_sweep_files_non_number_names_the_parameters_range_and_units(tmp_path, line, words):
    from warpfric.sweep_file import SweepError, load_sweep

    path = tmp_path / "s.toml"
    path.write_text(f"[grid]\n{line}\n")
    with pytest.raises(SweepError) as err:
        load_sweep(path)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


@pytest.mark.parametrize("sweep, where", [
    ("[grid]\neccentricity = [0.0, 0.2]\n", "[grid] eccentricity"),
    ("[zip]\neccentricity = [0.0, 0.2]\nnormal_force = [500.0, 1000.0]\n", "[zip] eccentricity"),
])
def test_a_parameter_set_in_scene_and_swept_is_refused(tmp_path, sweep, where):
    """[scene] eccentricity = 0.1 beside a sweep of eccentricity would be ignored without a word (each
    member takes the swept value): the file is refused, naming both places."""
    from warpfric.sweep_file import SweepError, load_sweep

    path = tmp_path / "s.toml"
    path.write_text("[scene]\neccentricity = 0.1\n" + sweep)
    with pytest.raises(SweepError) as err:
        load_sweep(path)
    for w in ("'eccentricity'", "[scene]", where, "remove one"):
        assert w in str(err.value), (w, str(err.value))


def test_fronts_given_as_an_event_name_points_to_fronts_of_that_event():
    with pytest.raises(ValueError, match="got str \\(for that event: fronts=warpfric.Fronts\\(event='strength'\\)\\)"):
        simulate({"eccentricity": [0.0]}, fronts="strength")


def test_a_stop_before_the_disc_moves_is_refused():
    """stop_time <= rest_until ran, ended no_peak and advised a later end_time, the wrong fix."""
    with pytest.raises(ValueError, match="parameter 'stop_time' = 5.0 \\(s\\) stops the disc before it starts to move; "
                                         "valid range \\(rest_until, inf\\] = \\(20.0, inf\\] s.*member 1"):
        simulate({"stop_time": [np.inf, 5.0]})


def test_record_times_that_are_no_numbers_are_named():
    with pytest.raises(ValueError, match="record setting 'times' = \\('a',\\) is invalid; valid: non-empty"):
        wf.Record(times=("a",))
    with pytest.raises(ValueError, match="record window: start 'a' and stop 20 are invalid; valid: numbers"):
        wf.Record.window("a", 20, 3)


def test_torque_arm_none_is_the_pad_height_and_nan_no_value():
    """A NaN in a per-member torque_arm ran silently as the pad height; None (the scene's, or given
    for every member) means the pad height, as documented."""
    with pytest.raises(ValueError, match="parameter torque_arm\\[0\\] = nan m is out of range"):
        simulate({"torque_arm": [np.nan, 0.01]})
    from warpfric.members import resolve_members

    height = wf.Parameters().height
    for members, scene in (({"torque_arm": None, "eccentricity": [0.0, 0.1]}, wf.Parameters(torque_arm=0.02)),
                           ({"eccentricity": [0.0, 0.1]}, wf.Parameters())):
        values, _ = resolve_members(members, scene)
        np.testing.assert_array_equal(values["torque_arm"], [height, height])
    values, _ = resolve_members({"torque_arm": [0.01, -0.02]}, wf.Parameters())
    np.testing.assert_array_equal(values["torque_arm"], [0.01, -0.02])


def test_a_scene_holds_one_value_a_parameter():
    """A list in Parameters was accepted and failed later inside simulate without the parameter's name."""
    with pytest.raises(ValueError, match="parameter 'normal_force': value \\[1000.0, 2000.0\\] is not a single number.*"
                                         "simulate\\(\\{'normal_force'"):
        wf.Parameters(normal_force=[1000.0, 2000.0])
    with pytest.raises(ValueError, match="parameter 'eccentricity': value .* is not a single number"):
        wf.Parameters(eccentricity=np.array([0.1]))
    assert wf.Parameters(normal_force=np.float64(1500.0), eccentricity=0).normal_force == 1500.0


def test_ragged_members_window_and_event_off_name_what_is_wrong():
    with pytest.raises(ValueError, match="parameter 'eccentricity': value .* is not a rectangular array"):
        simulate({"eccentricity": [[0.1], [0.1, 0.2]]})
    with pytest.raises(ValueError, match="record window: start 20.25 s is after stop 20.05 s"):
        wf.Record.window(20.25, 20.05, 10)
    with pytest.raises(ValueError, match="no fronts: simulate\\(\\.\\.\\., fronts=None\\)"):
        wf.Fronts(event="off")


@pytest.mark.parametrize("kw, words", [
    ({"normal_force": 0.0}, ["'normal_force' = 0.0 N", "(0, inf) N"]),
    ({"eccentricity": 1.0}, ["'eccentricity' = 1.0", "[-0.6, 0.6]"]),
    ({"length": float("nan")}, ["'length' = nan m", "(0, inf) m"]),
])
def test_a_scene_is_checked_where_it_is_written(kw, words):
    """Parameters refuses a value out of range when it is made, not only when simulate runs it; None
    and stop_time = inf keep their meanings."""
    with pytest.raises(ValueError) as err:
        wf.Parameters(**kw)
    for w in words:
        assert w in str(err.value), (w, str(err.value))
    wf.Parameters(end_time=None, stop_time=float("inf"), torque_arm=None)


def test_the_ends_that_take_inf_say_so_and_a_per_member_none_points_to_inf():
    """stop_time and end_time take inf (no stop, the automatic end): their range is written (0, inf],
    not (0, inf), and so does their metadata (an infinite end open elsewhere); a None inside a per-member
    list (None stands only for the whole) is answered with inf. A value that is not a number names the
    unit with the range."""
    meta = {f.name: f.metadata for f in dataclasses.fields(wf.Parameters)}
    assert not meta["stop_time"]["high_open"] and not meta["end_time"]["high_open"]
    takes_inf = ("stop_time", "end_time")
    assert all(m["high_open"] for name, m in meta.items() if np.isinf(m["high"]) and name not in takes_inf)
    assert meta["disc_velocity"]["low_open"] and not meta["eccentricity"]["high_open"]
    with pytest.raises(ValueError, match=r"'stop_time' = -1.0 s is out of range; valid range \(0, inf\] s"):
        simulate({"stop_time": [-1.0]})
    with pytest.raises(ValueError, match=r"valid range \(0, inf\] s \(per member, write inf where you mean None\)"):
        simulate({"end_time": [None, 21.0]})
    with pytest.raises(ValueError, match=r"'normal_force': value \[None, 2.0\] is not a real number; valid range "
                                         r"\(0, inf\) N$"):
        simulate({"normal_force": [None, 2.0]})
    with pytest.raises(ValueError, match=r"'torque_arm'.*\(per member, write the member's pad height where you mean None"):
        simulate({"torque_arm": [None, 0.01]})


def test_parameters_that_the_model_switches_ignore_are_named():
    """Model(tilt=False) spreads the load evenly and has no moment balance: an eccentricity swept
    there changed nothing (the same mu_s and steps) without a word; likewise shear_strength without
    the stress gate. One warning names each with the switch; defaults or used values give none."""
    with pytest.warns(UserWarning, match=r"parameters without effect under these model switches: eccentricity "
                                         r"\(tilt=False.*shear_strength \(relaxation_gate='none'\)") as caught:
        ds = run({"eccentricity": [0.0, 0.3], "shear_strength": [1.3e8, 1e8]}, nodes=20, rtol=1e-5,
                 model=wf.Model(tilt=False, relaxation_gate="none"))
    assert len([w for w in caught if "without effect" in str(w.message)]) == 1
    assert ds.mu_s.values[0] == ds.mu_s.values[1] and ds.steps_accepted.values[0] == ds.steps_accepted.values[1]
    from warpfric.members import resolve_members

    model = wf.Model(relaxation_gate="none", tilt=False, inertia=False, viscous_friction=False)
    assert model.unused_parameters(resolve_members(None, wf.Parameters())[0]) == []
    values = resolve_members({"eccentricity": [0.1], "shear_strength": [1e8]}, wf.Parameters())[0]
    assert wf.Model().unused_parameters(values) == []  # both used by the default model


def test_a_run_beyond_the_machines_memory_is_refused(monkeypatch):
    """One member of 1e8 nodes needs ~53 GB; with less memory the system killed it after the size
    warning. Refused before anything runs, naming the estimate and the machine's memory."""
    from warpfric import progress

    monkeypatch.setattr(progress, "machine_memory_bytes", lambda: 25 * 10**9)
    with pytest.raises(ValueError, match=r"this run \(1 member x 100000000 nodes at once\) needs about 53.0 GB of "
                                         r"memory, more than this machine's 25.0 GB"):
        simulate(None, device="cpu", solver=wf.Solver(nodes=10**8))


def test_a_broadcasting_slip_is_refused_before_its_arrays_are_built(monkeypatch):
    """(100000, 1) x (1000,) members, a slip of the broadcasting rules: simulate built 28 arrays of
    1e8 members (22 GB) before its memory check, and numpy's MemoryError or the system's killer came
    first. The check now comes with the broadcast shape, before any array of that size."""
    import tracemalloc

    from warpfric import progress

    monkeypatch.setattr(progress, "machine_memory_bytes", lambda: 25 * 10**9)
    members = {"normal_force": np.full((100_000, 1), 1000.0), "eccentricity": np.zeros(1000)}
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=r"^the members' arrays broadcast to shape \(100000, 1000\): this run "
                                             r"\(100000000 members x 20 nodes at once\) needs about 1.1 TB of memory"):
            simulate(members, device="cpu", solver=wf.Solver(nodes=20))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6, peak  # one (1e8,) float64 array alone is 800 MB


def test_a_disc_that_starts_before_the_full_load_is_run_with_a_warning():
    """rest_until = 0 starts the disc at t = 0, while the normal force ramps over 10 s: the default
    scene peaks at ~0.16 s under ~16 N, a mu_s under a force still rising, while the output's
    normal_force says 1000 N. It runs (a user may want it), and one warning says so; the default
    protocol (rest 20 s, ramp 10 s) gives none."""
    import warnings

    with pytest.warns(UserWarning, match=r"before the normal force is fully applied \(force_ramp_time\)"):
        ds = run({"rest_until": [0.0, 20.0]}, nodes=11)
    assert ds.mu_s_time.values[0] < ds.force_ramp_time.values.min() and ds.mu_s_time.values[1] > 20.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run({"rest_until": [10.0]}, nodes=11)


def test_a_numpy_scalar_in_a_scene_is_kept_as_its_value():
    """Parameters(normal_force=np.array(1000.0)) kept the 0-d array: its repr read
    normal_force=array(1000.), and it compared as an array. The scene holds the float."""
    scene = wf.Parameters(normal_force=np.array(1000.0), eccentricity=np.float64(0.1))
    assert type(scene.normal_force) is float and scene.normal_force == 1000.0
    assert type(scene.eccentricity) is float and "normal_force=1000.0" in repr(scene)
    assert scene == wf.Parameters(normal_force=1000.0, eccentricity=0.1)


def test_parameters_held_as_coordinates_of_a_members_dataset_are_used():
    """A grid built the xarray way, coordinates stacked into member (as by_parameters gives a run
    back), ran one member of the default scene without a word; a parameter as a coordinate beside a
    data variable was ignored (4 members at 1000 N). They are used, and a Dataset of several members
    with no parameter along member is refused."""
    import xarray as xr

    grid = xr.Dataset(coords={"normal_force": [500.0, 1000.0], "eccentricity": [-0.1, 0.1]})
    values, varying = resolve_members(grid.stack(member=["normal_force", "eccentricity"]), wf.Parameters())
    np.testing.assert_array_equal(values["normal_force"], [500.0, 500.0, 1000.0, 1000.0])
    np.testing.assert_array_equal(values["eccentricity"], [-0.1, 0.1, -0.1, 0.1])
    assert set(varying) == {"normal_force", "eccentricity"}
    mixed = xr.Dataset({"eccentricity": ("member", [0.0, 0.1])}, coords={"normal_force": ("member", [500.0, 2000.0])})
    np.testing.assert_array_equal(resolve_members(mixed, wf.Parameters())[0]["normal_force"], [500.0, 2000.0])
    with pytest.raises(ValueError, match="has 3 members along 'member' but no parameter along it"):
        resolve_members(xr.Dataset(coords={"member": [0, 1, 2]}), wf.Parameters())


def test_a_runs_outputs_give_its_members_back(tmp_path):
    """simulate(ds) of a run's Dataset (or its file) was refused for its outputs' dims ("variable
    'displacement' has dims ('member', 'x')"), though docs/guide.md says the way back works: it takes
    the run's parameters (variables along member, or coordinates after set_coords, or a by_parameters view)
    and runs the same members again, bit for bit; a selection of members runs those. A Record for a run numbered from K names its members by
    index, and the refusal of a number says so."""
    import xarray as xr

    kw = dict(solver=wf.Solver(nodes=11), fronts=None)
    first = simulate({"eccentricity": [0.0, 0.1, -0.1]}, scene=wf.Parameters(disc_velocity=2e-4), member_offset=10,
                     **kw)
    again = simulate(first, member_offset=10, **kw)
    np.testing.assert_array_equal(again.mu_s.values, first.mu_s.values)
    np.testing.assert_array_equal(again.disc_velocity.values, [2e-4] * 3)
    np.testing.assert_array_equal(again.member.values, [10, 11, 12])
    two = simulate(first.sel(member=[11, 12]), **kw)
    np.testing.assert_array_equal(two.mu_s.values, first.mu_s.values[1:])
    # the parameters as coordinates (set_coords for groupby, or by_parameters' grid stacked back)
    grid = simulate({"eccentricity": [0.0, 0.1], "normal_force": [[800.0], [1000.0]]}, **kw)
    for back in (grid.set_coords(["normal_force", "eccentricity"]),
                 wf.io.by_parameters(grid).stack(member=["normal_force", "eccentricity"])):
        rerun = simulate(back, **kw)
        assert rerun.sizes["member"] == 4
        order = np.lexsort((rerun.eccentricity.values, rerun.normal_force.values))
        np.testing.assert_array_equal(rerun.mu_s.values[order], grid.mu_s.values[np.lexsort(
            (grid.eccentricity.values, grid.normal_force.values))])
    # a by_parameters view itself (refused for its dims before): stacked back, its members in the order of their
    # numbers, a combination that no member ran (NaN there) left out; one swept name too
    views = [(part, wf.io.by_parameters(part)) for part in (grid, grid.isel(member=[0, 1, 3]),
                                                             grid.sel(member=grid.member[grid.eccentricity == 0.1]))]
    views.append((grid, wf.io.by_parameters(grid, ["eccentricity", "normal_force"])))  # stacks as numbers 0, 2, 1, 3
    path = tmp_path / "grid.nc"
    wf.io.write_ensemble(grid, path)
    with xr.open_dataset(path) as raw:  # a file's view: member_number a coordinate, the members string labels
        views.append((grid, wf.io.by_parameters(raw.load())))
    for part, view in views:
        rerun = simulate(view, **kw)
        np.testing.assert_array_equal(rerun.normal_force.values, part.normal_force.values)
        np.testing.assert_array_equal(rerun.eccentricity.values, part.eccentricity.values)
        np.testing.assert_array_equal(rerun.mu_s.values, part.mu_s.values)
    hole = wf.io.by_parameters(grid.isel(member=[0, 1, 3]))
    with pytest.raises(ValueError, match="this cell of a by_parameters view was run by no member"):
        simulate(hole.sel(normal_force=1000.0, eccentricity=0.0), **kw)
    np.testing.assert_array_equal(simulate(hole.sel(normal_force=1000.0, eccentricity=0.1), **kw).mu_s.values,
                                  grid.mu_s.values[3:4])
    with pytest.raises(ValueError, match=r"contains 12; valid: member indices 0..2 \(a member's index is its number "
                                         r"less simulate's member_offset.*member_offset=K\)"):
        simulate(first, member_offset=10, record=wf.Record.detachment(first, members=(12,)), **kw)
    record = wf.Record.detachment(first, members=(12,), member_offset=10)
    assert record.members == (2,)


def test_a_solver_or_model_setting_given_per_member_is_named_as_such():
    """{"nodes": [20]} was "unknown parameter 'nodes'" and the list of parameters, without a word that
    nodes is a Solver setting: the refusal says where it goes."""
    for name, kind in (("nodes", "Solver"), ("rtol", "Solver"), ("relaxation_gate", "Model")):
        with pytest.raises(ValueError, match=rf"unknown parameter '{name}': {name} is a {kind} setting, the same for "
                                             rf"every member \(wf.{kind}\({name}=...\); in a sweep file "
                                             rf"\[{kind.lower()}\] {name} = ...\)"):
            resolve_members({name: [20]}, wf.Parameters())


def test_help_of_parameters_gives_units_and_ranges():
    """docs/guide.md sends the reader to help(wf.Parameters) for units and ranges, which it lacked:
    a line per parameter with its unit, the range the checks refuse outside of, and its default."""
    doc = wf.Parameters.__doc__
    lines = {line.split()[0]: line.split() for line in doc.splitlines() if line.strip()}
    assert set(wf.PARAMETER_NAMES) <= set(lines)
    assert lines["normal_force"][1:4] == ["N", "(0,", "inf)"] and lines["normal_force"][4] == "1000"
    assert lines["eccentricity"][1:4] == ["-", "[-0.6,", "0.6]"]
    assert lines["viscous_coefficient"][1:6] == ["Pa", "s", "m-1", "[0,", "inf)"]
    with pytest.raises(ValueError, match=r"valid range \[-0.6, 0.6\]"):
        resolve_members({"eccentricity": [0.61]}, wf.Parameters())


def test_a_misspelt_parameter_as_a_coordinate_is_named():
    """A coordinate along member that is no parameter was dropped without a word (the stacked grid
    of 'eccentricty' ran 4 members at eccentricity 0); as a data variable it was refused."""
    import xarray as xr

    grid = xr.Dataset(coords={"normal_force": [500.0, 1000.0], "eccentricty": [-0.1, 0.1]})
    with pytest.raises(ValueError, match="coordinate 'eccentricty' along member is no parameter \\(did you mean "
                                         "'eccentricity'\\?\\)"):
        resolve_members(grid.stack(member=["normal_force", "eccentricty"]), wf.Parameters())


def test_numpy_scalars_and_a_team_beyond_the_coarse_grid_run_and_write(tmp_path):
    """Valid input that failed late (a host-code review): Solver/Fronts/Model settings given as numpy
    scalars (np.True_) reached the attributes, where write_ensemble raised TypeError after the run; a
    numpy member_offset overflowed its own width in the worker split (np.int8(126) named -126); and
    Solver(lanes=10) at N = 21 with the grid check raised after the whole fine run, the coarse grid
    (11 nodes) allowing 5 lanes at most."""
    import warnings

    ds = simulate({"eccentricity": [0.0, 0.1]}, solver=wf.Solver(nodes=np.int64(11), predict_switches=np.True_),
                  model=wf.Model(tilt=np.True_), fronts=wf.Fronts(grid_check=np.False_))
    assert ds.attrs["solver_predict_switches"] == 1 and type(ds.attrs["solver_nodes"]) is int
    wf.io.write_ensemble(ds, tmp_path / "np.nc")
    assert wf.io.open_ensemble(tmp_path / "np.nc").attrs["solver_predict_switches"] == 1
    split = simulate({"eccentricity": np.linspace(-0.1, 0.1, 8)}, member_offset=np.int8(126), workers=2,
                     solver=wf.Solver(nodes=11), fronts=None, device="cpu")  # worker processes serve the CPU
    assert split.member.values.tolist() == list(range(126, 134))
    # member numbers past the sweep's limit (int32, with room for the labels' run): one bound for
    # simulate and sweep files (simulate let numbers up to 2**31 - 1 through that a sweep refused)
    from warpfric.parameters import MEMBER_NUMBER_LIMIT
    from warpfric.sweep_file import SweepError, check_member_offset

    with pytest.raises(ValueError, match=rf"member_offset = {MEMBER_NUMBER_LIMIT - 1} is invalid for 2 members; "
                                         rf"valid: an integer in \[0, {MEMBER_NUMBER_LIMIT - 2}\]"):
        simulate({"eccentricity": [0.0, 0.1]}, member_offset=MEMBER_NUMBER_LIMIT - 1)
    with pytest.raises(SweepError, match=rf"expected an integer in \[0, {MEMBER_NUMBER_LIMIT - 2}\]"):
        check_member_offset(MEMBER_NUMBER_LIMIT - 1, 2, "--member-offset")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        checked = simulate(solver=wf.Solver(nodes=21, lanes=10), fronts=wf.Fronts(grid_check=True))
    assert checked.status.values[0] == 0 and 0 < float(checked.mu_s_grid_error[0]) < 1e-3
    # on the CPU the team runs on fibers, which is said once, of the run asked for (a GPU says nothing)
    assert sum("Solver(lanes=" in str(w.message) for w in caught) == (1 if DEVICE == "cpu" else 0)


def test_max_end_time_is_checked_only_where_it_can_end_the_run():
    """max_end_time (the automatic end's cap, 80 s) was checked against rest_until for every member, so a
    late disc start with an explicit end_time was refused for a parameter the user never set and the
    run never used; where the automatic end applies, the cap still has to lie after the disc starts."""
    ds = simulate({"rest_until": [100.0], "end_time": [100.05]}, solver=wf.Solver(nodes=11), fronts=None)
    assert float(ds.final_time[0]) == 100.05 and ds.status.values[0] == 4  # no peak in 50 ms: no_peak, as asked
    with pytest.raises(ValueError, match=r"'max_end_time' = 80.0 \(s\) ends before the disc starts to move"):
        simulate({"rest_until": [100.0]}, solver=wf.Solver(nodes=11), fronts=None)


def test_a_sweep_files_fronts_and_scheduler_faults_use_the_files_words(tmp_path, capsys):
    """In a sweep file, a bad [fronts] setting pointed to simulate(..., fronts=None) and did not name
    its table; a scheduler that is no address did not say what one looks like."""
    from conftest import run_cli

    sweep = tmp_path / "f.toml"
    sweep.write_text('[solver]\nnodes = 11\n[fronts]\nevent = "foo"\n[grid]\neccentricity = [0.0]\n')
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "f.nc", "--device", "cpu")
    assert code == 2 and len(err) == 1 and err[0].startswith(f"warpfric: error: {sweep}: [fronts] fronts setting "
                                                             "'event' = 'foo' is invalid"), err
    assert "write `fronts = false` at the file's top level" in err[0] and "simulate(" not in err[0], err
    pytest.importorskip("distributed")
    sweep.write_text('[solver]\nnodes = 11\n[grid]\neccentricity = [0.0]\n')
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "g.nc", "--scheduler", "locl", "--device", "cpu")
    assert code == 2 and "expected a scheduler's address such as 'tcp://host:8786'" in err[-1], err


def test_a_new_users_slips_are_named(tmp_path):
    """Slips a review found accepted without a word, or answered from inside numpy, xarray or
    pathlib: each now a one-line error naming what is wrong, or taken as meant."""
    import xarray as xr

    with pytest.raises(TypeError, match=r"^Parameters takes keyword arguments only, as Parameters\(shear_modulus="
                                        r"\.\.\.\); got 1 positional value: 1000$"):
        wf.Parameters(1000)  # set the shear modulus, the first field, to 1000 Pa
    for cls in (wf.Solver, wf.Model, wf.Fronts, wf.Record):  # Solver(60) set nodes, Model(True) inertia
        with pytest.raises(TypeError, match=rf"^{cls.__name__} takes keyword arguments only"):
            cls(60)
    with pytest.raises(ValueError, match=r"progress = 5 is invalid; valid: None .*True, False or a string"):
        wf.simulate(device=DEVICE, progress=5)
    with pytest.raises(ValueError, match=r"^Record.detachment: ds is invalid; .* got a Dataset without member, "
                                         r"final_time$"):
        wf.Record.detachment(xr.Dataset())  # xarray's AttributeError: 'Dataset' object has no attribute 'member'
    ds = simulate(solver=wf.Solver(nodes=11))
    with pytest.raises(ValueError, match=r"whose member is no dimension .* isel\(member=\[0\]\) keeps it"):
        wf.Record.detachment(ds.isel(member=0))
    with pytest.raises(ValueError, match=r"^write_ensemble: path = 5 is invalid; valid: a file name"):
        wf.io.write_ensemble(ds, 5)  # pathlib's TypeError
    path = wf.io.write_ensemble(ds, tmp_path / "one.nc")
    one = wf.io.open_ensembles(str(path))  # a string was iterated: "o: no such file"
    assert one.sizes["member"] == 1 and float(one.mu_s[0]) == float(ds.mu_s[0])
    with pytest.raises(ValueError, match=r"the same file is given twice"):
        wf.io.open_ensembles([path, tmp_path / "." / "one.nc"])  # (read as a selection written apart)


def test_settings_take_zero_d_arrays_as_parameters_do():
    """Parameters took np.array(1000.0); Solver refused np.array(1e-5) as 'array(1e-05)'."""
    solver = wf.Solver(rtol=np.array(1e-5), nodes=np.array(40))
    assert solver.rtol == 1e-5 and type(solver.nodes) is int and solver.nodes == 40
    assert wf.Model(inertia=np.array(False)).inertia is False
    assert wf.Fronts(threshold=np.array(0.3)).threshold == 0.3
    with pytest.raises(ValueError, match=r"solver setting 'nodes' = 2 is invalid"):
        wf.Solver(nodes=np.array(2))  # checked as the value it holds


def test_value_messages_name_the_unit_and_stay_short():
    with pytest.raises(ValueError, match=r"^parameter 'normal_force': value None is not allowed; valid range \(0, inf\) "
                                         r"N$"):
        wf.Parameters(normal_force=None)
    with pytest.raises(ValueError) as caught:
        wf.Parameters(normal_force=10**400)  # its 401 digits were the message
    assert len(str(caught.value)) < 200 and "(401 characters) is out of range (beyond float64" in str(caught.value)
    # an int beyond int64 but within float64 is a value (numpy made an object array of it: "not a real number")
    assert wf.Parameters(shear_modulus=10**20).shear_modulus == 1e20


def test_a_raised_step_floor_is_named_as_the_cause_of_step_size_underflow():
    """min_step = initial_step = 1e-2 s ends step_size_underflow, whose advice said 'a tighter rtol',
    which lowers the steps further; the floor that was set is what to change."""
    with pytest.warns(UserWarning, match=r"1 step_size_underflow \(the step size fell below its floor, min_step = "
                                         r"0.01 s, set above its default 1e-14 s: a smaller min_step\)"):
        ds = simulate(solver=wf.Solver(nodes=11, min_step=1e-2, initial_step=1e-2))
    assert int(ds.status[0]) == 3 and np.isnan(float(ds.mu_s[0]))
