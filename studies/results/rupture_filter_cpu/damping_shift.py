"""Relative change of mu_s by damping (and by the patched filter) against the same N without, over the 9 inviscid scenes."""
import numpy as np
for N in (25, 50, 100, 200):
    base = np.load(f"/tmp/diag/mu_N{N}_d0_stress_r1e-05_main.npy")
    for tag in ("d10000_stress_r1e-05_main", "d100000_stress_r1e-05_main", "d1e+06_stress_r1e-05_main"):
        m = np.load(f"/tmp/diag/mu_N{N}_{tag}.npy"); d = m / base - 1
        print(f"N={N:3d} {tag:28s} max |d mu_s|/mu_s {np.abs(d).max():.1e}  median {np.median(np.abs(d)):.1e}")
