"""Messages a person can read (issue 22, part 7): a bad value in a per-member array names the
member; a dimensionless parameter prints no '(1)', which reads like an index."""

import re

import numpy as np
import pytest
from conftest import DEVICE

import warpfric as wf
from warpfric.cli import main, summary


def _refusal(members) -> str:
    with pytest.raises(ValueError) as err:
        wf.simulate(members, device=DEVICE, progress=False)
    return str(err.value)


def test_a_nan_among_10000_members_is_named_by_its_index():
    e = np.zeros(10_000)
    e[1234] = np.nan
    assert _refusal({"eccentricity": e}) == ("parameter eccentricity[1234] = nan is out of range; valid range "
                                             "[-0.6, 0.6] (dimensionless)")


def test_a_masked_member_is_refused_as_a_nan_is():
    """netCDF4 returns missing values as a masked array; np.asarray dropped the mask and the member ran
    with the data under it (status ok), where a NaN in its place is refused."""
    force = np.ma.masked_array([500.0, 1000.0, 800.0, 0.0], mask=[False, True, False, True])
    assert _refusal({"normal_force": force}) == ("parameter normal_force[1] is masked (no value: a missing or fill "
                                                 "value, as netCDF4 returns it) (2 members masked); valid range "
                                                 "(0, inf) N; give every member a value")
    unmasked = wf.simulate({"normal_force": np.ma.masked_array([500.0, 1000.0])}, solver=wf.Solver(nodes=11),
                           fronts=None, device=DEVICE, progress=False)
    assert unmasked.normal_force.values.tolist() == [500.0, 1000.0] and (unmasked.status.values == 0).all()


def test_the_first_bad_member_is_named_with_the_unit_and_the_count():
    message = _refusal({"normal_force": [1000.0, -2.0, np.inf]})
    assert message == ("parameter normal_force[1] = -2.0 N is out of range; valid range (0, inf) N "
                       "(2 members out of range)")


def test_broadcast_members_are_named_by_their_flat_index():
    # 3 x 2 members in C order: normal_force[2] is member (1, 0)
    message = _refusal({"normal_force": [[500.0], [np.nan], [800.0]], "eccentricity": [0.0, 0.1]})
    assert message.startswith("parameter normal_force[2] = nan N is out of range")


@pytest.mark.parametrize("members", [{"eccentricity": 0.9}, {"eccentricity": [0.1, 0.9]}, {"poisson_ratio": 0.5},
                                     {"aging_coefficient": -1.0}])
def test_dimensionless_parameters_print_no_unit_1(members):
    message = _refusal(members)
    assert "(1)" not in message and not re.search(r"\b1\)", message) and "(dimensionless)" in message


def test_a_scalar_is_named_without_an_index():
    assert _refusal({"density": np.nan}).startswith("parameter 'density' = nan kg m-3 is out of range")


def test_a_sweep_file_value_names_its_member(tmp_path, capsys):
    """A swept value out of range names the file, the parameter's index in its list and the range; a
    [scene] or [solver] value out of range names the file and the table."""
    sweep = tmp_path / "s.toml"
    sweep.write_text("[grid]\nnormal_force = [500.0, 1000.0]\neccentricity = [0.0, 0.2, 0.7]\n")
    assert main(["run", str(sweep), "-o", str(tmp_path / "s.nc")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"warpfric: error: {sweep}: parameter eccentricity[2] = 0.7 is out of range; valid range [-0.6, 0.6] "
                   "(dimensionless) (2 members out of range)")
    for table, line, words in (("scene", "normal_force = -3.0", "parameter 'normal_force' = -3.0 N is out of range"),
                               ("solver", "nodes = 2", "solver setting 'nodes' = 2 is invalid")):
        sweep.write_text(f"[{table}]\n{line}\n[grid]\neccentricity = [0.0]\n")
        assert main(["run", str(sweep), "-o", str(tmp_path / "s.nc")]) == 2
        assert capsys.readouterr().err.startswith(f"warpfric: error: {sweep}: [{table}] {words}")


def test_info_prints_dimensionless_ranges_without_unit_1():
    ds = wf.simulate({"eccentricity": [0.0, 0.1], "normal_force": [500.0, 600.0]}, solver=wf.Solver(nodes=11),
                     fronts=None, device=DEVICE, progress=False)
    ds.attrs.update(varying_parameters="normal_force eccentricity", warpfric_version="x", wall_time_s=0.0)
    lines = summary(ds, "x.nc").splitlines()
    ecc = next(line for line in lines if line.strip().startswith("eccentricity"))
    force = next(line for line in lines if line.strip().startswith("normal_force"))
    assert ecc.endswith("in [0, 0.1] (dimensionless)") and force.endswith("in [500, 600] N")


def test_info_names_the_members_not_ok():
    """`warpfric info` lists the members of each status other than ok by their numbers, the first
    ten, then how many more (the CLI's warning of members not ok points there)."""
    ds = wf.simulate({"eccentricity": np.zeros(14), "normal_force": np.full(14, 500.0)}, solver=wf.Solver(nodes=11),
                     fronts=None, device=DEVICE, progress=False, member_offset=100)
    ds.attrs.update(warpfric_version="x", wall_time_s=0.0)
    meanings = ds.status.attrs["flag_meanings"].split()
    status = np.zeros(14, dtype=np.int32)
    status[[1, 4]] = meanings.index("stalled")
    status[2:] = np.where(np.arange(2, 14) >= 3, meanings.index("no_peak"), status[2:])
    ds["status"].values[:] = status
    lines = summary(ds, "x.nc").splitlines()
    assert "  status: ok 2, no_peak 11, stalled 1" in lines or "  status: ok 2, stalled 1, no_peak 11" in lines
    assert f"    stalled: member 101" in lines
    assert "    no_peak: members 103, 104, 105, 106, 107, 108, 109, 110, 111, 112 and 1 more" in lines


def test_help_of_simulate_names_every_output():
    """help(warpfric.simulate) is where docs/sweeps.md sends a reader for the outputs; it had fallen
    behind them (detachment_end_time was missing). Every variable of a run with the default front,
    the velocity and strength events, a recording and the grid check is named there, by name or by
    a documented pattern (``v_*``); the input parameters are "every input parameter"."""
    from warpfric.parameters import PARAMETER_NAMES

    ds = wf.simulate(solver=wf.Solver(nodes=21, rtol=1e-4), fronts=wf.Fronts(event=("contact", "velocity", "strength"),
                                                                             grid_check=True),
                     record=wf.Record.window(20.1, 20.2, 3), device=DEVICE, progress=False)
    named = re.findall(r"``([A-Za-z0-9_*]+)``", wf.simulate.__doc__)
    patterns = [re.compile("^" + name.replace("*", "[a-z0-9]+") + "$") for name in named]
    prefixes = ("velocity_", "strength_")  # an event other than the first: its outputs prefixed
    missing = [v for v in list(ds.data_vars) + list(ds.coords) if v not in PARAMETER_NAMES and not any(
        p.match(v) or (v.startswith(prefixes) and p.match(v.split("_", 1)[1])) for p in patterns)]
    assert missing == [], missing


def test_a_record_of_many_times_prints_their_count_and_range():
    """print(Record.detachment(...)) dumped 1,001 floats (a user's study)."""
    assert repr(wf.Record.window(20.0, 20.3, 1001, members=(2,))) == \
        "Record(members=(2,), times=<1001 times from 20 to 20.3 s>)"
    assert repr(wf.Record(members=(0,), times=(20.1, 20.2))) == "Record(members=(0,), times=(20.1, 20.2))"
