"""Relative mu_s errors of the saved runs (/tmp/diag/mu_*.npy, from totals.py) against the stress reference
(studies/reference/reference_scenes_stress.nc; its inviscid scenes matched by (e, F))."""
import glob, numpy as np, sys
sys.path.insert(0, "/work/main/studies")
from warpfric.io import open_ensemble
ref = open_ensemble("/work/main/studies/reference/reference_scenes_stress.nc")
e = np.broadcast_to(ref.eccentricity.values, (ref.sizes["member"],)); F = np.broadcast_to(ref.normal_force.values, e.shape)
eta = np.broadcast_to(ref.viscous_coefficient.values, e.shape); mu = ref.mu_s.values
E, FF = np.meshgrid([-0.2, 0.0, 0.2], [500.0, 1000.0, 5000.0], indexing="ij")
r = np.array([mu[(np.isclose(e, a)) & (np.isclose(F, b)) & (eta == 0)][0] for a, b in zip(E.ravel(), FF.ravel())])
print("reference (rtol/N in attrs):", {k: v for k, v in ref.attrs.items() if k.startswith("solver_nodes") or k.startswith("solver_rtol")})
print("reference mu_s:", " ".join(f"{v:.9f}" for v in r))
for f in sorted(glob.glob("/tmp/diag/mu_*.npy")):
    m = np.load(f); d = m / r - 1
    print(f"{f.split('/')[-1]:45s} max|err| {np.abs(d).max():.1e}  per scene: " + " ".join(f"{v:+.1e}" for v in d))
