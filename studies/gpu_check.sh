#!/usr/bin/env bash
# On the lent GPU machine (after the Warp install of shared/device/README.md): the test suite on
# cuda:0, then the engine benchmark without and with front metrics. Logs and JSON under $OUT.
#   bash studies/gpu_check.sh [extra bench_engine.py arguments]
set -uo pipefail
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
OUT=${OUT:-out}; mkdir -p "$OUT"
python3 -c "import warp as wp; wp.init(); print(wp.__version__, wp.get_cuda_devices())"
WARPFRIC_TEST_DEVICE=cuda:0 python3 -m pytest -q -p no:cacheprovider tests 2>&1 | tee "$OUT/tests_cuda.log" | tail -15
python3 studies/bench_engine.py --device cuda:0 --repeat 2 --out "$OUT/bench_engine_h100.json" "$@" 2>&1 | tee "$OUT/bench_h100.log" | tail -8
python3 studies/bench_engine.py --device cuda:0 --repeat 2 --fronts --out "$OUT/bench_engine_h100_fronts.json" "$@" 2>&1 | tee "$OUT/bench_h100_fronts.log" | tail -8
