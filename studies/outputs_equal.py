"""Refactor guard: save every output of a fixed set of scenes, or compare against a saved set.

    python studies/outputs_equal.py save  FILE.npz [--device cpu] [--scenes cpu|team|gpu]
    python studies/outputs_equal.py compare FILE.npz [--device cpu] [--scenes cpu|team|gpu]

Scenes "cpu" (the default; N = 30, CPU-sized), each with the members e = 0, -0.2 (1000 N), 0.3
(300 N) and 0.6 (3000 N, lift-off): the default law with fronts and two recorded members, the
gate-less and the velocity-gate laws, float32 (gate-less), the model switches off (inertia, tilt,
poisson_coupling, viscous_friction), and the default law without fronts.

Scenes "team": the cooperative kernel (kernels/team.py) on the CPU, the members above at N = 30:
the default law with fronts in teams of 4 and 7 lanes (7 or 8 nodes a lane; 4 or 5), the
gate-less law in a team of 4.

Scenes "gpu" (with --device cuda:0), for what only a GPU runs, the blocked cooperative kernel and
its shared work array: the engine benchmark's members (studies/bench_engine.py ``members``), the
default law with the contact front, 1,100 at N = 200 (8 members a block on an H100, member stride
9), 1,000 at N = 300 (7 a block, stride 7: the largest shared array), 300 at N = 40 (3 a block,
stride 3) and the first member alone at N = 200 (stride 1), each in teams of min(32, N // 2) lanes
(the blocked kernel; for one member lanes=None would choose a team of several warps).

``compare`` prints the largest relative difference of each scene's outputs and exits 1 above
--rtol (default 1e-12; 0 asks for bit equality).
"""

import argparse
import os
import sys
import warnings

import numpy as np

import warpfric as wf

# velocity first: its outputs are the unprefixed ones of the releases before the contact front
FRONTS = wf.Fronts(event="velocity")
MEMBERS = {"eccentricity": [0.0, -0.2, 0.3, 0.6], "normal_force": [1000.0, 1000.0, 300.0, 3000.0]}


def scenes():
    rec = wf.Record.window(20.1, 20.4, 7, members=(0, 2))
    yield "stress", dict(model=wf.Model(), record=rec)
    yield "none", dict(model=wf.Model(relaxation_gate="none"))
    yield "velocity", dict(model=wf.Model(relaxation_gate="velocity"))
    yield "none_f32", dict(model=wf.Model(relaxation_gate="none"), dtype="float32")
    yield "switches_off", dict(model=wf.Model(inertia=False, tilt=False, poisson_coupling=False, viscous_friction=False))
    yield "stress_no_fronts", dict(model=wf.Model(), fronts=None)


def team_scenes():
    yield "team4_stress", dict(model=wf.Model(), lanes=4)
    yield "team7_stress", dict(model=wf.Model(), lanes=7)
    yield "team4_none", dict(model=wf.Model(relaxation_gate="none"), lanes=4)


def gpu_scenes():
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_engine import members

    for nodes, m in ((200, 1100), (300, 1000), (40, 300), (200, 1)):
        # lanes pinned: for one member lanes=None would take a team of several warps (96 lanes)
        yield f"n{nodes}_m{m}", dict(model=wf.Model(), members=members(m), nodes=nodes, fronts=wf.Fronts(),
                                     lanes=min(32, nodes // 2))


def run(device, which="cpu"):
    # the team scenes run the cooperative kernel on the CPU on purpose
    warnings.filterwarnings("ignore", message=r"Solver\(lanes=")
    out = {}
    for name, kw in {"cpu": scenes, "team": team_scenes, "gpu": gpu_scenes}[which]():
        solver = wf.Solver(nodes=kw.get("nodes", 30), dtype=kw.get("dtype", "float64"), lanes=kw.get("lanes"))
        ds = wf.simulate(kw.get("members", MEMBERS), model=kw["model"], solver=solver, fronts=kw.get("fronts", FRONTS),
                         record=kw.get("record"), device=device, progress=False)
        for var, arr in ds.data_vars.items():
            if np.issubdtype(arr.dtype, np.number):
                out[f"{name}/{var}"] = arr.values
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("action", choices=("save", "compare"))
    ap.add_argument("file")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--rtol", type=float, default=1e-12)
    ap.add_argument("--scenes", choices=("cpu", "team", "gpu"), default="cpu")
    args = ap.parse_args(argv)
    now = run(args.device, args.scenes)
    if args.action == "save":
        np.savez_compressed(args.file, **now)
        print(f"saved {len(now)} arrays to {args.file}")
        return 0
    ref = dict(np.load(args.file))
    worst = 0.0
    missing = sorted(set(ref) ^ set(now))
    for key in sorted(set(ref) & set(now)):
        a, b = ref[key].astype(np.float64), now[key].astype(np.float64)
        same_nan = np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(np.isinf(a), np.isinf(b))
        fin = np.isfinite(a) & np.isfinite(b)
        rel = float(np.max(np.abs(a[fin] - b[fin]) / np.maximum(np.abs(a[fin]), 1e-300), initial=0.0))
        if not same_nan:
            rel = np.inf
        if rel > args.rtol:
            print(f"  {key}: max relative difference {rel:.3g}")
        worst = max(worst, rel)
    print(f"{len(ref)} arrays compared; largest relative difference {worst:.3g}; missing/new: {missing or 'none'}")
    return 0 if worst <= args.rtol and not missing else 1


if __name__ == "__main__":
    sys.exit(main())
