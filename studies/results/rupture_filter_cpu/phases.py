"""Cumulative counts at chosen end times (members = end_time), inviscid scene, N given; stress gate default law.
usage: phases.py N e F [damping] [gate]"""
import sys, time, warnings
import numpy as np
import warpfric as wf
N = int(sys.argv[1]); e = float(sys.argv[2]); F = float(sys.argv[3])
damping = float(sys.argv[4]) if len(sys.argv) > 4 else 0.0
gate = sys.argv[5] if len(sys.argv) > 5 else "stress"
ends = [10.0, 19.9, 20.0 + 1e-9, 20.1, 20.15, 20.2, 20.25, 20.3, 20.4, 20.6]
# end times before the disc start (20 s): the disc starts right there instead (rest_until = t), which
# leaves the history up to t unchanged; end = t + 1e-9
rest = [min(t, 20.0) for t in ends]
ends = [t + 1e-9 if t < 20.0 else t for t in ends]
keys = ["steps_accepted", "steps_rejected", "rejected_error_test", "rejected_newton", "rejected_switch",
        "missed_predictions", "gate_switches", "unlocated_switches", "newton_iterations"]
t0 = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    ds = wf.simulate({"eccentricity": [e], "normal_force": [F], "viscous_coefficient": [0.0], "end_time": ends, "rest_until": rest},
                     scene=wf.Parameters(damping=damping),
                     model=wf.Model(relaxation_gate=gate),
                     solver=wf.Solver(nodes=N, rtol=1e-5, max_steps=10**6, stall_factor=float("inf")),
                     fronts=wf.Fronts(event="contact") if gate == "stress" else None, device="cpu", progress=False, workers=1)
print(f"N={N} e={e} F={F} damping={damping} gate={gate} wall {time.perf_counter()-t0:.1f}s")
print(f"{'end':>10} {'status':>6} " + " ".join(f"{k[:10]:>10}" for k in keys) + f" {'mu_s':>12}")
prev = None
for m in range(ds.sizes["member"]):
    row = [int(ds[k].values[m]) for k in keys]
    print(f"{float(ds.final_time[m]):10.5f} {int(ds.status[m]):6d} " + " ".join(f"{v:10d}" for v in row) + f" {float(ds.mu_s[m]):12.9f}")
print("increments per phase:")
prevrow = [0]*len(keys); pt = 0.0
for m in range(ds.sizes["member"]):
    row = [int(ds[k].values[m]) for k in keys]
    print(f"{pt:8.3f}-{float(ds.final_time[m]):8.3f} " + " ".join(f"{a-b:10d}" for a, b in zip(row, prevrow)))
    prevrow = row; pt = float(ds.final_time[m])
