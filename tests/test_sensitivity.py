"""Sensitivity designs and indices: SALib's Ishigami function through warpfric's own
design -> dataset -> analysis path, a small real design through the command line, failed
members, and bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr
from conftest import DEVICE

pytest.importorskip("SALib")
from warpfric.cli import main  # noqa: E402
from warpfric.sensitivity import DESIGN_ATTR, analyse, generate, parse_design  # noqa: E402

# Ishigami (a = 7, b = 0.1): analytic indices (Saltelli et al. 2008; SALib's test values)
S1_TRUE = np.array([0.3139, 0.4424, 0.0, 0.0])
ST_TRUE = np.array([0.5576, 0.4424, 0.2437, 0.0])


def ishigami_dataset(method="saltelli", n=1024, seed=7):
    spec = {"method": method, "n": n, "seed": seed,
            "parameters": {f"x{i}": {"low": -np.pi, "high": np.pi} for i in (1, 2, 3, 4)}}  # x4: a dummy
    design = parse_design(spec, check_names=False)
    rows = generate(design)
    x1, x2, x3 = rows["x1"], rows["x2"], rows["x3"]
    y = np.sin(x1) + 7 * np.sin(x2) ** 2 + 0.1 * x3 ** 4 * np.sin(x1)
    data = {k: ("member", v) for k, v in rows.items()}
    data["y"] = ("member", y)
    data["status"] = ("member", np.zeros(y.size, dtype=np.int32))
    return xr.Dataset(data, attrs={DESIGN_ATTR: json.dumps(design)})


def test_ishigami_sobol_indices_within_confidence():
    res = analyse(ishigami_dataset(), ("y",), num_resamples=200).sel(output="y")
    for key, true in (("S1", S1_TRUE), ("ST", ST_TRUE)):
        est, conf = res[key].values, res[f"{key}_conf"].values
        assert np.all(np.abs(est - true) <= 1.5 * conf + 0.01), (key, est, conf)
    assert abs(float(res.S2.sel(parameter="x1", parameter_2="x3")) - 0.2437) < 0.1  # the x1-x3 interaction
    assert abs(float(res.ST.sel(parameter="x4"))) < 0.01
    assert res.S2.attrs["units"] == res.S2_conf.attrs["units"] == "1"  # Sobol indices are fractions of the variance


def test_the_bar_figure_keeps_its_legend_off_the_bars_and_names_the_error_bars():
    """The legend sat inside the last panel, over its bars, and nothing said what the error bars
    were."""
    from warpfric.sensitivity import bar_figure

    fig = bar_figure(analyse(ishigami_dataset(n=256), ("y",), num_resamples=50, conf_level=0.9))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    (ax,) = fig.axes
    legend = ax.get_legend()
    assert legend.get_window_extent(renderer).x0 > ax.get_window_extent(renderer).x1
    assert "90% confidence" in legend.get_title().get_text()
    assert [t.get_text() for t in legend.get_texts()] == ["S1 (first order)", "ST (total)"]


def test_a_ctrl_c_inside_the_sampling_is_raised_after_it(monkeypatch):
    """A Ctrl-C that lands inside SALib's sampling: scipy's compiled Sobol set-up swallows the
    KeyboardInterrupt raised there (emulated: a sample function that catches it and goes on), so
    generate holds the signal and raises it once the sampling ends."""
    import os
    import signal
    import time

    from SALib.sample import sobol

    real_sample = sobol.sample

    def swallowing_sample(*args, **kwargs):
        try:
            os.kill(os.getpid(), signal.SIGINT)  # Python's handler of the moment runs as kill returns
            time.sleep(0.01)
        except KeyboardInterrupt:
            pass  # what scipy's compiled code does: "Exception ignored in ..."
        return real_sample(*args, **kwargs)

    monkeypatch.setattr(sobol, "sample", swallowing_sample)
    # Python's own Ctrl-C, also where the tests run with SIGINT ignored (started with & from a script)
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            ishigami_dataset(n=8)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # Python's own handler again
    finally:
        signal.signal(signal.SIGINT, inherited)
    monkeypatch.undo()
    assert generate(parse_design({"method": "saltelli", "n": 8, "seed": 1, "parameters": {
        "x1": {"low": 0.0, "high": 1.0}, "x2": {"low": 0.0, "high": 1.0}}}, check_names=False))["x1"].size == 48


def test_a_small_base_size_warns_that_the_indices_are_not_resolved():
    """At n = 8 the Ishigami indices have half-widths of ~0.6 (S1 of x3 below 0): one warning names
    the output and its half-width; at n = 1024 (half-widths <= 0.08) there is none."""
    import warnings

    with pytest.warns(UserWarning, match=r"not resolved at base size n = 8: confidence half-widths up to 'y' \+- 0\.6"):
        res = analyse(ishigami_dataset(n=8), ("y",))
    assert float(np.maximum(res.S1_conf, res.ST_conf).max()) > 0.1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = analyse(ishigami_dataset(n=1024), ("y",))
    assert float(np.maximum(res.S1_conf, res.ST_conf).max()) <= 0.1


def test_morris_ranks_the_dummy_last():
    res = analyse(ishigami_dataset("morris", n=200), ("y",)).sel(output="y")
    mu_star = res.mu_star.values
    assert mu_star[3] < 1e-9 < mu_star[:3].min()


def test_failed_members_are_refused_or_filled_explicitly():
    ds = ishigami_dataset(n=64)
    ds["y"].values[[3, 10]] = np.nan
    ds["status"].values[5] = 1
    with pytest.raises(ValueError, match=r"3 of .* members failed or lack it .*3, 5, 10.*fill-mean to replace them "
                                         r"by the mean; 2 of them ended ok without it, so the mean stands for something"):
        analyse(ds, ("y",))  # members 3 and 10 ok without y, member 5 failed
    with pytest.warns(UserWarning, match="not resolved at base size n = 64"):  # a small design, on purpose
        res = analyse(ds, ("y",), on_failure="fill-mean")
    assert int(res.filled_members.sel(output="y")) == 3


def test_small_real_design_through_the_command_line(tmp_path):
    sweep = tmp_path / "design.toml"
    sweep.write_text("""
[solver]
nodes = 40
[design]
method = "saltelli"
n = 32
seed = 3
second_order = false
[design.parameters]
eccentricity = {low = -0.3, high = 0.3}
normal_force = {low = 300.0, high = 3000.0, scale = "log"}
aging_coefficient = {low = 0.05, high = 0.1}
""")
    out = tmp_path / "design.nc"
    run = subprocess.run([sys.executable, "-m", "warpfric", "run", str(sweep), "-o", str(out), "--device", DEVICE,
                          "--quiet"], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    res = subprocess.run([sys.executable, "-m", "warpfric", "sensitivity", str(out), "--output", "mu_s",
                          "--output", "v_middle"], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    result = xr.load_dataset(tmp_path / "design_sensitivity.nc")
    assert result.attrs["members"] == 32 * 5
    # CF: every variable has units and every coordinate a long_name; the file says what wrote it
    assert all("units" in result[v].attrs for v in result.data_vars), {v: result[v].attrs for v in result.data_vars}
    assert all("long_name" in result[c].attrs for c in result.coords)
    assert result.attrs["Conventions"] == "CF-1.8" and "warpfric sensitivity" in result.attrs["history"]
    assert result.attrs["title"] == "saltelli sensitivity of mu_s, v_middle to eccentricity, normal_force, aging_coefficient"
    st = result.ST.sel(output="mu_s")
    # the aging coefficient sets the contact strength; eccentricity and force move mu_s by < 1e-3
    assert float(st.sel(parameter="aging_coefficient")) > 0.8
    assert (tmp_path / "design_sensitivity.png").stat().st_size > 10_000
    info = subprocess.run([sys.executable, "-m", "warpfric", "info", str(out)], capture_output=True, text=True, timeout=600)
    assert "sensitivity design: saltelli, base size 32, seed 3, 3 parameters" in info.stdout
    with xr.open_dataset(out) as opened:
        design = json.loads(opened.attrs[DESIGN_ATTR])
    assert design["method"] == "saltelli" and design["seed"] == 3 and design["scales"][1] == "log"


BAD = [
    ('method = "saltelli"\nn = 16\n[design.parameters]\nfoo = {low = 0.0, high = 1.0}\neccentricity = {low = 0.0, high = 0.1}\n',
     ["foo", "accepted"]),
    ('method = "saltelli"\nn = 16\n[design.parameters]\neccentricity = {low = 0.2, high = 0.1}\nnormal_force = {low = 1.0, high = 2.0}\n',
     ["eccentricity", "low = 0.2", "below high"]),
    ('method = "saltelli"\nn = 100\n[design.parameters]\neccentricity = {low = 0.0, high = 0.1}\nnormal_force = {low = 1.0, high = 2.0}\n',
     ["n = 100", "power of two"]),
    ('method = "sobolev"\nn = 16\n[design.parameters]\neccentricity = {low = 0.0, high = 0.1}\nnormal_force = {low = 1.0, high = 2.0}\n',
     ["sobolev", "saltelli"]),
    # a missing key read "n = None" / "method = None"; a bound outside the range was found only if a
    # sampled row fell outside it, as "eccentricity[0] = -0.72..., 2 members out of range"
    ('method = "saltelli"\n[design.parameters]\neccentricity = {low = 0.0, high = 0.1}\nnormal_force = {low = 1.0, high = 2.0}\n',
     ["[design] n: missing", "the base sample size"]),
    ('n = 16\n[design.parameters]\neccentricity = {low = 0.0, high = 0.1}\nnormal_force = {low = 1.0, high = 2.0}\n',
     ["[design] method: missing", "saltelli, morris, latin"]),
    ('method = "latin"\nn = 4\n[design.parameters]\neccentricity = {low = -0.9, high = 0.2}\nnormal_force = {low = 1.0, high = 2.0}\n',
     ["[design.parameters] eccentricity.low = -0.9 is outside eccentricity's valid range [-0.6, 0.6]"]),
    # morris levels take high itself: poisson_ratio's open limit 0.5 was found only in the sampled rows
    ('method = "morris"\nn = 4\n[design.parameters]\npoisson_ratio = {low = 0.3, high = 0.5}\nnormal_force = {low = 1.0, high = 2.0}\n',
     ["[design.parameters] poisson_ratio.high = 0.5 is outside poisson_ratio's valid range (-1, 0.5)"]),
]


@pytest.mark.parametrize("key, method", [("second_order = true", "morris"), ("levels = 4", "saltelli")])
def test_a_design_key_that_its_method_does_not_read_is_said(key, method):
    """second_order (saltelli only) and levels (morris only) were accepted without a word under the
    other method, as an unused [fronts] threshold is not."""
    from warpfric.sweep_file import parse_sweep

    text = (f'[design]\nmethod = "{method}"\nn = 4\n{key}\n[design.parameters]\n'
            'eccentricity = {low = -0.1, high = 0.1}\nnormal_force = {low = 500.0, high = 2000.0}\n')
    with pytest.warns(UserWarning, match=rf"\[design\] {key.split()[0]} applies to method = '(saltelli|morris)' only: "
                                         rf"method = '{method}' does not read it"):
        parse_sweep(text, "d.toml")


@pytest.mark.parametrize("design, words", BAD)
def test_bad_designs_exit_2_with_one_line(tmp_path, capsys, design, words):
    sweep = tmp_path / "bad.toml"
    sweep.write_text("[design]\n" + design)
    code = main(["run", str(sweep), "-o", str(tmp_path / "bad.nc"), "--device", "cpu"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    for word in words:
        assert word in err[0], (word, err[0])
    assert not (tmp_path / "bad.nc").exists()


def test_output_not_in_the_file(tmp_path, capsys):
    ds = ishigami_dataset(n=16)
    ds.attrs["warpfric_complete"] = 1
    path = tmp_path / "ish.nc"
    ds.to_netcdf(path)
    code = main(["sensitivity", str(path), "--output", "v_sideways"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "v_sideways" in err[0] and "available: " in err[0] and "y" in err[0]


def test_results_are_not_replaced_without_overwrite_and_the_ensemble_never(tmp_path, capsys):
    """`warpfric sensitivity` replaced its result, its figure and even the ensemble it read (-o on
    the input) without a word, and a missing folder ended in a traceback."""
    ds = ishigami_dataset(n=64)
    ds.attrs["warpfric_complete"] = 1
    path = tmp_path / "ish.nc"
    ds.to_netcdf(path)
    result, figure = tmp_path / "ish_sensitivity.nc", tmp_path / "ish_sensitivity.png"

    def run(*extra):
        code = main(["sensitivity", str(path), "--output", "y", *extra])
        return code, capsys.readouterr().err.strip().splitlines()

    assert run()[0] == 0 and result.exists() and figure.exists()
    first = result.stat().st_mtime_ns, figure.read_bytes()
    code, err = run()
    assert code == 2 and len(err) == 1 and "ish_sensitivity.nc' exists; pass --overwrite" in err[0], err
    assert (result.stat().st_mtime_ns, figure.read_bytes()) == first
    # a wrong output name is said first, not "exists" (which sent a user to --overwrite to learn it)
    code = main(["sensitivity", str(path), "--output", "v_sideways"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "'v_sideways' is not a per-member variable" in err[0], err
    figure.unlink()  # the figure alone, left from an earlier run, is refused the same
    result.rename(tmp_path / "kept.nc")
    figure.write_bytes(b"an older figure")
    code, err = run()
    assert code == 2 and "ish_sensitivity.png' exists" in err[0] and not result.exists(), err
    code, err = run("-o", str(path), "--overwrite")
    assert code == 2 and len(err) == 1 and "is the ensemble being analysed" in err[0], err
    with xr.open_dataset(path) as kept:
        assert kept.y.size == ds.y.size and DESIGN_ATTR in kept.attrs
    code, err = run("-o", str(tmp_path / "no_folder" / "x.nc"))
    assert code == 2 and len(err) == 1 and "does not exist" in err[0], err
    code, err = run("--overwrite")
    assert code == 0 and result.exists() and figure.read_bytes() != b"an older figure"
    assert not list(tmp_path.glob("*.tmp*"))
    # a folder where the figure goes: refused before anything is written (the result was written, then
    # the figure failed with exit 3), also with --overwrite, which cannot replace a folder
    result.unlink()
    figure.unlink()
    figure.mkdir()
    code, err = run("--overwrite")
    assert code == 2 and len(err) == 1 and "ish_sensitivity.png' is a folder" in err[0] and not result.exists(), err
    figure.rmdir()
    code, err = run("--overwrite")
    assert code == 0 and result.exists() and figure.is_file()
    with xr.open_dataset(result) as res:
        assert "S1" in res and list(res.output.values) == ["y"]


@pytest.mark.parametrize("outputs, words", [
    # the result file was written with ['y', 'y'] and the figure then failed in matplotlib
    (("y", "y"), ["output 'y' is given more than once"]),
    (("x1",), ["output 'x1' is an input parameter; available: y"]),
    (("status",), ["output 'status' is a flag variable; available: y"]),
    (("constant",), ["output 'constant' is the same in every member: its variance is 0"]),
])
def test_outputs_without_indices_are_refused(outputs, words):
    """Indices of a repeated output, of an input, of a flag or of a constant (0/0: '0.000 +- 0.000'
    with numpy's divide warning) are refused with the output's name."""
    ds = ishigami_dataset(n=16)
    ds["constant"] = ("member", np.ones(ds.sizes["member"]))
    with pytest.raises(ValueError) as err:
        analyse(ds, outputs)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_an_output_filled_into_a_constant_is_refused():
    """All members but one failed: filling them with the one left's value leaves no variance."""
    ds = ishigami_dataset(n=16)
    ds["status"].values[1:] = 1
    with pytest.raises(ValueError, match=r"'y' is the same in every member once the 159 of 160 that failed are filled"):
        analyse(ds, ("y",), on_failure="fill-mean")


def test_the_command_says_a_design_s_faults_and_an_unwritable_folder_before_the_analysis(tmp_path, capsys,
                                                                                         monkeypatch):
    """Members lacking an output were told only after "exists" and --overwrite, and a folder that
    cannot be written only after the analysis (exit 3, "could not write"), where `warpfric run` and
    `plot` say both first: exit 2, one line, nothing analysed."""
    import os
    from pathlib import Path

    import warpfric.sensitivity as sensitivity

    ds = ishigami_dataset(n=16)
    ds.attrs["warpfric_complete"] = 1
    ds["y"].values[[3, 5]] = np.nan  # two members lack the output
    path = tmp_path / "ish.nc"
    ds.to_netcdf(path)
    (tmp_path / "ish_sensitivity.nc").write_bytes(b"an earlier result")
    assert main(["sensitivity", str(path), "--output", "y"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "output 'y': 2 of 160 members failed or lack it (members 3, 5)" in err[0], err

    folder = (tmp_path / "ro").resolve()
    folder.mkdir()
    real_open = os.open

    def denied(p, flags, *args, **kwargs):  # the folder refuses new files, as a read-only one does
        if flags & os.O_CREAT and Path(p).resolve().parent == folder:
            raise PermissionError(13, "Permission denied", str(p))
        return real_open(p, flags, *args, **kwargs)

    analysed = []
    monkeypatch.setattr(os, "open", denied)
    monkeypatch.setattr(sensitivity, "analyse", lambda *a, **k: analysed.append(1))
    code = main(["sensitivity", str(path), "--output", "y", "--on-failure", "fill-mean", "-o", str(folder / "s.nc")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and f"cannot write in folder '{folder}' (permission denied)" in err[0], err
    assert analysed == [] and list(folder.iterdir()) == []


def test_an_output_no_member_has_is_refused_also_when_filling():
    """fill-mean over an output that every member lacks filled it with the mean of nothing (NaN), the
    zero-variance check let NaN through and SALib returned S1 = 0 for every parameter: written as a
    result. It is refused, naming the output."""
    ds = ishigami_dataset(n=16)
    ds["y"].values[:] = np.nan
    with pytest.raises(ValueError, match=r"output 'y': all 160 members failed or lack it"):
        analyse(ds, ("y",), on_failure="fill-mean")


def test_a_misspelt_output_and_values_the_log_cannot_take_are_named():
    """An output typo (mu_S) listed 70 names without the closest; --log over an output with values
    <= 0 said the ok members 'failed or lack it' (a user's study)."""
    ds = ishigami_dataset(n=16)
    with pytest.raises(ValueError, match=r"output 'Y' is not a per-member variable of the file \(did you mean 'y'\?\)"):
        analyse(ds, ("Y",))
    with pytest.raises(ValueError, match=r"output 'y': \d+ of 160 members failed or lack it \(members .*; \d+ of them "
                                         r"ok with a value <= 0, which the log \(--log\) cannot take\)"):
        analyse(ds, ("y",), log=True)  # the Ishigami function takes negative values


def test_many_outputs_and_parameters_wrap_into_rows():
    """20 parameters x 6 outputs made one row ~9,000 px wide: the panels now wrap, at most three a
    row and one a row where a panel is wide, each panel at most 14 inches."""
    from warpfric.sensitivity import bar_figure

    def indices(n_parameters, n_outputs):
        values = np.random.default_rng(0).random((n_outputs, n_parameters))
        return xr.Dataset({k: (("output", "parameter"), values) for k in ("S1", "S1_conf", "ST", "ST_conf")},
                          coords={"output": [f"y{i}" for i in range(n_outputs)],
                                  "parameter": [f"x{i}" for i in range(n_parameters)]})

    for n_parameters, n_outputs, shape in ((20, 6, (6, 1)), (6, 5, (2, 3)), (3, 2, (1, 2))):
        fig = bar_figure(indices(n_parameters, n_outputs))
        shown = [ax for ax in fig.axes if ax.get_visible()]
        rows = len({round(ax.get_position().y0, 3) for ax in shown})
        columns = len({round(ax.get_position().x0, 3) for ax in shown})
        assert len(shown) == n_outputs and (rows, columns) == shape, (n_parameters, n_outputs, rows, columns)
        assert fig.get_size_inches()[0] <= 3 * 7.0 + 1e-9 or columns == 1
