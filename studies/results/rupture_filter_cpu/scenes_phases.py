"""The 9 inviscid scenes (e in -0.2,0,0.2 x F in 500,1000,5000 N), rtol 1e-5, stress gate, contact front:
counts summed over the scenes per phase (members = end times; an end before the disc start 20 s is run with
rest_until = that end, which leaves the history before it unchanged).
usage: scenes_phases.py N [damping] [gate]"""
import sys, time, warnings, numpy as np, warpfric as wf
N = int(sys.argv[1]); damping = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
gate = sys.argv[3] if len(sys.argv) > 3 else "stress"
ends = np.array([10.0, 19.9, 20.0, 20.1, 20.2, 20.3, 20.6])
endt = np.where(ends <= 20.0, ends + 1e-9, ends); rest = np.minimum(ends, 20.0)
E, F = np.meshgrid([-0.2, 0.0, 0.2], [500.0, 1000.0, 5000.0], indexing="ij")
E, F = E.ravel(), F.ravel()
members = {"eccentricity": np.repeat(E, len(ends)), "normal_force": np.repeat(F, len(ends)),
           "viscous_coefficient": 0.0, "end_time": np.tile(endt, 9), "rest_until": np.tile(rest, 9)}
keys = ["steps_accepted", "steps_rejected", "rejected_error_test", "rejected_newton", "rejected_switch",
        "missed_predictions", "gate_switches", "unlocated_switches", "newton_iterations"]
t0 = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    ds = wf.simulate(members, scene=wf.Parameters(damping=damping), model=wf.Model(relaxation_gate=gate),
                     solver=wf.Solver(nodes=N, rtol=1e-5, max_steps=10**6, stall_factor=float("inf")),
                     fronts=wf.Fronts(event="contact") if gate == "stress" else None, device="cpu", progress=False,
                     workers=2)
print(f"N={N} damping={damping:g} gate={gate} wall {time.perf_counter()-t0:.1f}s  (sums over the 9 scenes; mean per scene = /9)")
C = np.stack([ds[k].values.reshape(9, len(ends)).astype(float) for k in keys], axis=-1)  # scene, end, key
tot = C.sum(axis=0)
print(f"{'phase':>17} " + " ".join(f"{k.replace('steps_','').replace('rejected_','rej_')[:11]:>11}" for k in keys))
prev = np.zeros(len(keys)); pt = 0.0
for j, t in enumerate(ends):
    print(f"{pt:7.2f}-{t:7.2f} s " + " ".join(f"{v:11.0f}" for v in tot[j] - prev)); prev = tot[j]; pt = t
print(f"{'total':>17} " + " ".join(f"{v:11.0f}" for v in tot[-1]))
st = ds.status.values.reshape(9, len(ends)); acc = C[:, -1, 0] + C[:, -1, 1]
mu = ds.mu_s.values.reshape(9, len(ends))[:, -1]
print("per scene (end 20.6): e, F, attempts, status, mu_s, first-last gate opening (s)")
yt = ds.yield_time.values.reshape(9, len(ends), -1)[:, -1] if "yield_time" in ds else np.full((9, 1), np.nan)
for s in range(9):
    print(f"  {E[s]:+.1f} {F[s]:6.0f} {acc[s]:8.0f} {st[s,-1]} {mu[s]:.9f} {np.nanmin(yt[s]):.4f}-{np.nanmax(yt[s]):.4f}")
print(f"mean attempts per scene (end 20.6): {acc.mean():.0f}")
np.savez(f"/tmp/diag/scenes_N{N}_d{damping:g}_{gate}.npz", C=C, ends=ends, mu=mu, E=E, F=F)
