#!/usr/bin/env bash
# Issue 4 on the lent H100 (after the Warp install of shared/device/README.md): the work-precision
# sweep with 10,000 members per setting, the hard-case stability map, and the 100,000-member
# throughput row. Logs and results under $OUT.
#   bash studies/gpu_issue4.sh [wp|stability|all]
set -uo pipefail
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
OUT=${OUT:-out}; mkdir -p "$OUT"
what=${1:-all}
if [[ $what == wp || $what == all ]]; then
  python3 studies/work_precision.py run --device cuda:0 --members 10000 --nodes 25 40 50 100 200 \
      --rtols 1e-3 1e-4 1e-5 1e-6 --dtypes float64 float32 --out "$OUT/work_precision_h100.nc" 2>&1 \
      | tee "$OUT/work_precision_h100.log" | tail -45
fi
if [[ $what == stability || $what == all ]]; then
  python3 studies/stability.py --device cuda:0 --max-steps 20000 --out "$OUT/stability_h100.nc" 2>&1 | tee "$OUT/stability_h100.log" | grep -v "^warpfric"
fi
