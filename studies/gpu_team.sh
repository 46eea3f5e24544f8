#!/bin/bash
# The cooperative kernel on the GPU (issue 13): agreement with the thread-per-member kernel, then
# the engine benchmark with both kernels. Run on the device host after the Warp install:
#   export PYTHONPATH=/tmp/site:$PWD; bash studies/gpu_team.sh [check|bench|all]
set -u
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
what=${1:-all}
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
if [ "$what" = check ] || [ "$what" = all ]; then
  python studies/team_check.py --device cuda:0 --nodes 30 --lanes 8 15 --gates none stress --out "$OUT/team_check.json" 2>&1 | grep -v "^Module" | tail -8
fi
if [ "$what" = bench ] || [ "$what" = all ]; then
  python studies/bench_engine.py --device cuda:0 --members ${MEMBERS:-1 1000 10000} --dtypes float64 --relaxation-gate ${GATE:-none} \
    --lanes ${LANES:-1 32} --out "$OUT/bench_team_${GATE:-none}.json" 2>&1 | grep -v "^Module\|^{" | tail -12
fi
