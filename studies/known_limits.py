"""The measurements behind docs/performance.md, "Known limits" (CPU, float64 unless stated):

    python studies/known_limits.py vibration     # inviscid pad vibration: steps against rtol and damping
    python studies/known_limits.py float32       # float32 at low disc velocity against float64
    python studies/known_limits.py all
    (also: python studies/bench.py limits vibration|float32|all)
"""

from __future__ import annotations

import sys
import time

import warpfric as wf


def vibration():
    """viscous_coefficient = 0, N = 40, protocol to 20.6 s, fronts off: accepted steps (in all, and
    before the disc starts at 20 s) and mu_s against rtol, and with damping at rtol 1e-7."""
    print(f"{'rtol':>6} {'damping Pa s/m':>15} {'accepted':>9} {'by 20 s':>9} {'rejected':>9} {'mu_s':>12} {'wall s':>7}")
    for rtol, damping in ((1e-5, 0.0), (1e-6, 0.0), (1e-7, 0.0), (1e-8, 0.0), (1e-7, 1e5), (1e-7, 1e6)):
        t0 = time.perf_counter()
        ds = wf.simulate({"viscous_coefficient": 0.0, "damping": damping, "end_time": [20.6, 20.0 + 1e-9]},
                         solver=wf.Solver(nodes=40, rtol=rtol, max_steps=10**7), fronts=None, device="cpu")
        print(f"{rtol:6.0e} {damping:15.0e} {int(ds.steps_accepted[0]):9d} {int(ds.steps_accepted[1]):9d} "
              f"{int(ds.steps_rejected[0]):9d} {float(ds.mu_s[0]):12.9f} {time.perf_counter() - t0:7.2f}")


def float32():
    """Default scene (F = 1000 N), N = 100, rtol 1e-5, fronts off, float32 and float64 at several
    disc velocities; mu_s error against float64 at rtol 1e-8."""
    print(f"{'v_d m/s':>8} {'f32 status':>10} {'f32 steps':>9} {'f32 mu_s err':>12} {'f64 mu_s err':>12}")
    for v in (1e-6, 1e-5, 1e-4, 1e-3):
        m = {"disc_velocity": [v]}
        a = wf.simulate(m, solver=wf.Solver(nodes=100, dtype="float32", max_steps=20000), fronts=None, device="cpu")
        b = wf.simulate(m, solver=wf.Solver(nodes=100, dtype="float64", max_steps=20000), fronts=None, device="cpu")
        c = wf.simulate(m, solver=wf.Solver(nodes=100, dtype="float64", rtol=1e-8, max_steps=10**6), fronts=None,
                        device="cpu")
        ref = float(c.mu_s[0])
        print(f"{v:8.0e} {int(a.status[0]):10d} {int(a.steps_accepted[0]):9d} {float(a.mu_s[0]) / ref - 1:12.2e} "
              f"{float(b.mu_s[0]) / ref - 1:12.2e}")


def main(argv=None):
    import argparse

    checks = {"vibration": vibration, "float32": float32}
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("check", nargs="?", default="all", choices=[*checks, "all"], help="which measurement (default all)")
    name = ap.parse_args(sys.argv[1:] if argv is None else argv).check
    for key in (checks if name == "all" else [name]):
        print(f"== {key}: {checks[key].__doc__.split(chr(10))[0]}")
        checks[key]()


if __name__ == "__main__":
    main()
