"""Mean attempts and mu_s of the 9 inviscid scenes to 20.6 s (rtol 1e-5, contact front), for N given.
usage: totals.py N [damping] [gate] [rtol]   (the package imported is whatever PYTHONPATH gives; printed)"""
import os, sys, time, warnings, numpy as np, warpfric as wf
N = int(sys.argv[1]); damping = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
gate = sys.argv[3] if len(sys.argv) > 3 else "stress"; rtol = float(sys.argv[4]) if len(sys.argv) > 4 else 1e-5
E, F = np.meshgrid([-0.2, 0.0, 0.2], [500.0, 1000.0, 5000.0], indexing="ij")
t0 = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    ds = wf.simulate({"eccentricity": E.ravel(), "normal_force": F.ravel(), "viscous_coefficient": 0.0},
                     scene=wf.Parameters(end_time=20.6, damping=damping), model=wf.Model(relaxation_gate=gate),
                     solver=wf.Solver(nodes=N, rtol=rtol, max_steps=10**6, stall_factor=float("inf")),
                     fronts=wf.Fronts(event="contact") if gate == "stress" else None, device="cpu", progress=False, workers=2)
att = (ds.steps_accepted + ds.steps_rejected).values
print(f"pkg={os.path.dirname(wf.__file__)} tag={os.environ.get('WF_TAG','main')} N={N} damping={damping:g} "
      f"gate={gate} rtol={rtol:g}: mean attempts {att.mean():.0f} (min {att.min()}, max {att.max()}), "
      f"status {sorted(set(ds.status.values.tolist()))}, wall {time.perf_counter()-t0:.1f}s")
print("  mu_s:", " ".join(f"{v:.9f}" for v in ds.mu_s.values))
np.save(f"/tmp/diag/mu_N{N}_d{damping:g}_{gate}_r{rtol:g}_{os.environ.get('WF_TAG','main')}.npy", ds.mu_s.values)
import warpfric.kernels.esdirk as _E
assert ("/tmp/diag/" in _E.__file__) == (os.environ.get("WF_TAG", "main") != "main"), _E.__file__
