"""The 18 reference scenes (stress gate, contact front, end 20.6 s, rtol 1e-5) at N given, with whatever package
PYTHONPATH gives (tag in WF_TAG): largest relative mu_s error against studies/reference/reference_scenes_stress.nc
(N = 400, rtol 1e-8) and mean attempts, per group (viscous / inviscid). usage: ref18.py N [damping]"""
import os, sys, warnings, numpy as np
sys.path.insert(0, "/work/main/studies")
import warpfric as wf, warpfric.kernels.esdirk as _E
from warpfric.io import open_ensemble
from work_precision import reference_law, scene_members
N = int(sys.argv[1]); damping = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
ref = open_ensemble(os.environ.get("WF_REF", "/work/main/studies/reference/reference_scenes_stress.nc"))
model, fronts = reference_law(ref); members, idx = scene_members(ref, 18)
visc = members["viscous_coefficient"] > 0
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    ds = wf.simulate(members, scene=wf.Parameters(end_time=float(ref.end_time), damping=damping), model=model, fronts=fronts,
                     solver=wf.Solver(nodes=N, rtol=1e-5, max_steps=10**6, stall_factor=float("inf")), device="cpu",
                     progress=False, workers=2)
err = np.abs(ds.mu_s.values / ref.mu_s.values[idx] - 1); att = (ds.steps_accepted + ds.steps_rejected).values
print(f"{os.path.basename(os.environ.get('WF_REF', 'stress'))} {os.environ.get('WF_TAG', 'main'):>10} ({os.path.dirname(_E.__file__)}) N={N:3d} damping={damping:g}: "
      f"viscous mu_s err {err[visc].max():.1e} attempts {att[visc].mean():6.0f} | inviscid mu_s err {err[~visc].max():.1e} "
      f"attempts {att[~visc].mean():6.0f} | status {sorted(set(ds.status.values.tolist()))}")
