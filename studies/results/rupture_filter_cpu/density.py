"""Accepted/rejected steps per 10-ms interval (members = end times) of one inviscid scene: mean step size per interval.
usage: density.py N e F [damping] [gate] [rtol]"""
import sys, time, warnings, numpy as np, warpfric as wf
N = int(sys.argv[1]); e = float(sys.argv[2]); F = float(sys.argv[3])
damping = float(sys.argv[4]) if len(sys.argv) > 4 else 0.0
gate = sys.argv[5] if len(sys.argv) > 5 else "stress"
rtol = float(sys.argv[6]) if len(sys.argv) > 6 else 1e-5
ends = np.round(np.arange(20.10, float(__import__("os").environ.get("WF_END", "20.3")) + 1e-4, 0.01), 4)
t0 = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    ds = wf.simulate({"eccentricity": [e], "normal_force": [F], "viscous_coefficient": [0.0], "end_time": ends},
                     scene=wf.Parameters(damping=damping), model=wf.Model(relaxation_gate=gate),
                     solver=wf.Solver(nodes=N, rtol=rtol, max_steps=10**6, stall_factor=float("inf")),
                     fronts=wf.Fronts(event="contact") if gate == "stress" else None, device="cpu", progress=False, workers=2)
print(f"N={N} e={e} F={F} damping={damping:g} gate={gate} rtol={rtol:g}  wall {time.perf_counter()-t0:.1f}s")
acc = ds.steps_accepted.values.astype(int); rej = ds.steps_rejected.values.astype(int)
sw = ds.gate_switches.values.astype(int)
print(f"{'interval':>17} {'acc':>7} {'rej':>6} {'switches':>8} {'mean h (s)':>11}")
for i in range(1, len(ends)):
    da = acc[i] - acc[i - 1]
    print(f"{ends[i-1]:8.2f}-{ends[i]:8.2f} {da:7d} {rej[i]-rej[i-1]:6d} {sw[i]-sw[i-1]:8d} {0.01/max(da,1):11.2e}")
print("at 20.30:", acc[-1], rej[-1], "mu_s(20.3 run)", float(ds.mu_s.values[-1]))
