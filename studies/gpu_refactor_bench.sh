#!/usr/bin/env bash
# Issue 12's benchmark: the staged integrator (this tree) against the tree before the refactor, on the
# lent GPU (after the Warp install of shared/device/README.md). Prepare the old tree first, here:
#   mkdir -p benchref/studies && git archive 042ea86 | tar -x -C /tmp/old && cp -r /tmp/old/warpfric benchref/ \
#     && cp -r /tmp/old/kernels benchref/warpfric/kernels && cp -r /tmp/old/studies/{bench_engine.py,reference} benchref/studies/
# then: bash studies/gpu_refactor_bench.sh   (rows under $OUT; delete benchref/ afterwards)
set -uo pipefail
export PYTHONUNBUFFERED=1
for tree in new old; do
  root=$PWD; [ $tree = old ] && root=$PWD/benchref
  for gate in none stress; do
    PYTHONPATH=/tmp/site:$root timeout 250 python3 $root/studies/bench_engine.py --device cuda:0 --members 1 10000 --dtypes float64 \
      --repeat 2 --relaxation-gate $gate --out $OUT/bench_${tree}_${gate}.json 2>&1 | grep -v "^Warp\|^   \|^Module" | tail -2 | sed "s|^|$tree $gate |"
  done
done
