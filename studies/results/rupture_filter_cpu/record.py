"""Record the pad velocity of the inviscid scene (e=0, F=1000) at N given, over windows; save npz.
usage: record.py N t0 t1 count [damping] [gate] [tag]"""
import sys, warnings, numpy as np, warpfric as wf
N = int(sys.argv[1]); t0, t1 = float(sys.argv[2]), float(sys.argv[3]); count = int(sys.argv[4])
damping = float(sys.argv[5]) if len(sys.argv) > 5 else 0.0
gate = sys.argv[6] if len(sys.argv) > 6 else "stress"
tag = sys.argv[7] if len(sys.argv) > 7 else ""
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    ds = wf.simulate({"eccentricity": [0.0], "normal_force": [1000.0], "viscous_coefficient": [0.0]},
                     scene=wf.Parameters(end_time=20.6, damping=damping), model=wf.Model(relaxation_gate=gate),
                     solver=wf.Solver(nodes=N, rtol=float(__import__("os").environ.get("WF_RTOL", "1e-5")), max_steps=10**6, stall_factor=float("inf")),
                     fronts=wf.Fronts(event="contact") if gate == "stress" else None,
                     record=wf.Record.window(t0, t1, count), device="cpu", progress=False, workers=1)
v = ds.velocity_history.values[0]; s = ds.slip_rate_history.values[0]; tf = ds.friction_stress_history.values[0]
sn = ds.normal_stress_history.values[0]
out = f"/tmp/diag/rec_N{N}_{t0}_{t1}_{count}_d{damping:g}_{gate}{tag}.npz"
np.savez(out, t=ds.time.values, x=ds.x.values, v=v, s=s, tf=tf, sn=sn, mu=ds.friction_coefficient_history.values[0],
         yt=ds.yield_time.values[0] if "yield_time" in ds else np.nan,
         acc=int(ds.steps_accepted[0]), rej=int(ds.steps_rejected[0]), mu_s=float(ds.mu_s[0]))
print(out, int(ds.steps_accepted[0]), int(ds.steps_rejected[0]), float(ds.mu_s[0]))
