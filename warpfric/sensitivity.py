"""warpfric.sensitivity: sampling designs and Sobol / Morris indices over ensembles, with SALib
(optional extra: ``pip install "warpfric[sensitivity]"``).

A sweep file's ``[design]`` table (docs/sweeps.md)::

    [design]
    method = "saltelli"        # "saltelli" (Sobol indices), "morris", "latin"
    n = 1024                   # base size: Saltelli rows = n*(2D+2) (n*(D+2) without second order),
                               # Morris rows = n*(D+1) (n trajectories), Latin rows = n
    seed = 1
    second_order = true        # saltelli only
    levels = 4                 # morris only
    [design.parameters]
    eccentricity = {low = -0.3, high = 0.3}
    normal_force = {low = 300.0, high = 3000.0, scale = "log"}   # sampled uniformly in log

The design (method, problem, seed, sizes) is stored in the output's global attribute
``sensitivity_design`` (JSON), so :func:`analyse` can redo the analysis from the file alone.
Members whose status is not ok, or whose requested output is NaN (an absent front segment), are
never dropped silently: a Saltelli or Morris analysis needs every row, so :func:`analyse` refuses
them unless ``on_failure="fill-mean"``, which replaces them by the mean of the other members and
records how many it replaced (attribute ``filled_members`` of each output).
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np

from .parameters import PARAMETER_NAMES, bound_outside_range, did_you_mean

METHODS = ("saltelli", "morris", "latin")
DESIGN_ATTR = "sensitivity_design"


class DesignError(ValueError):
    pass


def _salib():
    try:
        import SALib  # noqa: F401
    except ImportError:  # pragma: no cover - depends on the environment
        raise DesignError('sensitivity designs need SALib: pip install "warpfric[sensitivity]"') from None


def parse_design(table: dict, check_names: bool = True) -> dict:
    """Validate a [design] table; return the design dict (JSON-serialisable)."""
    allowed = {"method", "n", "seed", "second_order", "levels", "parameters"}
    for key in table:
        if key not in allowed:
            raise DesignError(f"unknown key [design] {key}; accepted: {', '.join(sorted(allowed))}")
    for key, what in (("method", f"one of {', '.join(METHODS)}"), ("n", "the base sample size, an integer >= 1")):
        if key not in table:
            raise DesignError(f"[design] {key}: missing; expected {what}")
    method = table.get("method")
    if method not in METHODS:
        raise DesignError(f"[design] method = {method!r}; accepted: {', '.join(METHODS)}")
    for key, owner in (("second_order", "saltelli"), ("levels", "morris")):
        if key in table and method != owner:  # as an unused [fronts] threshold: said, not refused
            warnings.warn(f"[design] {key} applies to method = {owner!r} only: method = {method!r} does not read it",
                          stacklevel=3)
    n = table.get("n")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise DesignError(f"[design] n = {n!r}: expected an integer >= 1 (the base sample size)")
    if method == "saltelli" and n & (n - 1):
        raise DesignError(f"[design] n = {n}: the Saltelli (Sobol sequence) base size must be a power of two, "
                          f"e.g. {2 ** round(math.log2(n))}")
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise DesignError(f"[design] seed = {seed!r}: expected an integer >= 0")
    second_order = table.get("second_order", True)
    if not isinstance(second_order, bool):
        raise DesignError(f"[design] second_order = {second_order!r}: expected true or false")
    levels = table.get("levels", 4)
    if isinstance(levels, bool) or not isinstance(levels, int) or levels < 2 or levels % 2:
        raise DesignError(f"[design] levels = {levels!r}: expected an even integer >= 2 (Morris grid levels)")
    params = table.get("parameters")
    if not isinstance(params, dict) or len(params) < 2:
        raise DesignError("[design.parameters]: give at least two parameters as name = {low = ..., high = ...}")
    names, bounds, scales = [], [], []
    for name, spec in params.items():
        where = f"[design.parameters] {name}"
        if check_names and name not in PARAMETER_NAMES:
            raise DesignError(f"unknown parameter {where}; accepted: {', '.join(PARAMETER_NAMES)}")
        if not isinstance(spec, dict) or set(spec) - {"low", "high", "scale"} or not {"low", "high"} <= set(spec):
            raise DesignError(f"{where} = {spec!r}: expected {{low = ..., high = ..., scale = 'linear' | 'log'}}")
        low, high = spec["low"], spec["high"]
        for v in (low, high):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise DesignError(f"{where}: bounds must be finite numbers, got {v!r}")
        if not low < high:
            raise DesignError(f"{where}: low = {low!r} must be below high = {high!r}")
        scale = spec.get("scale", "linear")
        if scale not in ("linear", "log"):
            raise DesignError(f"{where}.scale = {scale!r}; accepted: linear, log")
        if scale == "log" and low <= 0:
            raise DesignError(f"{where}: scale = 'log' needs low > 0, got {low!r}")
        if check_names:  # a bound outside the parameter's range draws values outside it (as [sample] says)
            for key, value in (("low", low), ("high", high)):
                # latin and saltelli draw below high; morris levels take high itself
                problem = bound_outside_range(name, key, value, takes_high=method == "morris")
                if problem is not None:
                    raise DesignError(f"{where}.{problem}")
        names.append(name)
        bounds.append([float(low), float(high)])
        scales.append(scale)
    return dict(method=method, n=n, seed=seed, second_order=second_order, levels=levels,
                names=names, bounds=bounds, scales=scales)


def _problem(design: dict) -> dict:
    bounds = [[math.log(lo), math.log(hi)] if sc == "log" else [lo, hi]
              for (lo, hi), sc in zip(design["bounds"], design["scales"])]
    return {"num_vars": len(design["names"]), "names": list(design["names"]), "bounds": bounds}


def generate(design: dict) -> dict:
    """The design's rows as {name: (rows,) float64} in SI units (log-scaled parameters exponentiated).
    A Ctrl-C during the sampling is held until it ends, then raised (KeyboardInterrupt): scipy's
    compiled Sobol set-up, which SALib's Saltelli sampling calls, swallows one raised inside it
    ("Exception ignored in: 'scipy.stats._sobol._initialize_v'"), and the sweep went on."""
    _salib()
    from SALib.sample import latin, morris, sobol

    from .io import sigint_held

    problem = _problem(design)
    with sigint_held() as interrupted:
        if design["method"] == "saltelli":
            X = sobol.sample(problem, design["n"], calc_second_order=design["second_order"], seed=design["seed"])
        elif design["method"] == "morris":
            X = morris.sample(problem, design["n"], num_levels=design["levels"], seed=design["seed"])
        else:
            X = latin.sample(problem, design["n"], seed=design["seed"])
    if interrupted:
        raise KeyboardInterrupt
    out = {}
    for j, (name, scale) in enumerate(zip(design["names"], design["scales"])):
        out[name] = np.exp(X[:, j]) if scale == "log" else X[:, j].astype(np.float64)
    return out


def design_rows(design: dict) -> int:
    d = len(design["names"])
    if design["method"] == "saltelli":
        return design["n"] * (2 * d + 2 if design["second_order"] else d + 2)
    if design["method"] == "morris":
        return design["n"] * (d + 1)
    return design["n"]


def check_outputs(ds, outputs) -> None:
    """ValueError (one line) unless every name of ``outputs`` is once a per-member result of ``ds``:
    not an input parameter (nor one of its design's names), not a flag variable."""
    repeated = sorted({o for o in outputs if list(outputs).count(o) > 1})
    if repeated:
        raise ValueError(f"output {repeated[0]!r} is given more than once; give each output once")
    design_names = json.loads(ds.attrs[DESIGN_ATTR])["names"] if DESIGN_ATTR in ds.attrs else ()
    inputs = set(PARAMETER_NAMES) | set(design_names)

    def is_flag(v):  # status, the edge codes: categories, not quantities
        return v == "status" or "flag_meanings" in ds[v].attrs

    def is_output(v):  # a per-member result: not an input parameter, not a flag
        return ds[v].dims == ("member",) and v not in inputs and not is_flag(v)

    for out in outputs:
        if out not in ds or not is_output(out):
            candidates = [v for v in ds.data_vars if is_output(v)]
            what = ("an input parameter" if out in inputs else "a flag variable" if out in ds and is_flag(out)
                    else "not a per-member variable of the file")
            hint = did_you_mean(out, candidates) if out not in ds else ""  # a misspelt name: the closest output
            raise ValueError(f"output {out!r} is {what}{hint}; available: {', '.join(candidates)}")


def design_outputs(ds, outputs=("mu_s",), on_failure: str = "refuse", log: bool = False):
    """What analyse checks before it computes (ValueError, one line, for each fault): the file's
    design, its rows against the members, each output's name, the members that failed or lack it
    (refused, or with on_failure='fill-mean' replaced by the mean of the others) and its variance.
    Returns (design, {output: the values analysed, (member,) float64}, {output: members filled})."""
    if DESIGN_ATTR not in ds.attrs:
        raise ValueError(f"the file has no sensitivity design (global attribute {DESIGN_ATTR!r}); "
                         "run a sweep with a [design] table")
    design = json.loads(ds.attrs[DESIGN_ATTR])
    if design["method"] == "latin":
        raise ValueError("a Latin hypercube design has no indices of its own; use method = 'saltelli' or 'morris'")
    if on_failure not in ("refuse", "fill-mean"):
        raise ValueError(f"on_failure = {on_failure!r}; accepted: refuse, fill-mean")
    rows = design_rows(design)
    if ds.sizes["member"] != rows:
        raise ValueError(f"the file has {ds.sizes['member']} members but the design has {rows} rows")
    status = ds["status"].values if "status" in ds else np.zeros(rows, dtype=int)
    check_outputs(ds, outputs)
    values, filled = {}, {}
    for out in outputs:
        Y = ds[out].values.astype(np.float64)
        if log:
            with np.errstate(divide="ignore", invalid="ignore"):
                Y = np.where(Y > 0, np.log(Y), np.nan)
        not_positive = log & np.isfinite(ds[out].values) & (status == 0) & ~np.isfinite(Y)  # values <= 0 under log
        bad = (status != 0) | ~np.isfinite(Y)
        if bad.all():  # nothing to fill from: the mean of no member is NaN, and SALib gave zeros for it
            raise ValueError(f"output {out!r}: all {rows} members failed or lack it; the design needs the output "
                             "in its rows (--on-failure fill-mean fills from the members that have it)")
        if bad.any():
            if on_failure == "refuse":
                idx = np.flatnonzero(bad)
                why = (f"; {int(not_positive.sum())} of them ok with a value <= 0, which the log (--log) cannot take"
                       if not_positive.any() else "")
                lacking = int(((status == 0) & ~np.isfinite(ds[out].values)).sum())
                pointer = (" (front_count's indices say what decides whether a second front exists)"
                           if out == "v_second" else "")
                caveat = (f"; {lacking} of them ended ok without it, so the mean stands for something that did not "
                          f"happen there and the indices mix whether it exists with its value{pointer}"
                          if lacking else "")
                raise ValueError(f"output {out!r}: {bad.sum()} of {rows} members failed or lack it (members "
                                 f"{', '.join(map(str, idx[:10]))}{' ...' if idx.size > 10 else ''}{why}); the design "
                                 f"needs every row: pass --on-failure fill-mean to replace them by the mean{caveat}")
            Y = np.where(bad, Y[~bad].mean(), Y)
        if np.all(Y == Y[0]):  # no variance: every index would be 0/0
            filled_text = f" once the {bad.sum()} of {rows} that failed are filled with the mean" if bad.any() else ""
            raise ValueError(f"output {out!r} is the same in every member{filled_text}: its variance is 0 and its "
                             "indices are undefined")
        values[out], filled[out] = Y, int(bad.sum())
    return design, values, filled


def analyse(ds, outputs=("mu_s",), on_failure: str = "refuse", num_resamples: int = 100, conf_level: float = 0.95,
            log: bool = False):
    """Sensitivity indices of ``outputs`` (variables along member) for the design stored in ``ds``.

    Returns an xarray Dataset: for Saltelli designs S1, S1_conf, ST, ST_conf (output, parameter)
    and S2, S2_conf (output, parameter, parameter_2) when second order; for Morris mu_star,
    mu_star_conf, sigma, mu (output, parameter); Latin designs have no index of their own and are
    refused. on_failure: 'refuse' (default) raises ValueError naming the members that failed or
    lack the output; 'fill-mean' replaces their values by the mean of the others (counted in the
    result's ``filled_members``). log: analyse the natural log of each output (for heavy-tailed
    outputs such as front speeds; a non-positive value counts as lacking)."""
    import xarray as xr

    design, values, filled = design_outputs(ds, outputs, on_failure, log)
    _salib()
    from SALib.analyze import morris as morris_analyze
    from SALib.analyze import sobol as sobol_analyze

    rows = design_rows(design)
    problem = _problem(design)
    X = np.column_stack([np.log(ds[n].values) if sc == "log" else ds[n].values
                         for n, sc in zip(design["names"], design["scales"])])
    names = design["names"]
    d = len(names)
    result = {}
    for out in outputs:
        Y = values[out]
        if design["method"] == "saltelli":
            r = sobol_analyze.analyze(problem, Y, calc_second_order=design["second_order"],
                                      num_resamples=num_resamples, conf_level=conf_level, seed=design["seed"])
        else:
            r = morris_analyze.analyze(problem, X, Y, num_resamples=num_resamples, conf_level=conf_level,
                                       num_levels=design["levels"], seed=design["seed"])
        result[out] = r
    data = {}
    keys = ("S1", "S1_conf", "ST", "ST_conf") if design["method"] == "saltelli" else ("mu_star", "mu_star_conf", "sigma", "mu")
    long = {"S1": "first-order Sobol index", "S1_conf": "confidence half-width of S1", "ST": "total Sobol index",
            "ST_conf": "confidence half-width of ST", "mu_star": "Morris mean absolute elementary effect",
            "mu_star_conf": "confidence half-width of mu_star", "sigma": "Morris standard deviation of the elementary effects",
            "mu": "Morris mean elementary effect"}
    for k in keys:
        data[k] = (("output", "parameter"), np.array([np.asarray(result[o][k], dtype=float) for o in outputs]),
                   {"long_name": long[k], "units": "1" if k.startswith("S") else "output units per unit of the parameter (log for log-scaled)"})
    if design["method"] == "saltelli" and design["second_order"]:
        for k in ("S2", "S2_conf"):
            data[k] = (("output", "parameter", "parameter_2"),
                       np.array([np.asarray(result[o][k], dtype=float).reshape(d, d) for o in outputs]),
                       {"long_name": ("second-order Sobol index" if k == "S2" else "confidence half-width of S2"),
                        "units": "1"})
    data["filled_members"] = (("output",), np.array([filled[o] for o in outputs], dtype=np.int32),
                              {"long_name": f"members replaced by the mean ({on_failure})", "units": "1"})
    res = xr.Dataset(data, coords={
        "output": ("output", list(outputs), {"long_name": "ensemble output analysed"}),
        "parameter": ("parameter", names, {"long_name": "design parameter"}),
        "parameter_2": ("parameter_2", names, {"long_name": "second design parameter of a pair (S2)"})})
    if design["method"] == "saltelli":
        _warn_unresolved(res, design["n"])
    res.attrs.update({"Conventions": "CF-1.8",
                      "title": f"{design['method']} sensitivity of {', '.join(outputs)} to {', '.join(names)}",
                      "source": "warpfric sensitivity (SALib)",
                      DESIGN_ATTR: ds.attrs[DESIGN_ATTR], "conf_level": conf_level, "num_resamples": num_resamples,
                      "on_failure": on_failure, "members": rows, "output_transform": "log" if log else "none"})
    return res


# a Sobol index whose confidence half-width exceeds this is not resolved (the indices lie in [0, 1])
UNRESOLVED_HALF_WIDTH = 0.1


def _warn_unresolved(res, n: int) -> None:
    """One warning naming each output whose first-order or total indices have a confidence half-width
    above UNRESOLVED_HALF_WIDTH: at a small base size n the estimates can leave [0, 1] or give
    S1 > ST, and read as results. The half-width falls about as 1/sqrt(n)."""
    import warnings

    widest = np.maximum(res.S1_conf.max("parameter"), res.ST_conf.max("parameter")).values
    loose = [(str(o), float(w)) for o, w in zip(res.output.values, widest) if not w <= UNRESOLVED_HALF_WIDTH]
    if loose:
        which = ", ".join(f"{o!r} +- {w:.2g}" for o, w in loose)
        factor = max(w for _, w in loose) / UNRESOLVED_HALF_WIDTH
        needed = 2 ** math.ceil(math.log2(n * factor ** 2))  # Saltelli's base size is a power of two
        warnings.warn(f"Sobol indices not resolved at base size n = {n}: confidence half-widths up to {which} "
                      f"(above {UNRESOLVED_HALF_WIDTH:g}); the half-width falls about as 1/sqrt(n): n = {needed} "
                      "at least (a power of two; the estimate of a small design is itself rough)", stacklevel=3)


BAR_PANELS_PER_ROW = 3  # panels of bar_figure side by side (each up to 7 inches wide)


def bar_plot(res, path) -> None:
    """The indices of ``res`` (analyse's Dataset) as bars (bar_figure), written to ``path``."""
    bar_figure(res).savefig(path, dpi=110, bbox_inches="tight")


def bar_figure(res):
    """One panel per output: S1 and ST (Sobol) or mu* and sigma (Morris) per parameter, with their
    confidence intervals as error bars; one legend, outside the panels, naming the intervals' level."""
    from .plots import _subplots  # a Figure without pyplot: a notebook's display stays as it was

    outputs = list(res.output.values)
    names = [str(name) for name in res.parameter.values]
    width = min(max(4.5, 0.6 * len(names) + 1.5), 14.0)  # inches a panel
    # at most BAR_PANELS_PER_ROW panels a row (20 parameters x 6 outputs made one row of ~9,000 px)
    columns = min(len(outputs), max(1, BAR_PANELS_PER_ROW if width <= 7 else 1))
    rows = -(-len(outputs) // columns)
    fig, grid = _subplots(rows, columns, figsize=(width * columns, 3.8 * rows), squeeze=False)
    panels = list(grid.flat)
    for ax in panels[len(outputs):]:
        ax.set_visible(False)
    x = np.arange(res.sizes["parameter"])
    # names upright where the longest fits its bar pair's width (~0.065 in a character at 8 pt),
    # else slanted and smaller
    upright = max(len(name) for name in names) * 0.065 <= 0.85 * width / len(names)
    for ax, out in zip(panels, outputs):
        r = res.sel(output=out)
        if "S1" in res:
            ax.bar(x - 0.2, r.S1, 0.4, yerr=r.S1_conf, capsize=2, label="S1 (first order)")
            ax.bar(x + 0.2, r.ST, 0.4, yerr=r.ST_conf, capsize=2, label="ST (total)")
            ax.set_ylabel("Sobol index")
        else:
            ax.bar(x - 0.2, r.mu_star, 0.4, yerr=r.mu_star_conf, capsize=2, label="mu* (mean |elementary effect|)")
            ax.bar(x + 0.2, r.sigma, 0.4, label="sigma (their spread)")
        ax.set_xticks(x, names, rotation=0 if upright else 45, ha="center" if upright else "right",
                      fontsize=8 if upright else 7)
        ax.set_title(("log " if res.attrs.get("output_transform") == "log" else "") + str(out), fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    # one legend for all panels, outside on the right (inside, it covered bars), saying what the
    # error bars are: SALib's confidence intervals of the indices
    level = res.attrs.get("conf_level", 0.95)
    handles, labels = panels[0].get_legend_handles_labels()
    grid[0][-1].legend(handles, labels, fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False,
                       title=f"error bars: {float(level):.0%} confidence\n(SALib's bootstrap)", title_fontsize=7)
    fig.tight_layout()
    return fig
