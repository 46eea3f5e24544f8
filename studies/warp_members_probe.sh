#!/usr/bin/env bash
# Probe: several members per warp (WARPFRIC_TEAM_WARP_MEMBERS) for teams of 16 and 8 lanes, against
# 32 lanes one member per warp. Correctness first (outputs bit for bit those of one member per warp),
# then 10,000 (and 1,000) members timed. Writes under $OUT.
set -uo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 WARPFRIC_COMMIT=${WARPFRIC_COMMIT:-probe}
OUT=${OUT:-out}; mkdir -p "$OUT"
python3 - <<'PY' 2>&1 | tee "$OUT/warp_members_equal.txt"
import os, numpy as np, warpfric as wf
vals = {"eccentricity": np.linspace(-0.3, 0.3, 21), "normal_force": np.geomspace(300.0, 3000.0, 21)}
def run(lanes, g, nodes=200):
    os.environ["WARPFRIC_TEAM_WARP_MEMBERS"] = str(g)
    os.environ["WARPFRIC_TEAM_BLOCK_MEMBERS"] = "8"
    return wf.simulate(vals, solver=wf.Solver(nodes=nodes, rtol=1e-5, lanes=lanes), fronts=wf.Fronts(),
                       device="cuda:0", progress=False)
for lanes, g in ((16, 2), (8, 4)):
    a = run(lanes, 1); b = run(lanes, g)
    bad = [k for k, v in a.data_vars.items() if not np.array_equal(v.values, b[k].values, equal_nan=True)]
    print(f"lanes {lanes}: {g} per warp vs 1: {len(a.data_vars) - len(bad)} of {len(a.data_vars)} equal; "
          f"differ: {bad[:8]}; ok {int((b.status.values == 0).sum())}/21; mu_s {b.mu_s.values[:3]}", flush=True)
os.environ.pop("WARPFRIC_TEAM_BLOCK_MEMBERS")
PY
E="python3 studies/bench_engine.py --device cuda:0 --dtypes float64 --jsonl $OUT/warp_members.jsonl"
for round in 1 2; do
  for cfg in "32 1" "16 1" "16 2" "8 4"; do
    set -- $cfg
    WARPFRIC_TEAM_WARP_MEMBERS=$2 $E --lanes $1 --members ${MEMBERS:-1000 10000} --out "$OUT/wm.json" 2>&1 \
      | grep 'cuda:0' | grep -v '{' | sed "s/^/lanes $1 x $2: /"
  done
done
