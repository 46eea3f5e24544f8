#!/bin/bash
# The cooperative kernel's remaining target rows (issue 13): 10,000 members with fronts, 100,000
# members without (H100, N = 200, gate-less, rtol 1e-5, float64, lanes 32; compile excluded).
#   export PYTHONPATH=/tmp/site:$PWD; bash studies/gpu_team_more.sh
set -u
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
timeout 300 python -u studies/bench_engine.py --device cuda:0 --members 10000 --dtypes float64 --relaxation-gate none \
  --lanes 32 --fronts --out "$OUT/bench_team_none_fronts.json" 2>&1 | tail -2
timeout 200 python -u studies/bench_engine.py --device cuda:0 --members 100000 --dtypes float64 --relaxation-gate none \
  --lanes 32 --out "$OUT/bench_team_none_100k.json" 2>&1 | tail -2
