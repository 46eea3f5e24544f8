"""One cooperative-kernel run with its build and run times printed as they happen (device check).

    python studies/team_smoke.py DEVICE LANES NODES GATE [MEMBERS]
"""
import sys
import time

import warpfric as wf

device, lanes, nodes, gate = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
m = int(sys.argv[5]) if len(sys.argv) > 5 else 4
values = {"eccentricity": [0.0, -0.2, 0.3, 0.6][:m] if m <= 4 else [0.1] * m}
t0 = time.perf_counter()
ds = wf.simulate(values, model=wf.Model(relaxation_gate=gate), solver=wf.Solver(nodes=nodes, lanes=lanes),
                 device=device, progress=False)
print(f"lanes {lanes} N {nodes} {gate}: build {ds.attrs['kernel_build_time_s']:.1f} s, run {ds.attrs['wall_time_s']:.3f} s, "
      f"total {time.perf_counter() - t0:.1f} s, mu_s {ds.mu_s.values[:4]}, status {ds.status.values[:4]}", flush=True)
