#!/usr/bin/env bash
# The GPU measurements of docs/performance.md, on a host with an NVIDIA GPU and Warp installed
# (warpfric importable: `pip install -e .`, or PYTHONPATH pointing at a site folder and this tree).
#
#   bash studies/gpu_bench.sh MODE [extra options for studies/bench.py]
#
# Every mode runs `python studies/bench.py ...` (or, for the test suite, the figures and the
# 2-GPU sweep, the project's own commands) and leaves its logs and JSON under $OUT (default out/);
# the JSON lines of every call go to $JSONL (default $OUT/bench.jsonl): copy what you keep into
# studies/results/. Compilation is excluded from every timing (a warm-up run compiles first).
#
# modes (default settings of the tables: N = 200, rtol 1e-5, float64, the bench_engine members):
#   tests          the test suite on cuda:0 (ARGS go to pytest: -n 8 runs it in eight processes, pytest-xdist)
#   engine         stress gate: team of 32 lanes and thread per member, predicted switches on and off,
#                  1 / 1,000 / 10,000 members
#   gateless       the same for relaxation_gate="none" (predictions do not apply)
#   fronts         10,000 members: fronts off, contact, strength, velocity
#   large          100,000 members (team of 32)
#   rtol           stress gate at rtol 1e-4 (mu_s within 1e-4)
#   methods        TR-BDF2 against ESDIRK4, gate-less, rtol 1e-5 / 1e-6 / 1e-7, 1 and 10,000 members
#   float32        gate-less, float64 against float32 (with the float64 re-run), 10,000 members
#   hostcpu        the GPU host's own CPU: 1 / 4 / 16 members, thread kernel
#   work-precision 10,000 realisations per (N, rtol), float64: the default law, then the gate-less law
#   stability      the hard-case map: stress gate in float64; gate-less in float64 and float32
#   peers          JAX + diffrax (needs jax and the wheels of studies/diffrax_wheels.sh) and scipy BDF
#   profile        one member: time per attempt against N (team of 32)
#   launch-chunks  launches of 7 attempts against one launch: outputs equal bit for bit
#   launches       where the time goes: every launch of 1 / 1,000 / 10,000 members timed (running
#                  members, attempts), launches of 500 and 100 attempts, and Nsight Compute's
#                  occupancy and SM-active cycles of each 10,000-member launch
#   ncu            Nsight Compute on the 10,000-member launch (occupancy, rooflines); GATE, LANES
#   ncu-one        Nsight Compute's warp stall reasons of the one-member launch
#   ncu-sources    Nsight Compute's source counters of the one-member launch (line info on)
#   stalls         Nsight Compute's warp stall reasons and memory traffic of one 10,000-member launch
#   stall-sites    the same launch's warp samples by SASS instruction (line-info kernel), summed by Python
#                  call site and source line (studies/stall_sites.py)
#   stall-sites-one the same for one member alone (its automatic team), the launch that integrates it
#   sass           the integrate kernel's SASS instructions by inlined call site (studies/sass_sites.py)
#   exchange       the team's lane exchanges, tiles against warp shuffles: outputs (studies/team_exchange.py)
#                  and 1 / 10,000 members timed with each
#   wide           teams of several warps: team sizes give the same member (studies/team_lanes.py), then
#                  32 / 64 / 96 lanes for 1 and 100 members, 32 / 96 for 133 / 264 / 528, and one member
#                  at N = 400 in 32 to 192 lanes, two rounds
#   blocks         members per thread block, chosen per run (min(8, ceil(members / SMs))) against 1
#                  (WARPFRIC_TEAM_BLOCK_MEMBERS=1):
#                  1 / 1,000 / 10,000 members, the contact front, the gate-less law, two rounds; then the
#                  GPU tests of tests/test_team.py (outputs bit for bit equal)
#   footprint      the working set against L1 and L2: Nsight Compute's DRAM, L2 and L1 counters of one
#                  100-attempt launch of 10,000 members at 8 / 6 / 4 / 2 members a block and in teams of 64
#                  lanes, and of one wave of 8 members a block on 132 / 66 / 33 SMs (1,056 / 528 / 264
#                  members); then the wall times of the 10,000-member rows
#   dask [SWEEP]   2 GPUs: one process against a local Dask cluster of 1 and 2 workers
#   figures [ARGS] every figure study at full size (ARGS e.g. --relaxation-gate none)
set -uo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH=/tmp/site:$PWD${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
OUT=${OUT:-out}; mkdir -p "$OUT"
JSONL=${JSONL:-$OUT/bench.jsonl}
mode=${1:-}; shift || true
B="python3 studies/bench.py --jsonl $JSONL"
E="$B engine --device cuda:0 --dtypes float64"
python3 -c "import warp as wp; wp.config.quiet = True; wp.init(); print('warp', wp.__version__, wp.get_cuda_devices())"
ncu_bin() { command -v ncu || ls /usr/local/cuda*/bin/ncu /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1; }
# stall_sites_table SUFFIX [options of studies/stall_sites.py]: the SASS source page of the profile
# $OUT/stall_sites$SUFFIX.ncu-rep summed by call site and source line, with the integrate cubin of
# $WARP_CACHE_PATH whose instructions match it (one cubin per shared-work stride); the table's head
stall_sites_table() {
  local suffix=$1 cubin; shift
  "$NCU" -i "$OUT/stall_sites$suffix.ncu-rep" --page source --csv --print-source sass | gzip -9 > "$OUT/stall_sass$suffix.csv.gz"
  for cubin in $(find "$WARP_CACHE_PATH" -name "*integrate*.cubin"); do
    cp "$cubin" "$OUT/integrate$suffix.cubin"
    if python3 studies/stall_sites.py --csv "$OUT/stall_sass$suffix.csv.gz" --cubin "$OUT/integrate$suffix.cubin" "$@" \
      > "$OUT/stall_sites$suffix.txt" 2>&1; then head -40 "$OUT/stall_sites$suffix.txt"; return 0; fi
  done
  head -40 "$OUT/stall_sites$suffix.txt"
  echo "no integrate cubin matches the profile"; return 1
}
case "$mode" in
  tests)
    WARPFRIC_TEST_DEVICE=cuda:0 python3 -m pytest -q -p no:cacheprovider tests "$@" 2>&1 | tee "$OUT/tests_cuda.log" | tail -15 ;;
  engine)
    $E --members 1 1000 10000 --relaxation-gate stress --lanes 32 1 --predict-switches on off \
      --out "$OUT/bench_engine_stress.json" "$@" 2>&1 | tee "$OUT/engine.log" | tail -14 ;;
  gateless)
    $E --members 1 1000 10000 --relaxation-gate none --lanes 32 1 --out "$OUT/bench_engine_none.json" "$@" 2>&1 \
      | tee "$OUT/gateless.log" | tail -8 ;;
  fronts)
    $E --members 10000 --relaxation-gate stress --front-events off contact strength velocity \
      --out "$OUT/bench_fronts.json" "$@" 2>&1 | tee "$OUT/fronts.log" | tail -6 ;;
  large)
    $E --members 100000 --relaxation-gate stress --lanes 32 --out "$OUT/bench_engine_100k.json" "$@" 2>&1 | tail -3 ;;
  rtol)
    $E --members 1 1000 10000 --relaxation-gate stress --lanes 32 --rtol 1e-4 --out "$OUT/bench_engine_rtol1e-4.json" "$@" \
      2>&1 | tail -5 ;;
  methods)
    for method in tr_bdf2 esdirk4; do
      for r in 1e-5 1e-6 1e-7; do
        $E --members 1 10000 --relaxation-gate none --lanes 32 --methods $method --rtol $r \
          --out "$OUT/bench_none_${method}_$r.json" "$@" 2>&1 | tail -3
      done
    done ;;
  float32)
    $B engine --device cuda:0 --members 10000 --dtypes float64 float32 --repeat 2 --relaxation-gate none \
      --out "$OUT/bench_engine_none_f32.json" "$@" 2>&1 | tail -4 ;;
  hostcpu)
    $B engine --device cpu --members 1 4 16 --dtypes float64 --relaxation-gate stress --lanes 1 \
      --out "$OUT/bench_hostcpu_stress.json" "$@" 2>&1 | tail -5 ;;
  work-precision)  # the default law (its reference), then the gate-less law; rtol 1e-6 only at N = 200 under the
    # stress gate (the inviscid scenes' dynamic rupture takes ~10^5 attempts a member at smaller N)
    $B work-precision run --device cuda:0 --members 10000 --nodes 200 --rtols 1e-3 1e-4 1e-5 1e-6 --dtypes float64 \
      --reference studies/reference/reference_scenes_stress.nc --out "$OUT/work_precision_h100_stress_n200.nc" "$@" 2>&1 \
      | tee "$OUT/work_precision_h100_stress_n200.log" | tail -8
    $B work-precision run --device cuda:0 --members 10000 --nodes 100 50 25 --rtols 1e-3 1e-4 1e-5 --dtypes float64 \
      --reference studies/reference/reference_scenes_stress.nc --out "$OUT/work_precision_h100_stress.nc" "$@" 2>&1 \
      | tee "$OUT/work_precision_h100_stress.log" | tail -12
    $B work-precision run --device cuda:0 --members 10000 --nodes 200 100 50 25 --rtols 1e-3 1e-4 1e-5 1e-6 \
      --dtypes float64 --out "$OUT/work_precision_h100_none.nc" "$@" 2>&1 | tee "$OUT/work_precision_h100_none.log" | tail -20 ;;
  stability)
    $B stability --device cuda:0 --dtypes float64 --out "$OUT/stability_stress.nc" "$@" 2>&1 \
      | grep -v "pass [12]/2" | tee "$OUT/stability_stress.log" | tail -25
    $B stability --device cuda:0 --dtypes float64 float32 --relaxation-gate none --stall-factor 10 \
      --out "$OUT/stability_none.nc" "$@" 2>&1 | grep -v "pass [12]/2" | tee "$OUT/stability_none.log" | tail -25 ;;
  peers)
    for method in esdirk4 tr_bdf2; do
      $B peers diffrax --members 1 100 1000 --nodes 40 --rtols 1e-5 --end-time 20.6 --relaxation-gate none --timeout 60 \
        --kill-factor 1.2 --device gpu --warpfric-device cuda:0 --root-finders newton --warpfric-method $method \
        --warpfric-rtols 1e-4 1e-5 1e-6 1e-7 --repeat 3 --out "$OUT/baseline_diffrax_$method.json" "$@" 2>&1 | tail -6
    done
    $B peers scipy --gpu-json studies/results/work_precision_h100.json --out "$OUT/baseline_scipy_gpuhost.json" 2>&1 | tail -8 ;;
  profile)
    $B profile --device cuda:0 --lanes 32 "$@" 2>&1 | tee "$OUT/profile.txt" | tail -8 ;;
  launch-chunks)
    $B launch-chunks --device cuda:0 "$@" 2>&1 | tail -3 | tee "$OUT/launch_chunks.txt" ;;
  launches)
    $E --members 1 1000 10000 --steps-per-launch 500 100 --launch-log "$OUT/launches.jsonl" \
      --out "$OUT/bench_launches.json" "$@" 2>&1 | tee "$OUT/launches.log" | grep -v '^{' | tail -12
    # every launch after the three of the benchmark's one-member warm-up (--profile-from-start off
    # with --cuda-profile-range profiled nothing on the H100 host of 2655f21)
    "$(ncu_bin)" -k regex:integrate --launch-skip 3 --section SpeedOfLight --section Occupancy \
      --section LaunchStats python3 studies/bench_engine.py --device cuda:0 --dtypes float64 --members 10000 \
      --steps-per-launch 100 --repeat 1 --out "$OUT/bench_ncu.json" > "$OUT/ncu_launches.txt" 2>&1
    grep -E "Duration|SM Active Cycles|Elapsed Cycles|Achieved Occupancy" "$OUT/ncu_launches.txt" ;;
  ncu)
    GATE=${GATE:-none}; LANES=${LANES:-32}; NCU=$(ncu_bin); echo "ncu: $NCU"
    python3 studies/bench_engine.py --device cuda:0 --members 1 --dtypes float64 --relaxation-gate "$GATE" --lanes "$LANES" \
      --out "$OUT/ncu_warm.json" > /dev/null 2>&1  # compile outside the profiler
    "$NCU" -k regex:integrate --launch-skip 1 --launch-count 1 \
      --section LaunchStats --section Occupancy --section SpeedOfLight --section MemoryWorkloadAnalysis \
      --section SpeedOfLight_HierarchicalDoubleRooflineChart --section ComputeWorkloadAnalysis \
      --metrics sm__sass_thread_inst_executed_op_dadd_pred_on.sum,sm__sass_thread_inst_executed_op_dmul_pred_on.sum,sm__sass_thread_inst_executed_op_dfma_pred_on.sum,gpu__time_duration.sum,dram__bytes.sum \
      python3 studies/bench_engine.py --device cuda:0 --members 10000 --dtypes float64 --relaxation-gate "$GATE" \
      --lanes "$LANES" --out "$OUT/ncu_bench.json" > "$OUT/ncu_${GATE}_l${LANES}.txt" 2>&1
    grep -E "Block Size|Grid Size|Registers Per|Theoretical Occupancy|Achieved Occupancy|Compute \(SM\) Throughput|Memory Throughput|DRAM Throughput|Duration|dfma|dmul|dadd|dram__bytes|Local Memory|Waves Per SM|Stack Size|Block Limit" \
      "$OUT/ncu_${GATE}_l${LANES}.txt" | head -40 ;;
  ncu-one)
    NCU=$(ncu_bin); echo "ncu: $NCU"
    "$NCU" -k regex:integrate --launch-skip 2 --launch-count 1 \
      --section LaunchStats --section Occupancy --section WarpStateStats --section ComputeWorkloadAnalysis \
      --section MemoryWorkloadAnalysis --section SchedulerStats --section InstructionStats \
      --metrics regex:smsp__average_warps_issue_stalled_.*_per_issue_active\.ratio,gpu__time_duration.sum,smsp__inst_executed.sum \
      python3 studies/bench.py --jsonl "$JSONL" one-member --times 2 > "$OUT/ncu_one_member_stress_l32.txt" 2>&1
    grep -E "Duration|Warp Cycles Per Issued|Issued Ipc|stalled_.*ratio|inst_executed.sum|Local Memory|Registers Per|Stack" \
      "$OUT/ncu_one_member_stress_l32.txt" | awk '$NF+0 > 0.05 || !/stalled/' | head -40 ;;
  stalls)
    NCU=$(ncu_bin); echo "ncu: $NCU"
    python3 studies/bench_engine.py --device cuda:0 --members 1 --dtypes float64 --lanes 32 --out "$OUT/stalls_warm.json" \
      > /dev/null 2>&1  # compile outside the profiler
    # the first launch of the 10,000 members, after the three of the benchmark's one-member warm-up
    # (--profile-from-start off with --cuda-profile-range profiled nothing on the H100 host of 2655f21)
    "$NCU" -k regex:integrate --launch-skip 3 --launch-count 1 \
      --section LaunchStats --section Occupancy --section WarpStateStats --section MemoryWorkloadAnalysis \
      --section SchedulerStats --section SpeedOfLight \
      --metrics regex:smsp__average_warps_issue_stalled_.*_per_issue_active\.ratio,smsp__inst_executed.sum,l1tex__t_sector_pipe_lsu_mem_global_op_ld_hit_rate.pct,dram__bytes.sum,l1tex__t_sectors_pipe_lsu_mem_local_op_ld.sum \
      python3 studies/bench_engine.py --device cuda:0 --dtypes float64 --members 10000 --lanes 32 --steps-per-launch 100 \
      --repeat 1 --out "$OUT/stalls_bench.json" > "$OUT/ncu_stress_10k_stalls.txt" 2>&1
    grep -E "Duration|Warp Cycles Per Issued|Issued Ipc|Achieved Active|stalled_.*ratio|inst_executed.sum|Hit Rate|Stack" \
      "$OUT/ncu_stress_10k_stalls.txt" | awk '$NF+0 > 0.04 || !/stalled/' | head -30 ;;
  stall-sites)
    NCU=$(ncu_bin); echo "ncu: $NCU"
    # a kernel cache of its own: the line-info kernel is then the one integrate cubin in it
    export WARP_CACHE_PATH=$(mktemp -d)
    python3 studies/bench_engine.py --device cuda:0 --members 1 --dtypes float64 --lanes 32 --lineinfo \
      --out "$OUT/stall_sites_warm.json" > "$OUT/stall_sites_warm.log" 2>&1 || { tail "$OUT/stall_sites_warm.log"; exit 1; }
    "$NCU" -k regex:integrate --launch-skip 3 --launch-count 1 --section SourceCounters \
      --section WarpStateStats --import-source yes -o "$OUT/stall_sites" python3 studies/bench_engine.py \
      --device cuda:0 --dtypes float64 --members 10000 --lanes 32 --lineinfo --steps-per-launch 100 \
      --repeat 1 --out "$OUT/stall_sites_bench.json" > "$OUT/ncu_stall_sites.log" 2>&1
    # the cache holds a cubin for the warm-up (one member a block) and one for the profile (eight)
    stall_sites_table "" "$@" || exit 1 ;;
  stall-sites-one)
    # one member alone (the automatic team: 96 lanes at N = 200), the launch that integrates it
    NCU=$(ncu_bin); echo "ncu: $NCU"
    export WARP_CACHE_PATH=$(mktemp -d)
    python3 studies/bench_engine.py --device cuda:0 --members 1 --dtypes float64 --lineinfo \
      --out "$OUT/stall_sites_one_warm.json" > "$OUT/stall_sites_one_warm.log" 2>&1 || { tail "$OUT/stall_sites_one_warm.log"; exit 1; }
    # the benchmark's warm-up simulate launches twice (the second launch finds the member done), then the timed one
    "$NCU" -k regex:integrate --launch-skip 2 --launch-count 1 --section SourceCounters --section WarpStateStats \
      --section LaunchStats --section Occupancy --section SpeedOfLight --import-source yes -o "$OUT/stall_sites_one" \
      python3 studies/bench_engine.py --device cuda:0 --dtypes float64 --members 1 --lineinfo --repeat 1 \
      --out "$OUT/stall_sites_one_bench.json" > "$OUT/ncu_stall_sites_one.log" 2>&1
    "$NCU" -i "$OUT/stall_sites_one.ncu-rep" --page details > "$OUT/ncu_one_member_details.txt" 2>&1
    stall_sites_table _one "$@" || exit 1 ;;
  sass)
    python3 studies/sass_sites.py "$@" 2>&1 | tee "$OUT/sass_sites.txt" | head -30 ;;
  blocks)
    # a block per member (WARPFRIC_TEAM_BLOCK_MEMBERS=1) keeps its work in global memory: so that the
    # rows differ only by the blocks, the blocked runs keep theirs there too
    export WARPFRIC_TEAM_SHARED_WORK=0
    for round in 1 2; do
      for k in 1 auto; do
        if [ "$k" = auto ]; then unset WARPFRIC_TEAM_BLOCK_MEMBERS; else export WARPFRIC_TEAM_BLOCK_MEMBERS=$k; fi
        $E --lanes 32 --members 1 1000 10000 --out "$OUT/bench_blocks.json" "$@" 2>&1 | grep 'cuda:0' | grep -v '{' | sed "s/^/block $k: /"
        $E --lanes 32 --members 10000 --front-events contact --out "$OUT/bench_blocks.json" "$@" 2>&1 | grep 'cuda:0' | grep -v '{' | sed "s/^/block $k: /"
        $E --lanes 32 --members 10000 --relaxation-gate none --out "$OUT/bench_blocks.json" "$@" 2>&1 | grep 'cuda:0' | grep -v '{' | sed "s/^/block $k: /"
      done
    done
    unset WARPFRIC_TEAM_BLOCK_MEMBERS WARPFRIC_TEAM_SHARED_WORK
    WARPFRIC_TEST_DEVICE=cuda:0 python3 -m pytest -q -p no:cacheprovider tests/test_team.py 2>&1 | tee "$OUT/tests_team_cuda.log" | tail -3 ;;
  exchange)
    (cd studies && python3 team_exchange.py --members 1000 "$@") 2>&1 | tee "$OUT/team_exchange.txt" | tail -9
    WARPFRIC_TEAM_EXCHANGE=tile $E --members 1 10000 --relaxation-gate stress --lanes 32 --out "$OUT/bench_tile.json" 2>&1 \
      | tail -3
    $E --members 1 10000 --relaxation-gate stress --lanes 32 --out "$OUT/bench_shuffle.json" 2>&1 | tail -3 ;;
  wide)
    python3 studies/team_lanes.py --nodes 200 --lanes 1 32 64 96 2>&1 | tee "$OUT/team_lanes_n200.txt" | tail -4
    for round in 1 2; do
      $E --members 1 100 --lanes 32 64 96 --repeat 5 --out "$OUT/bench_wide.json" 2>&1 | grep -v '^{' | tail -6
      $E --members 133 264 528 --lanes 32 96 --repeat 3 --out "$OUT/bench_wide_members.json" 2>&1 | grep -v '^{' | tail -6
      $E --members 1 --nodes 400 --lanes 32 64 128 192 --repeat 3 --out "$OUT/bench_wide_n400.json" 2>&1 \
        | grep -v '^{' | tail -4
    done ;;
  ncu-sources)
    NCU=$(ncu_bin); echo "ncu: $NCU"
    "$NCU" -k regex:integrate --launch-skip 2 --launch-count 1 --section SourceCounters --section WarpStateStats \
      --import-source yes -o "$OUT/one_member_sources" python3 studies/bench.py --jsonl "$JSONL" one-member --times 2 --lineinfo \
      > "$OUT/ncu_sources.log" 2>&1
    "$NCU" -i "$OUT/one_member_sources.ncu-rep" --page details --section SourceCounters > "$OUT/source_counters.txt" 2>&1
    head -c 3000 "$OUT/source_counters.txt" ;;
  dask)
    # 2 GPUs: the same sweep file in one process on cuda:0, then on a local Dask cluster with 1 and 2
    # workers; the combined files are compared with the one-process file bit for bit
    SWEEP=${1:-studies/sweeps/bench_200k.toml}
    python3 -c "import distributed, warp as wp; wp.config.quiet = True; wp.init(); print('distributed', distributed.__version__, 'gpus', wp.get_cuda_device_count())"
    run() {  # label, extra options
      local label=$1; shift
      local t0=$(date +%s.%N)
      python3 -m warpfric run "$SWEEP" -o "$OUT/$label.nc" "$@" 2>&1 | tee "$OUT/$label.log" | grep -v "^Warp\|^   " | grep -v "chunks done" | tail -4
      echo "$label: $(python3 -c "print(f'{$(date +%s.%N) - $t0:.1f}')") s wall (process start to exit)" | tee -a "$OUT/times.txt"
    }
    run plain --device cuda:0
    run dask1 --local-cluster --workers 1
    run dask2 --local-cluster --workers 2
    python3 - "$OUT" <<'PY'
import sys, numpy as np, xarray as xr
out = sys.argv[1]
ref = xr.open_dataset(f"{out}/plain.nc").load()
for label in ("dask1", "dask2"):
    ds = xr.open_dataset(f"{out}/{label}.nc").load()
    same = all(np.array_equal(ref[v].values, ds[v].values, equal_nan=ref[v].dtype.kind == "f") for v in ref.variables)
    print(f"{label}: outputs equal to the single-process run bit for bit: {same}; members {ds.sizes['member']}, "
          f"ok {int((ds.status.values == 0).sum())}")
PY
    rm -f "$OUT"/plain.nc "$OUT"/dask1.nc "$OUT"/dask2.nc
    cat "$OUT/times.txt" ;;
  footprint)
    NCU=$(ncu_bin); echo "ncu: $NCU"
    metrics=dram__bytes_read.sum,dram__bytes_write.sum,lts__t_sector_hit_rate.pct,gpu__time_duration.sum
    metrics=$metrics,l1tex__t_sector_pipe_lsu_mem_global_op_ld_hit_rate.pct,smsp__inst_executed.sum
    metrics=$metrics,l1tex__t_sector_pipe_lsu_mem_local_op_ld_hit_rate.pct,launch__grid_size
    # footprint_row TAG MEMBERS LANES BLOCK_MEMBERS (empty: the engine's choice): the first launch
    # after the benchmark's one-member warm-up
    footprint_row() {
      env ${4:+WARPFRIC_TEAM_BLOCK_MEMBERS=$4} "$NCU" -k regex:integrate --launch-skip 3 --launch-count 1 \
        --metrics "$metrics" python3 studies/bench_engine.py --device cuda:0 --dtypes float64 --members "$2" \
        --lanes "$3" --repeat 1 --steps-per-launch 100 --out "$OUT/footprint_$1.json" > "$OUT/footprint_$1.txt" 2>&1
      python3 - "$1" "$OUT/footprint_$1.txt" <<'PY'
import re, sys
units = {"byte": 1e-9, "Kbyte": 1e-6, "Mbyte": 1e-3, "Gbyte": 1.0, "Tbyte": 1e3}
v = {}
for line in open(sys.argv[2]):
    m = re.match(r"\s+(\S+)\s+(\S+)?\s+([\d,.]+)\s*$", line)
    if m:
        v[m.group(1)] = float(m.group(3).replace(",", "")) * units.get(m.group(2) or "", 1.0)
g = lambda k: v.get(k, float("nan"))
print(f"{sys.argv[1]:>14s} {g('gpu__time_duration.sum'):9.2f} {g('dram__bytes_read.sum'):8.2f} "
      f"{g('dram__bytes_write.sum'):8.2f} {g('lts__t_sector_hit_rate.pct'):7.2f} "
      f"{g('l1tex__t_sector_pipe_lsu_mem_global_op_ld_hit_rate.pct'):7.2f} "
      f"{g('l1tex__t_sector_pipe_lsu_mem_local_op_ld_hit_rate.pct'):7.2f} {g('smsp__inst_executed.sum'):10.4g} "
      f"{g('launch__grid_size'):6.0f}")
PY
    }
    echo "           row   launch ms  DRAM rd GB  wr GB  L2 hit  L1 gl  L1 stack  warp instr  blocks"
    for block in 8 6 4 2; do footprint_row "10000_b$block" 10000 32 "$block"; done
    footprint_row 10000_l64 10000 64 ""
    for members in 1056 528 264; do footprint_row "${members}_b8" "$members" 32 8; done
    # the same rows timed (8 members a block is the engine's own choice at 10,000 members)
    for block in 8 6 4 2; do
      WARPFRIC_TEAM_BLOCK_MEMBERS=$block $E --members 10000 --lanes 32 --repeat 2 --out "$OUT/footprint_b$block.json"
    done > "$OUT/footprint_times.log" 2>&1
    $E --members 10000 --lanes 64 --repeat 2 --out "$OUT/footprint_l64.json" >> "$OUT/footprint_times.log" 2>&1
    grep -E "^ *[0-9]+ +[0-9]+ +float" "$OUT/footprint_times.log" ;;
  figures)
    python3 studies/figures.py all --device cuda:0 --outdir "$OUT/figures" "$@" 2>&1 | tee "$OUT/figures_gpu.log" | tail -12 ;;
  *)
    awk 'NR > 1 && /^#/ { print } NR > 1 && !/^#/ { exit }' "$0"; exit 2 ;;
esac
