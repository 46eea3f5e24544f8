"""Files that combine however a user opens them (issue 22, part 3). Two runs made without any flag
number their members alike (0, 1, ...), but every file labels its members '<run id>:<number>'
(coordinate ``member``; the numbers are ``member_number``) and keeps its recorded fields in the
netCDF4 group 'recorded': xarray's default ``xr.open_mfdataset(files)`` (combine='by_coords')
then keeps every member exactly once, and ``warpfric.io.open_ensembles`` refuses repeated member
numbers with a message that says what to do. Before, by_coords kept 2 of 5 members of plain files
and made mu_s 2-D (recorded_member x member) with NaN padding when members were recorded."""

import re
import warnings

import numpy as np
import pytest
import xarray as xr
from conftest import DEVICE, run

import warpfric as wf
from warpfric.cli import main
from warpfric.io import open_ensemble, open_ensembles, write_ensemble

pytest.importorskip("dask")  # xr.open_mfdataset needs it

SWEEP = """
fronts = false
[solver]
nodes = 11
[grid]
eccentricity = {values}
"""
RECORD = "[record]\nmembers = [{member}]\nstart = 20.2\nstop = 20.3\ncount = 5\n"
LABEL = re.compile(r"^\d{8}T\d{9}-[0-9a-f]{6}:\d{10}$")  # <UTC start, ms>-<random>:<number>


def _run(tmp_path, capsys, name, values, record=None, *args):
    sweep = tmp_path / f"{name}.toml"
    sweep.write_text(SWEEP.format(values=values) + (RECORD.format(member=record) if record is not None else ""))
    code = main(["run", str(sweep), "-o", str(tmp_path / f"{name}.nc"), "--device", DEVICE, "--quiet",
                 *map(str, args)])
    assert code == 0, capsys.readouterr().err
    capsys.readouterr()
    return tmp_path / f"{name}.nc"


def _open_defaults(paths, new_defaults, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        with xr.set_options(use_new_combine_kwarg_defaults=new_defaults):
            return xr.open_mfdataset(paths, **kwargs).load()


@pytest.mark.parametrize("new_defaults", [False, True])
@pytest.mark.parametrize("recorded", [False, True])
def test_two_runs_without_flags_keep_every_member_at_xarrays_defaults(tmp_path, capsys, recorded, new_defaults):
    a = _run(tmp_path, capsys, "a", "[-0.2, 0.0, 0.2]", 1 if recorded else None)
    b = _run(tmp_path, capsys, "b", "[0.1, 0.3]", 0 if recorded else None)
    first, second = open_ensemble(a), open_ensemble(b)
    assert first.member.values.tolist() == [0, 1, 2] and second.member.values.tolist() == [0, 1]  # alike
    both = _open_defaults([a, b], new_defaults)
    assert dict(both.sizes) == {"member": 5, "x": 11}
    assert both.mu_s.dims == ("member",) and not np.isnan(both.mu_s.values).any()  # no padding
    np.testing.assert_array_equal(both.mu_s.values, np.concatenate([first.mu_s.values, second.mu_s.values]))
    np.testing.assert_array_equal(both.eccentricity.values, [-0.2, 0.0, 0.2, 0.1, 0.3])
    np.testing.assert_array_equal(both.member_number.values, [0, 1, 2, 0, 1])
    assert all(LABEL.match(label) for label in both.member.values) and np.unique(both.member.values).size == 5
    runs = [label.split(":")[0] for label in both.member.values]
    assert len(set(runs[:3])) == len(set(runs[3:])) == 1 and runs[0] < runs[3]  # runs sort by their start
    if recorded:
        rec = _open_defaults([a, b], new_defaults, group="recorded")
        np.testing.assert_array_equal(rec.recorded_member_number.values, [1, 0])
        np.testing.assert_array_equal(rec.recorded_member.values, [both.member.values[1], both.member.values[3]])
        np.testing.assert_array_equal(rec.velocity_history.values, np.concatenate(
            [first.velocity_history.values, second.velocity_history.values]))


def test_open_ensembles_refuses_them_and_says_what_to_do(tmp_path, capsys):
    a = _run(tmp_path, capsys, "a", "[-0.2, 0.0, 0.2]", 1)
    b = _run(tmp_path, capsys, "b", "[0.1, 0.3]", 0)
    with pytest.raises(ValueError) as err:
        open_ensembles([a, b])
    message = str(err.value)
    assert "member numbers 0, 1 occur more than once" in message and "--member-offset K" in message
    assert "xr.open_mfdataset(files)" in message
    c = _run(tmp_path, capsys, "c", "[0.1, 0.3]", 0, "--member-offset", 3)  # what it says: distinct numbers
    combined = open_ensembles([a, c])
    assert combined.member.values.tolist() == [0, 1, 2, 3, 4]
    assert combined.recorded_member.values.tolist() == [1, 3]


def test_one_file_given_twice_is_an_error_not_a_duplicate(tmp_path, capsys):
    a = _run(tmp_path, capsys, "a", "[-0.2, 0.0, 0.2]")
    with pytest.raises(ValueError, match="Could not find any dimension coordinates"):
        _open_defaults([a, a], False)
    with pytest.raises(ValueError, match="the same file is given twice"):
        open_ensembles([a, a])


def test_the_chunks_of_a_run_share_its_id_and_a_resumed_run_keeps_it(tmp_path, capsys, monkeypatch):
    import importlib

    simulate_module = importlib.import_module("warpfric.simulate")
    real = simulate_module.simulate
    calls = []

    def interrupted(*args, **kwargs):
        if "member_offset" in kwargs:
            calls.append(1)
            if len(calls) == 2:
                raise KeyboardInterrupt
        return real(*args, **kwargs)

    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP.format(values="[-0.2, 0.0, 0.2]"))
    out = tmp_path / "s.nc"
    monkeypatch.setattr(simulate_module, "simulate", interrupted)
    assert main(["run", str(sweep), "-o", str(out), "--chunk", "1", "--device", DEVICE, "--quiet"]) == 130
    monkeypatch.setattr(simulate_module, "simulate", real)
    assert main(["run", str(sweep), "-o", str(out), "--resume", "--device", DEVICE, "--quiet"]) == 0
    with xr.open_dataset(out) as ds:
        labels = ds.member.values.tolist()
    assert len({label.split(":")[0] for label in labels}) == 1
    assert [label.split(":")[1] for label in labels] == ["0000000000", "0000000001", "0000000002"]


def test_labels_survive_a_rewrite_and_old_files_still_open(tmp_path):
    ds = wf.simulate({"eccentricity": [0.0, 0.1]}, solver=wf.Solver(nodes=11), fronts=None, device=DEVICE,
                     progress=False, record=wf.Record.window(20.2, 20.3, 3, members=(1,)))
    write_ensemble(ds, tmp_path / "a.nc")
    back = open_ensemble(tmp_path / "a.nc")
    assert back.member.values.tolist() == [0, 1] and back.member_id.dims == ("member",)
    write_ensemble(back, tmp_path / "b.nc")  # the same members: the same labels
    np.testing.assert_array_equal(open_ensemble(tmp_path / "b.nc").member_id.values, back.member_id.values)
    # a file in the layout before labels: numbers as the member coordinate, recorded fields in the root
    old = ds.assign_coords(recorded_member=("recorded", [1])).swap_dims(recorded="recorded_member").rename(
        time="record_time")
    old.attrs["warpfric_complete"] = 1
    old.to_netcdf(tmp_path / "old.nc")
    again = open_ensemble(tmp_path / "old.nc")
    assert again.member.values.tolist() == [0, 1] and again.recorded_member.values.tolist() == [1]
    np.testing.assert_array_equal(again.velocity_history.values, ds.velocity_history.values)


@pytest.mark.parametrize("new_defaults", [False, True])
def test_runs_of_different_constants_keep_each_members_value(tmp_path, capsys, new_defaults):
    """A parameter constant in each run but not between them: every member keeps its own value (files
    store every parameter along member; a scalar would be kept from the first file under xarray's
    announced defaults, compat='override')."""
    paths = []
    for name, force in (("a", 500.0), ("b", 900.0)):
        sweep = tmp_path / f"{name}.toml"
        sweep.write_text(SWEEP.format(values="[0.0, 0.1]") + f"[scene]\nnormal_force = {force}\n")
        assert main(["run", str(sweep), "-o", str(tmp_path / f"{name}.nc"), "--device", DEVICE, "--quiet"]) == 0
        paths.append(tmp_path / f"{name}.nc")
    both = _open_defaults(paths, new_defaults)
    np.testing.assert_array_equal(both.normal_force.values, [500.0, 500.0, 900.0, 900.0])
    assert open_ensemble(paths[0]).normal_force.dims == ()  # in memory a constant is a scalar again


def test_open_ensembles_refuses_different_recording_times_in_one_line(tmp_path, capsys):
    a = _run(tmp_path, capsys, "a", "[-0.2, 0.0, 0.2]", 1)
    sweep = tmp_path / "b.toml"
    sweep.write_text(SWEEP.format(values="[0.1, 0.3]") + RECORD.format(member=0).replace("stop = 20.3", "stop = 20.4"))
    assert main(["run", str(sweep), "-o", str(tmp_path / "b.nc"), "--member-offset", "3", "--device", DEVICE,
                 "--quiet"]) == 0
    with pytest.raises(ValueError) as err:
        open_ensembles([a, tmp_path / "b.nc"])
    assert "recorded their fields at different times" in str(err.value) and "group='recorded'" in str(err.value)
    assert "\n" not in str(err.value)


def test_different_solver_settings_are_named_as_plain_values(tmp_path):
    """'differ in solver_nodes (np.int32(24), np.int32(30))': the values as a reader writes them."""
    a = write_ensemble(run({"eccentricity": [0.0]}, nodes=11, rtol=1e-4), tmp_path / "a.nc")
    b = write_ensemble(run({"eccentricity": [0.1]}, nodes=13, rtol=1e-4).assign_coords(member=[1]), tmp_path / "b.nc")
    with pytest.raises(ValueError, match=r"differ in solver_nodes \(11, 13\): not one ensemble"):
        open_ensembles([a, b])


# --- members of different lengths: one x axis, the one simulate() gives them run together ---------

LENGTHS = [0.2, 0.25]
LENGTH_SWEEP = "fronts = false\n[solver]\nnodes = 11\n[grid]\nlength = [0.2, 0.25]\n"
LENGTH_RECORD = "[record]\nmembers = [0, 1]\nstart = 20.2\nstop = 20.25\ncount = 3\n"


def _alone(length, number, nodes=11, record=False):
    """One member simulated by itself, as the sweep file's chunk of it (numbered as in the sweep)."""
    return wf.simulate({"length": [length]}, solver=wf.Solver(nodes=nodes), fronts=None, device=DEVICE,
                       progress=False, member_offset=number,
                       record=wf.Record.window(20.2, 20.25, 3, members=(0,)) if record else None)


@pytest.mark.parametrize("recorded", [False, True])
def test_a_sweep_over_length_in_chunks_keeps_one_x_axis(tmp_path, capsys, recorded):
    """Each chunk built its own x (m of its one length) and the combine joined them outer: 22 nodes,
    each member's fields NaN on the other's half; with recorded fields the combine failed
    ('cannot align objects with join='exact''), exit 2, and --resume failed the same way forever."""
    sweep = tmp_path / "len.toml"
    sweep.write_text(LENGTH_SWEEP + (LENGTH_RECORD if recorded else ""))
    out = tmp_path / "len.nc"
    code = main(["run", str(sweep), "-o", str(out), "--chunk", "1", "--device", DEVICE, "--quiet"])
    assert code == 0, capsys.readouterr().err
    ds = open_ensemble(out)
    together = wf.simulate({"length": LENGTHS}, solver=wf.Solver(nodes=11), fronts=None, device=DEVICE,
                           progress=False)
    assert dict(ds.sizes)["x"] == 11
    np.testing.assert_array_equal(ds.x.values, together.x.values)  # x / L: the members differ in length
    assert ds.x.attrs["units"] == together.x.attrs["units"] == "1"
    for i, length in enumerate(LENGTHS):
        alone = _alone(length, i, record=recorded)
        np.testing.assert_allclose(ds.velocity.values[i], alone.velocity.values[0], rtol=1e-12, atol=0)
        assert not np.isnan(ds.velocity.values[i]).any()
        if recorded:
            assert ds.velocity_history.dims == ("recorded", "time", "x")
            np.testing.assert_allclose(ds.velocity_history.values[i], alone.velocity_history.values[0], rtol=1e-12,
                                       atol=0)


def test_concat_members_of_two_single_length_runs_gives_simulates_x():
    from warpfric.io import concat_members

    parts = [_alone(length, i) for i, length in enumerate(LENGTHS)]
    assert [p.x.attrs["units"] for p in parts] == ["m", "m"]  # each its own axis, in metres
    both = concat_members(parts, names=["short", "long"])
    together = wf.simulate({"length": LENGTHS}, solver=wf.Solver(nodes=11), fronts=None, device=DEVICE,
                           progress=False)
    assert both.sizes["x"] == 11 and both.sizes["member"] == 2
    np.testing.assert_array_equal(both.x.values, together.x.values)
    assert both.x.attrs == together.x.attrs
    for i, part in enumerate(parts):
        np.testing.assert_allclose(both.velocity.values[i], part.velocity.values[0], rtol=1e-12, atol=0)
    # one length in all: x stays in metres, the parts' own axis
    same = concat_members([_alone(0.2, 0), _alone(0.2, 1)])
    np.testing.assert_array_equal(same.x.values, parts[0].x.values)
    assert same.x.attrs["units"] == "m"


def test_concat_members_refuses_different_node_counts_naming_both():
    from warpfric.io import concat_members

    a, b = _alone(0.2, 0, nodes=11), _alone(0.2, 1, nodes=13)
    for part in (a, b):  # the settings check would name solver_nodes first: the node count's own check
        part.attrs.pop("solver_nodes")
    with pytest.raises(ValueError, match=r"^first and second have different node counts \(11 and 13 nodes"):
        concat_members([a, b], names=["first", "second"])


# --- parts with different outputs: refused by name, never dropped ----------------------------------

def _final_fields_and_not(tmp_path):
    from warpfric.runner import FINAL_FIELDS

    a = write_ensemble(_alone(0.2, 0), tmp_path / "a.nc")
    b = write_ensemble(_alone(0.2, 1).drop_vars(list(FINAL_FIELDS)), tmp_path / "b.nc")  # [run] final_fields = false
    return a, b


def test_files_with_and_without_final_fields_are_refused_naming_the_fields(tmp_path, capsys):
    """Before: KeyError 'displacement' (info: a traceback, exit 1) in one order, the fields silently
    dropped in the other."""
    a, b = _final_fields_and_not(tmp_path)
    for files in ((a, b), (b, a)):
        with pytest.raises(ValueError) as err:
            open_ensembles(list(files))
        message = str(err.value)
        assert str(a) in message and str(b) in message and "\n" not in message
        assert f"{a} has displacement, velocity, elastic_stress, contact_age, normal_stress, friction_stress, " \
               f"which {b} lacks" in message
    code = main(["info", str(a), str(b)])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2 and out == ""
    assert len(lines) == 1 and lines[0].startswith("warpfric: error:") and "displacement" in lines[0], lines


def test_a_file_without_fronts_and_one_with_them_are_refused_in_either_order(tmp_path):
    """Before: the settings check read the first file's attributes only, so a first file without
    fronts dropped the other's front outputs (v_main, arrival_time, ...) silently."""
    plain = write_ensemble(_alone(0.2, 0), tmp_path / "plain.nc")
    fronted = write_ensemble(wf.simulate({"length": [0.2]}, solver=wf.Solver(nodes=11), fronts=wf.Fronts(),
                                         device=DEVICE, progress=False, member_offset=1), tmp_path / "fronts.nc")
    assert "v_main" in open_ensemble(fronted)
    for files in ((plain, fronted), (fronted, plain)):
        with pytest.raises(ValueError, match=r"differ in fronts_\w+ \(.*not set.*\): not one ensemble \(a run "
                                             r"without fronts"):
            open_ensembles(list(files))


def test_recorded_fields_in_one_part_only_still_combine_but_different_ones_are_refused():
    from warpfric.io import concat_members

    recorded, plain = _alone(0.2, 0, record=True), _alone(0.2, 1)
    both = concat_members([plain, recorded])  # recorded members in some parts only: as before
    assert both.recorded_member.values.tolist() == [0] and both.sizes["member"] == 2
    np.testing.assert_array_equal(both.velocity_history.values, recorded.velocity_history.values)
    other = _alone(0.2, 2, record=True).drop_vars("slip_rate_history")
    with pytest.raises(ValueError, match=r"^dataset 0 and dataset 1 hold different recorded fields \(dataset 0 has "
                                         r"slip_rate_history, which dataset 1 lacks\)"):
        concat_members([recorded, other])


def test_a_file_of_an_earlier_version_without_detachment_end_time_combines_with_a_new_one(tmp_path):
    """Files written before detachment_end_time was an output lack it: reading one gives it NaN,
    named as unknown (not as a cut-off run), and such a file combines with a new one (the check of
    the parts' variables would refuse it otherwise); the new file's values are kept."""
    new = run({"eccentricity": [0.1]}, nodes=11, fronts=wf.Fronts())
    old = wf.simulate({"eccentricity": [0.2]}, solver=wf.Solver(nodes=11, rtol=1e-6), fronts=wf.Fronts(),
                      device=DEVICE, progress=False, member_offset=1)
    write_ensemble(new, tmp_path / "new.nc")
    write_ensemble(old.drop_vars("detachment_end_time"), tmp_path / "old.nc")
    read = open_ensemble(tmp_path / "old.nc")
    assert np.isnan(read.detachment_end_time.values).all()
    assert "unknown" in read.detachment_end_time.attrs["long_name"]
    both = open_ensembles([tmp_path / "new.nc", tmp_path / "old.nc"])
    assert both.detachment_end_time.values[0] == new.detachment_end_time.values[0] == new.final_time.values[0]
    assert np.isnan(both.detachment_end_time.values[1])
    # the old member saw its front through (finite detached_fraction): not taken for a run cut off (a
    # resume over old chunks warned of every old member, and the map's legend said "not given")
    from warpfric.simulate import detachment_not_over, warn_detachment_not_over

    assert np.isfinite(both.detached_fraction.values).all()
    capped, cut = detachment_not_over(both)
    assert not capped.any() and not cut.any()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_detachment_not_over(both)


def test_parts_run_on_different_devices_say_so_in_the_combination(tmp_path):
    """A --resume on another device (or another team size) gave the combined file the first chunk's
    device and lanes only: where the parts differ the attribute lists them all; where they agree it
    stays as it was."""
    from warpfric.io import concat_members

    a = run({"eccentricity": [0.1]}, nodes=11)
    b = wf.simulate({"eccentricity": [0.2]}, solver=wf.Solver(nodes=11, rtol=1e-6), device=DEVICE, progress=False,
                    member_offset=1, fronts=None)
    same = concat_members([a, b])
    assert same.attrs["device"] == a.attrs["device"] and same.attrs["lanes"] == a.attrs["lanes"]
    b.attrs["device"], b.attrs["lanes"] = "cuda:0", 32
    mixed = concat_members([a, b])
    assert mixed.attrs["device"] == f"mixed: {a.attrs['device']}, cuda:0"
    assert mixed.attrs["lanes"] == f"mixed: {a.attrs['lanes']}, 32"


def test_write_ensemble_says_what_to_use_for_datasets_it_cannot_write(tmp_path):
    """Three ways an xarray user reached a traceback or a bloated file: a file read with
    xr.open_dataset (its members are labels: "invalid literal for int()"), ds.where(status == 0)
    (the recorded fields broadcast over member: written, each field once per member) and a selection
    that drops a recorded member. Each is refused in one line that says what to use; the selection
    the message names writes. Two files of the same run's members are told so, not sent to
    open_mfdataset (whose index they would break)."""
    from warpfric.io import open_ensemble, open_ensembles

    ds = run({"eccentricity": [0.0, 0.1, 0.2]}, nodes=11, record=wf.Record.window(20.1, 20.2, 5, members=(0, 2)))
    write_ensemble(ds, tmp_path / "a.nc")
    with pytest.raises(ValueError, match=r"the members are labels .* warpfric.io.open_ensemble or open_ensembles"):
        write_ensemble(xr.open_dataset(tmp_path / "a.nc"), tmp_path / "b.nc")
    with pytest.raises(ValueError, match=r"lie along both recorded and member.*ds.sel\(member="):
        write_ensemble(ds.where(ds.status == 0), tmp_path / "b.nc")
    with pytest.raises(ValueError, match=r"ds.isel\(recorded=\[1\]\), or drop the recorded fields"):
        write_ensemble(ds.sel(member=[1, 2]), tmp_path / "b.nc")
    write_ensemble(ds.sel(member=[1, 2]).isel(recorded=[1]), tmp_path / "b.nc")
    assert open_ensemble(tmp_path / "b.nc").recorded_member.values.tolist() == [2]
    # a selection of a file read back keeps that file's labels (open_ensemble): the same members
    write_ensemble(open_ensemble(tmp_path / "a.nc").sel(member=[1, 2]).isel(recorded=[1]), tmp_path / "c.nc")
    with pytest.raises(ValueError, match="with the same member labels: the same members of one run"):
        open_ensembles([tmp_path / "a.nc", tmp_path / "c.nc"])
    with pytest.raises(ValueError, match="xr.open_mfdataset"):  # b.nc's members were labelled anew: another run
        open_ensembles([tmp_path / "a.nc", tmp_path / "b.nc"])


def test_open_ensembles_orders_the_members_and_keeps_every_files_history(tmp_path):
    """Files given out of order (["b.nc", "a.nc"]) gave members 3 4 5 0 1 2, an index that is not
    monotonic, and the first file's history only: the members come in order, with their values,
    and the history has each file's command."""
    from warpfric.io import open_ensembles

    a = run({"eccentricity": [0.0, 0.1, 0.2]}, nodes=11)
    b = wf.simulate({"eccentricity": [0.3, 0.4]}, solver=wf.Solver(nodes=11, rtol=1e-6), device=DEVICE,
                    progress=False, member_offset=3, fronts=None)
    write_ensemble(a, tmp_path / "a.nc", command="run A")
    write_ensemble(b, tmp_path / "b.nc", command="run B")
    both = open_ensembles([tmp_path / "b.nc", tmp_path / "a.nc"])
    assert both.member.values.tolist() == [0, 1, 2, 3, 4]
    np.testing.assert_array_equal(both.eccentricity.values, [0.0, 0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(both.mu_s.values[3:], b.mu_s.values)
    assert "run A" in both.attrs["history"] and "run B" in both.attrs["history"]


def test_a_multiindex_member_and_the_flags_of_older_parts(tmp_path):
    """write_ensemble of a Dataset whose member is a MultiIndex said 'the members are labels (the file's
    layout)', which it never was: it names the MultiIndex. A combination of a part without -3
    (unknown) among its nucleation_edge flags and one with it declares -3."""
    from warpfric.io import concat_members

    ds = run({"eccentricity": [0.0, 0.1]}, nodes=11, fronts=wf.Fronts())
    multi = ds.set_coords("eccentricity").set_index(member=["eccentricity"], append=True)
    with pytest.raises(ValueError, match="member is a MultiIndex .* .reset_index\\('member'\\)"):
        write_ensemble(multi, tmp_path / "m.nc")
    other = wf.simulate({"eccentricity": [0.2]}, solver=wf.Solver(nodes=11, rtol=1e-6), fronts=wf.Fronts(),
                        device=DEVICE, progress=False, member_offset=2)
    older = ds.copy()
    older["nucleation_edge"] = older.nucleation_edge.copy()
    older["nucleation_edge"].attrs.update(flag_values=np.array([-2, -1, 0, 1], np.int8),
                                          flag_meanings="none left interior right")
    both = concat_members([older, other])
    assert both.nucleation_edge.attrs["flag_meanings"] == "unknown none left interior right"


def test_history_has_a_line_per_run_not_per_command_text(tmp_path):
    """A run's chunks and the file that combines them carry the line of the run that wrote them, its
    start time included: the finishing --resume was listed twice, and an interrupted --resume merged
    into a later one of the same command text (a helper's run of sweeps.md's steps)."""
    from warpfric.io import merged_history

    def part(*lines):
        return xr.Dataset(attrs={"history": "\n".join(lines)})

    version = f"(warpfric {wf.__version__})"
    first = f"2026-11-27T06:40:45Z: warpfric run mid.toml -o mid.nc --chunk 200 {version}"
    resume1 = f"2026-11-27T06:40:55Z: warpfric run mid.toml -o mid.nc --resume {version}"
    resume2 = f"2026-11-27T06:41:14Z: warpfric run mid.toml -o mid.nc --resume {version}"
    merged = merged_history([part(first), part(first), part(resume1), part(resume2), part(resume2)])
    assert merged.splitlines() == [resume2, resume1, first]
    ds = run({"eccentricity": [0.0]}, nodes=11)
    ds.attrs["history"] = merged
    # the finishing run writes its own line, the one its chunks carry: once
    write_ensemble(ds, tmp_path / "c.nc", command="warpfric run mid.toml -o mid.nc --resume",
                   started="2026-11-27T06:41:14Z")
    with xr.open_dataset(tmp_path / "c.nc") as back:
        assert back.attrs["history"].splitlines() == [resume2, resume1, first]
    with pytest.raises(ValueError, match=r"started = '27 Nov 2026' is invalid; valid: None \(now\) or a UTC time"):
        write_ensemble(ds, tmp_path / "d.nc", command="x", started="27 Nov 2026")


def test_write_ensemble_sorts_its_members_keeps_text_and_checks_complevel(tmp_path):
    """From a host-code review: a selection out of order (isel([2, 0, 1]), sortby("mu_s")) was written
    with unsorted labels, which xr.open_mfdataset's default refuses; a text variable along member
    raised KeyError; complevel 10 failed inside netCDF naming 'shear_modulus'."""
    ds = run({"eccentricity": [0.0, 0.1, 0.2]}, nodes=11)
    ds["label"] = ("member", np.array(["a", "bb", "ccc"]))
    ds = ds.assign_coords(site=("member", ["north", "south", "east"]))  # a text coordinate too
    write_ensemble(ds.isel(member=[2, 0, 1]), tmp_path / "a.nc")
    back = open_ensemble(tmp_path / "a.nc")
    assert back.member.values.tolist() == [0, 1, 2] and back.label.values.tolist() == ["a", "bb", "ccc"]
    assert back.site.values.tolist() == ["north", "south", "east"]
    np.testing.assert_array_equal(back.mu_s.values, ds.mu_s.values)
    later = wf.simulate({"eccentricity": [0.3]}, solver=wf.Solver(nodes=11, rtol=1e-6), fronts=None, device=DEVICE,
                        progress=False, member_offset=3)
    write_ensemble(later, tmp_path / "b.nc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # xarray's coming change of its defaults
        with xr.open_mfdataset([tmp_path / "a.nc", tmp_path / "b.nc"]) as both:
            assert both.sizes["member"] == 4
    for bad in (10, 0, 4.5, "high", True):
        with pytest.raises(ValueError, match=re.escape(f"complevel = {bad!r} is invalid; valid: an integer in [1, 9]")):
            write_ensemble(ds, tmp_path / "c.nc", complevel=bad)
    assert not (tmp_path / "c.nc").exists()
