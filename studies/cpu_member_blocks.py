"""The CPU's member blocks (warpfric/simulate.py CPU_MEMBER_BLOCK): one ensemble run in blocks of that
many members against one launch over all of them, on one core, with the outputs compared.

    python studies/cpu_member_blocks.py [--cases 41:2048 100:512 200:256] [--block 32]

Each case NODES:MEMBERS is the default law at rtol 1e-5, fronts off, members with eccentricity
uniform in [-0.2, 0.2] and normal force log-uniform in [500, 5000] N (seed 0), workers=1, the
kernels compiled first. Prints the two times and whether every output is equal bit for bit
(docs/performance.md, "CPU")."""

import argparse
import sys
import time

import numpy as np

import warpfric as wf


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["41:2048", "100:512", "200:256"], help="NODES:MEMBERS each")
    ap.add_argument("--block", type=int, default=None, help="members per block (default: CPU_MEMBER_BLOCK)")
    args = ap.parse_args(argv)
    module = sys.modules["warpfric.simulate"]
    block = args.block or module.CPU_MEMBER_BLOCK
    rng = np.random.default_rng(0)
    for case in args.cases:
        nodes, n = (int(v) for v in case.split(":"))
        members = {"eccentricity": rng.uniform(-0.2, 0.2, n), "normal_force": np.exp(rng.uniform(np.log(500), np.log(5000), n))}
        kw = dict(solver=wf.Solver(nodes=nodes), fronts=None, device="cpu", progress=False, workers=1)
        wf.simulate({k: v[:2] for k, v in members.items()}, **kw)  # compile, or load the kernels
        times, results = {}, {}
        for label, size in (("one launch", 10**9), (f"blocks of {block}", block)):
            module.CPU_MEMBER_BLOCK = size
            t0 = time.perf_counter()
            results[label] = wf.simulate(members, **kw)
            times[label] = time.perf_counter() - t0
        a, b = results.values()
        equal = all(np.array_equal(a[v].values, b[v].values, equal_nan=a[v].dtype.kind == "f") for v in a.data_vars)
        print(f"N = {nodes}, {n} members: " + ", ".join(f"{k} {t:.2f} s" for k, t in times.items())
              + f" ({times['one launch'] / times[f'blocks of {block}']:.2f}x); outputs equal: {equal}", flush=True)


if __name__ == "__main__":
    main()
