"""Team size at small N on a GPU: the cooperative kernel with the largest power of two <= N // 2
lanes (the automatic choice before) against N // 2 lanes (the automatic choice now: every lane
owns two nodes, one lane three for odd N), on the cases of docs/performance.md ("Team size at
small N"). Each case is timed in two rounds, the two team sizes alternating; best of 10 runs (5 for
10,000 members), kernels compiled first.

    python studies/team_size.py [--device cuda:0]

Prints one line per timing: N, law, rtol, members, round, lanes, best wall time, mean attempts per
member, members ok, and the first member's mu_s (the two team sizes agree to round-off).
"""

import argparse
import time
import warnings

import numpy as np

import warpfric as wf

# (nodes, relaxation gate, rtol, end_time, members): the diffrax peers' setting (N = 40, gate-less,
# to 20.6 s), the cheapest mu_s-only setting of the gate-less law in "Work-precision" (N = 25, rtol
# 1e-4; under the default law it is N = 50), one member of the default law at N = 40
CASES = [
    (40, "none", 1e-5, 20.6, 1), (40, "none", 1e-5, 20.6, 100), (40, "none", 1e-5, 20.6, 10000),
    (25, "none", 1e-4, None, 10000), (25, "stress", 1e-4, None, 10000), (40, "stress", 1e-5, None, 1),
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda:0")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for nodes, gate, rtol, end, members in CASES:
        m = {"eccentricity": np.linspace(-0.2, 0.2, members), "normal_force": np.geomspace(500, 5000, members)}
        power_of_two = 1 << ((nodes // 2).bit_length() - 1)
        for rnd in (1, 2):
            for lanes in (power_of_two, min(32, nodes // 2)):
                solver = wf.Solver(nodes=nodes, rtol=rtol, max_steps=10**6, lanes=lanes)
                kw = dict(scene=wf.Parameters(end_time=end), model=wf.Model(relaxation_gate=gate), solver=solver,
                          fronts=None, device=args.device, progress=False)
                ds = wf.simulate(m, **kw)
                best = np.inf
                for _ in range(5 if members > 1000 else 10):
                    t0 = time.perf_counter()
                    ds = wf.simulate(m, **kw)
                    best = min(best, time.perf_counter() - t0)
                attempts = (ds.steps_accepted.values + ds.steps_rejected.values).mean()
                print(f"N {nodes} {gate} rtol {rtol:g} members {members} round {rnd} lanes {lanes}: "
                      f"best {best * 1e3:.2f} ms, attempts {attempts:.1f}, ok {(ds.status.values == 0).sum()}, "
                      f"mu_s[0] {ds.mu_s.values[0]:.12f}", flush=True)


if __name__ == "__main__":
    main()
