#!/usr/bin/env bash
# On the lent GPU machine (after the Warp install of shared/device/README.md), session 3 measurements:
#   bash studies/gpu_session3.sh tests    # the gate/trust/physics/fronts/numerics tests on cuda:0
#   bash studies/gpu_session3.sh bench    # engine benchmark: stress gate vs no gate, fronts off/on
#   bash studies/gpu_session3.sh stability  # hard-case map under the stress gate (float64)
#   bash studies/gpu_session3.sh figures  # every figure study, full size, under the stress gate
#   bash studies/gpu_session3.sh figures-nogate  # the same with relaxation_gate="none" (NAME_nogate files)
#   bash studies/gpu_session3.sh float32  # float32 (gate-less law) benchmark and stability map, straggler rule on
#   bash studies/gpu_session3.sh fallback  # session 4: the same with the float64 re-run of failed float32 members,
#                                          # and the float64 map of the gate-less law beside it
# Logs and JSON under $OUT.
set -uo pipefail
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
OUT=${OUT:-out}; mkdir -p "$OUT"
python3 -c "import warp as wp; wp.config.quiet = True; wp.init(); print('warp', wp.__version__, wp.get_cuda_devices())"
case "${1:-}" in
  tests)
    WARPFRIC_TEST_DEVICE=cuda:0 timeout 540 python3 -m pytest -q -p no:cacheprovider tests/test_gate.py \
      tests/test_trust.py tests/test_physics.py tests/test_fronts.py 2>&1 | tee "$OUT/tests_cuda.log" | tail -6 ;;
  bench)
    for gate in stress none; do
      python3 studies/bench_engine.py --device cuda:0 --members 1 1000 10000 --dtypes float64 --repeat 2 \
        --relaxation-gate $gate --out "$OUT/bench_engine_h100_$gate.json" 2>&1 | tee "$OUT/bench_h100_$gate.log" | tail -4
      python3 studies/bench_engine.py --device cuda:0 --members 10000 --dtypes float64 --repeat 2 --fronts \
        --relaxation-gate $gate --out "$OUT/bench_engine_h100_${gate}_fronts.json" 2>&1 | tee "$OUT/bench_h100_${gate}_fronts.log" | tail -2
    done ;;
  stability)
    timeout 500 python3 studies/stability.py --device cuda:0 --dtypes float64 --out "$OUT/stability_h100_stress.nc" \
      2>&1 | grep -v "pass [12]/2" | tee "$OUT/stability_h100_stress.log" | tail -25 ;;
  figures)
    timeout 560 python3 studies/figures.py all --device cuda:0 --outdir "$OUT/figures" 2>&1 | tee "$OUT/figures_h100.log" | tail -12 ;;
  figures-nogate)
    timeout 560 python3 studies/figures.py all --device cuda:0 --relaxation-gate none --outdir "$OUT/figures" 2>&1 \
      | tee "$OUT/figures_h100_nogate.log" | tail -12 ;;
  float32)
    # issue 11's benchmark: float32 (gate-less law; the stress gate refuses float32) against float64
    python3 studies/bench_engine.py --device cuda:0 --members 10000 --dtypes float64 float32 --repeat 1 \
      --relaxation-gate none --out "$OUT/bench_engine_h100_none_f32.json" 2>&1 | tee "$OUT/bench_h100_none_f32.log" | tail -3
    timeout 420 python3 studies/stability.py --device cuda:0 --dtypes float32 --relaxation-gate none \
      --stall-factor 10 --out "$OUT/stability_h100_none_f32.nc" 2>&1 | grep -v "pass [12]/2" \
      | tee "$OUT/stability_h100_none_f32.log" | head -12 ;;
  fallback)
    python3 studies/bench_engine.py --device cuda:0 --members 10000 --dtypes float64 float32 --repeat 2 \
      --relaxation-gate none --out "$OUT/bench_engine_h100_none_f32_fallback.json" 2>&1 \
      | tee "$OUT/bench_h100_none_f32_fallback.log" | tail -3
    timeout 400 python3 studies/stability.py --device cuda:0 --dtypes float64 float32 --relaxation-gate none \
      --stall-factor 10 --out "$OUT/stability_h100_none_fallback.nc" 2>&1 | grep -v "pass [12]/2" \
      | tee "$OUT/stability_h100_none_fallback.log" | grep -v "failed:" | head -24 ;;
  *) echo "usage: $0 tests|bench|stability|figures|float32|fallback"; exit 2 ;;
esac
