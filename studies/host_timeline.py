"""Where one member's wall time goes on the host: a timeline of warpfric.simulate (ms from its
call) and the median wall time of repeated runs (docs/performance.md, "One member's host time").

    python studies/host_timeline.py [--device cuda:0] [--nodes N] [--relaxation-gate none]
                                    [--runs 15] [--fronts] [--default-scene]

The member is that of studies/baseline_diffrax.py (the peers' comparison), rtol 1e-5, t = 0..20.6 s;
with --default-scene the default scene of `warpfric run` (the automatic end, the default rtol). Fronts
off, or with --fronts the default front event (contact). The timeline marks the engine's stages by
wrapping them (kernel lookup, module load, allocation, the state read-back buffer, initial states,
each launch, each read-back wait, the Dataset); the time between the first launch and the last wait
is the kernel's, the rest is host time on the critical path. A warm-up run compiles first.
"""

import argparse
import sys
import time

import numpy as np
import warp as wp

import warpfric as wf
from warpfric.device import init_warp
import warpfric.engine as engine
import warpfric.kernels.integrator as integrator
import warpfric.kernels.types as kernel_types

simulate_module = sys.modules["warpfric.simulate"]  # warpfric.simulate is also the function
sys.path.insert(0, "studies")
from baseline_diffrax import members  # noqa: E402

marks: list = []


def mark(name: str) -> None:
    marks.append((name, time.perf_counter()))


def wrap(owner, name: str, label: str, after: bool = True) -> None:
    """Mark ``label>`` before and ``label<`` after each call of owner.name."""
    original = getattr(owner, name)

    def wrapped(*args, **kwargs):
        mark(label + ">")
        result = original(*args, **kwargs)
        if after:
            mark(label + "<")
        return result

    setattr(owner, name, wrapped)


def instrument() -> None:
    wrap(engine, "run", "engine")
    wrap(integrator, "get_integrator", "kernel lookup")
    wrap(wp, "load_module", "load module")
    wrap(kernel_types, "allocate", "allocate")
    wrap(engine.StateSnapshots, "__init__", "read-back buffer")
    wrap(engine, "initial_states", "initial states")
    wrap(wp, "launch_tiled", "launch", after=False)
    wrap(wp, "launch", "launch", after=False)
    wrap(engine.StateSnapshots, "wait", "wait")
    wrap(simulate_module, "_to_dataset", "dataset")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda:0" if init_warp().get_cuda_device_count() else "cpu")  # quietly
    ap.add_argument("--nodes", type=int, default=None, help="default: 40, or the Solver's with --default-scene")
    ap.add_argument("--relaxation-gate", default="none", choices=["none", "stress", "velocity"])
    ap.add_argument("--runs", type=int, default=15)
    ap.add_argument("--fronts", action="store_true", help="the front outputs (simulate's default, the contact front)")
    ap.add_argument("--default-scene", action="store_true", help="the default scene of `warpfric run` (e = 0)")
    args = ap.parse_args(argv)
    fronts = wf.Fronts() if args.fronts else None
    model = wf.Model(relaxation_gate=args.relaxation_gate)
    if args.default_scene:
        solver = wf.Solver() if args.nodes is None else wf.Solver(nodes=args.nodes)
        scene = wf.Parameters()
        member = {"eccentricity": [0.0]}
    else:
        solver = wf.Solver(nodes=args.nodes or 40, rtol=1e-5, max_steps=10**6)
        scene = wf.Parameters(end_time=20.6)
        member = members(1)

    def one():
        return wf.simulate(member, scene=scene, model=model, solver=solver, fronts=fronts, device=args.device,
                           progress=False)

    one()  # compile
    walls = []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        ds = one()
        walls.append(time.perf_counter() - t0)
    instrument()
    marks.clear()
    mark("simulate>")
    one()
    mark("simulate<")
    t0 = marks[0][1]
    print("timeline (ms):", " ".join(f"{name} {(t - t0) * 1e3:.2f}" for name, t in marks))
    label = f"{args.relaxation_gate}{' default scene' if args.default_scene else ''}{' fronts' if args.fronts else ''}"
    print(f"{args.device} N = {solver.nodes} {label}: wall median {np.median(walls) * 1e3:.2f} ms "
          f"(min {min(walls) * 1e3:.2f}, max {max(walls) * 1e3:.2f}, {args.runs} runs), "
          f"{int(ds.steps_accepted.values[0] + ds.steps_rejected.values[0])} attempts, mu_s {ds.mu_s.values[0]:.9f}")


if __name__ == "__main__":
    main()
