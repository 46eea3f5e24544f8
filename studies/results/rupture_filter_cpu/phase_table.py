"""Markdown table of the per-phase counts (mean per scene over the 9 inviscid scenes) from scenes_phases.py's npz files."""
import numpy as np
keys = ["acc", "rej", "rej err", "rej newton", "rej switch", "missed pred", "switches", "unlocated", "newton it"]
print("| N | damping | phase (s) | " + " | ".join(keys) + " |")
print("|---|---|---|" + "---:|" * len(keys))
for N, d in ((25, "0"), (200, "0"), (25, "1e+06"), (200, "1e+06")):
    z = np.load(f"/tmp/diag/scenes_N{N}_d{d}_stress.npz"); C = z["C"].sum(axis=0) / 9; ends = z["ends"]
    bounds = [(0, 10.0), (10.0, 20.0), (20.0, 20.1), (20.1, 20.2), (20.2, 20.3), (20.3, 20.6)]
    idx = {float(t): j for j, t in enumerate(ends)}
    for a, b in bounds:
        row = C[idx[b]] - (C[idx[a]] if a > 0 else 0)
        print(f"| {N} | {d} | {a:g}-{b:g} | " + " | ".join(f"{v:.0f}" for v in row) + " |")
    print(f"| {N} | {d} | **total** | " + " | ".join(f"{v:.0f}" for v in C[-1]) + " |")
