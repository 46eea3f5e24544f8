"""Beyond the paper: how the eccentricity effect on mu_s depends on the stiffness ratio Lambda.

    python studies/stiffness_ratio.py [--nodes 200] [--lambdas 25] [--eccentricities 13] [--device cuda:0]
                                      [--out FILE.json]  (default ./stiffness_ratio_DEVICE.json, DEVICE without
                                      its colon; the committed results: studies/results/stiffness_ratio_h100.json,
                                      made with --out)

Lambda = (interface stiffness x real-contact fraction) / (pad shear stiffness)
       = (mu0/h) * A * H / (2 G),   A = (sigma_n / sigma_H) * (1 + b ln(1 + phi/phi0)),
evaluated at the mean pressure sigma_n = F / (L p) with the contact age at the end of the rest
(phi = rest_until: the contacts aged from the load ramp to the disc start). At the paper's 42 kPa it
is about 0.1; Ben-David & Fineberg's PMMA blocks (MPa pressures, GPa interface stiffness per um)
sit at Lambda ~ 50-150. Lambda is swept here through the normal force (the pressure, hence A), all
else at the paper's values: F = 1e3 .. 1e6 N gives 42 kPa .. 42 MPa (below sigma_H = 540 MPa).

For each Lambda, e = -0.3 .. 0.3: mu_s(e), its relative slope (1/mu_s(0)) d mu_s/d e (least
squares over the members that ended ok), the relative spread, the contact front's nucleation edge
and precursor length at e = 0, its number of fronts and the first and second fronts' speeds. Writes the JSON (every member's numbers) and a PNG beside it.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import warpfric as wf


def stiffness_ratio(p: wf.Parameters, normal_force) -> np.ndarray:
    """Lambda of the pad at normal force(s) F (N), other parameters from ``p``."""
    sigma = np.asarray(normal_force, dtype=np.float64) / (p.length * p.depth)
    area = sigma / p.hardness * (1 + p.aging_coefficient * np.log(1 + p.rest_until / p.aging_time))
    return p.interface_stiffness * area * p.height / (2 * p.shear_modulus)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--lambdas", type=int, default=25, help="number of Lambda values, log-spaced over 0.1..100")
    ap.add_argument("--eccentricities", type=int, default=13, help="number of e values over -0.3..0.3 (odd: e = 0 included)")
    ap.add_argument("--rtol", type=float, default=1e-5)
    ap.add_argument("--device", default=None)
    ap.add_argument("--out", default=None, help="result file (default ./stiffness_ratio_DEVICE.json, DEVICE without its colon: "
                    "stiffness_ratio_cuda0.json; a PNG is written beside it; the committed results: "
                    "studies/results/stiffness_ratio_h100.json, made with --out)")
    args = ap.parse_args(argv)
    if args.out:  # its folder before the simulation, not after it
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    scene = wf.Parameters()
    unit = float(stiffness_ratio(scene, 1.0))  # Lambda per newton
    lambdas = np.logspace(-1, 2, args.lambdas)
    ecc = np.linspace(-0.3, 0.3, args.eccentricities)
    force = lambdas / unit
    members = {"normal_force": np.repeat(force, ecc.size), "eccentricity": np.tile(ecc, lambdas.size)}
    t0 = time.perf_counter()
    ds = wf.simulate(members, scene=scene, solver=wf.Solver(nodes=args.nodes, rtol=args.rtol),
                     fronts=wf.Fronts(event=("contact", "strength")), device=args.device, progress=True)
    wall = time.perf_counter() - t0
    shape = (lambdas.size, ecc.size)
    mu = ds.mu_s.values.reshape(shape)
    ok = (ds.status.values == 0).reshape(shape)
    mid = ecc.size // 2
    rows = []
    for k, lam in enumerate(lambdas):
        good = ok[k] & np.isfinite(mu[k])
        slope = spread = np.nan
        if good.sum() >= 3 and np.isfinite(mu[k, mid]):
            slope = float(np.polyfit(ecc[good], mu[k, good], 1)[0] / mu[k, mid])
            spread = float(np.ptp(mu[k, good]) / mu[k, mid])
        at = k * ecc.size + mid
        edge = int(ds.nucleation_edge.values[at])
        rows.append(dict(
            stiffness_ratio=float(lam), normal_force=float(force[k]), pressure=float(force[k] / (scene.length * scene.depth)),
            mu_s=[None if not np.isfinite(x) else float(x) for x in mu[k]], members_ok=int(good.sum()),
            relative_slope=slope, relative_spread=spread,
            nucleation_edge_e0={-3: "unknown", -2: "none", -1: "left", 0: "interior", 1: "right"}[edge],
            precursor_length_e0=float(ds.precursor_front_length.values[at]),
            v_main_e0=float(ds.v_main.values[at]),
            front_count_e0=float(ds.front_count.values[at]), v_first_e0=float(ds.v_first.values[at]),
            v_second_e0=float(ds.v_second.values[at]),
            lift_off=[int(x) for x in ds.lift_off.values.reshape(shape)[k]],
            status=[int(x) for x in ds.status.values.reshape(shape)[k]],
        ))
    device = ds.attrs["device"]
    out = Path(args.out or f"stiffness_ratio_{device.replace(':', '')}.json")
    meta = dict(command="python studies/stiffness_ratio.py " + " ".join(argv if argv is not None else []),
                device=device, nodes=args.nodes, rtol=args.rtol, eccentricities=ecc.tolist(), wall_s=wall,
                members=int(ds.sizes["member"]), lambda_per_newton=unit)
    out.write_text(json.dumps(dict(meta=meta, rows=rows), indent=1, default=float))
    plot(rows, ecc, out.with_suffix(".png"))
    print(f"{'Lambda':>8} {'F (N)':>10} {'ok':>3} {'dmu/de/mu':>10} {'spread':>8} {'edge e=0':>9} {'precursor mm':>12} "
          f"{'fronts':>6} {'v_first':>8} {'v_second':>8}")
    for r in rows:
        print(f"{r['stiffness_ratio']:8.3g} {r['normal_force']:10.4g} {r['members_ok']:3d} {r['relative_slope']:10.3e} "
              f"{r['relative_spread']:8.2e} {r['nucleation_edge_e0']:>9} {1e3 * r['precursor_length_e0']:12.1f} "
              f"{r['front_count_e0']:6.0f} {r['v_first_e0']:8.3g} {r['v_second_e0']:8.3g}")
    print(f"{ds.sizes['member']} members, N = {args.nodes}, {device}: {wall:.1f} s -> {out}")


def plot(rows, ecc, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    lam = np.array([r["stiffness_ratio"] for r in rows])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    norm = LogNorm(lam.min(), lam.max())
    cmap = plt.get_cmap("viridis")
    for r in rows:
        mu = np.array([np.nan if v is None else v for v in r["mu_s"]])
        axes[0].plot(ecc, 100 * (mu / mu[len(ecc) // 2] - 1), color=cmap(norm(r["stiffness_ratio"])), lw=1)
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=axes[0], label="stiffness ratio $\\Lambda$")
    axes[0].set(xlabel="eccentricity 2e/L", ylabel="mu_s / mu_s(e=0) - 1 (%)", title="eccentricity effect")
    slope = np.array([r["relative_slope"] for r in rows])
    axes[1].semilogx(lam[slope > 0], slope[slope > 0], "o", color="C3", label="> 0 (higher towards e > 0)")
    axes[1].semilogx(lam[slope <= 0], -slope[slope <= 0], "s", color="C0", label="< 0 (higher towards e < 0)")
    axes[1].set_yscale("log")
    axes[1].set(xlabel="stiffness ratio $\\Lambda$", ylabel="|d mu_s/d e| / mu_s(0)", title="size and sign of the effect")
    axes[1].legend()
    axes[1].axvspan(0.05, 0.2, color="0.9", zorder=0)
    axes[1].text(0.1, axes[1].get_ylim()[1], " paper", va="top", fontsize=8)
    axes[1].axvspan(50, 150, color="0.9", zorder=0)
    axes[1].text(60, axes[1].get_ylim()[1], " PMMA", va="top", fontsize=8)
    prec = np.array([1e3 * r["precursor_length_e0"] for r in rows])
    edges = [r["nucleation_edge_e0"] for r in rows]
    for name, marker in (("left", "<"), ("right", ">"), ("interior", "o")):
        sel = np.array([e == name for e in edges])
        if sel.any():
            axes[2].semilogx(lam[sel], np.nan_to_num(prec[sel]), marker, label=f"nucleation: {name} edge" if name != "interior" else "nucleation: interior")
    axes[2].set(xlabel="stiffness ratio $\\Lambda$", ylabel="precursor length at e = 0 (mm; 0: none)",
                title="contact front at e = 0")
    axes[2].legend()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
