#!/bin/bash
# Nsight Compute on the cooperative kernel (issue 13): one 10,000-member launch of the integrate
# kernel (N = 200, gate-less law, rtol 1e-5, float64, lanes 32), the sections that give the launch
# shape, occupancy, the speed of light and the FP64 / memory rooflines. On the device host after the
# Warp install:  export PYTHONPATH=/tmp/site:$PWD; bash studies/gpu_ncu.sh
set -u
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
NCU=$(command -v ncu || ls /usr/local/cuda*/bin/ncu /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1)
echo "ncu: $NCU"
GATE=${GATE:-none}
LANES=${LANES:-32}
# compile and warm the kernel cache outside the profiler
python studies/bench_engine.py --device cuda:0 --members 1 --dtypes float64 --relaxation-gate $GATE --lanes $LANES \
  --out "$OUT/ncu_warm.json" > /dev/null 2>&1
"$NCU" -k regex:integrate --launch-skip 1 --launch-count 1 \
  --section LaunchStats --section Occupancy --section SpeedOfLight --section MemoryWorkloadAnalysis \
  --section SpeedOfLight_HierarchicalDoubleRooflineChart --section ComputeWorkloadAnalysis \
  --metrics sm__sass_thread_inst_executed_op_dadd_pred_on.sum,sm__sass_thread_inst_executed_op_dmul_pred_on.sum,sm__sass_thread_inst_executed_op_dfma_pred_on.sum,gpu__time_duration.sum,dram__bytes.sum \
  python studies/bench_engine.py --device cuda:0 --members 10000 --dtypes float64 --relaxation-gate $GATE \
  --lanes $LANES --out "$OUT/ncu_bench.json" > "$OUT/ncu_${GATE}_l${LANES}.txt" 2>&1
grep -E "Block Size|Grid Size|Registers Per|Theoretical Occupancy|Achieved Occupancy|Compute \(SM\) Throughput|Memory Throughput|DRAM Throughput|Duration|dfma|dmul|dadd|dram__bytes|Local Memory|Waves Per SM|Shared Memory Configuration Size|Stack Size|Block Limit" "$OUT/ncu_${GATE}_l${LANES}.txt" | head -40
