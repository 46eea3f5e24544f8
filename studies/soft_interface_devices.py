"""The soft-interface members of ``known_limits.py soft-interface`` on a GPU against the CPU
(docs/performance.md, "Known limits"): the CPU's thread kernel and the GPU's team kernel on the
same 120 members (N = 30, rtol 1e-5, automatic end), their statuses and mu_s side by side, then the
GPU's time at sliding widths 1e-3 and 1e-2.

    python studies/soft_interface_devices.py [--device cuda:0]
"""

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import warpfric as wf

sys.path.insert(0, str(Path(__file__).parent))
from known_limits import soft_interface_members  # noqa: E402


def run(members, device, width):
    return wf.simulate(members, solver=wf.Solver(nodes=30, sliding_width=width), device=device,
                       progress=False, fronts=None)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda:0")
    device = ap.parse_args(argv).device
    members = soft_interface_members()
    warnings.simplefilter("ignore")
    cpu = run(members, "cpu", 1e-3)
    for width in (1e-3, 1e-2):
        run({key: value[:2] for key, value in members.items()}, device, width)  # compile outside the timing
        start = time.perf_counter()
        ds = run(members, device, width)
        wall = time.perf_counter() - start
        st = ds.status.values
        print(f"width {width:g}: {wall:.2f} s on {device}, statuses {np.bincount(st, minlength=6).tolist()}, "
              f"accepted steps median {np.median(ds.steps_accepted.values):.0f} max {ds.steps_accepted.values.max()}")
        if width != 1e-3:
            continue
        both = (st == 0) & (cpu.status.values == 0)
        apart = np.abs(ds.mu_s.values[both] / cpu.mu_s.values[both] - 1)
        print(f"  against the CPU, {both.sum()} members ok on both: mu_s relative difference median "
              f"{np.median(apart):.1e}, 90th percentile {np.percentile(apart, 90):.1e}, largest {apart.max():.1e}; "
              f"members > 1e-6: {(apart > 1e-6).sum()}, > 1e-4: {(apart > 1e-4).sum()}")
        for i in np.flatnonzero(both)[np.argsort(apart)[::-1][:6]]:
            print(f"    member {i:3d}: F {members['normal_force'][i] / 1e3:6.1f} kN, mu0/h "
                  f"{members['interface_stiffness'][i]:.2e}: cpu {cpu.mu_s.values[i]:.6f} "
                  f"({cpu.steps_accepted.values[i]} steps) {device} {ds.mu_s.values[i]:.6f} "
                  f"({ds.steps_accepted.values[i]} steps)")
        print("  statuses differing:", np.flatnonzero(st != cpu.status.values).tolist())


if __name__ == "__main__":
    main()
