#!/bin/bash
# Session 6 on the GPU host (issue 13): predicted gate switches and the queued launches, timed with
# studies/bench_engine.py (N = 200, rtol 1e-5, float64, stress gate, compile excluded).
#   export PYTHONPATH=/tmp/site:$PWD; bash studies/gpu_session6.sh team|thread|more
# team:   the cooperative kernel (32 lanes), predicted switches on and off, 1 / 1,000 / 10,000 members;
#         then the queued launches on the GPU: chunks of 7 and of 100,000 attempts, outputs compared bit for bit
# thread: the thread-per-member kernel, the same rows; and the host CPU for 1 / 4 / 16 members
# more:   the cooperative kernel with fronts (10,000 members) and at 100,000 members
# accuracy: the team rows at rtol 1e-4
# esdirk4 METHOD: work against error of one integrator (tr_bdf2 or esdirk4) on the cooperative kernel,
#         gate-less law, rtol 1e-5 / 1e-6 / 1e-7, 1 and 10,000 members
# profile: where one member's time goes (cooperative kernel, 32 lanes): its attempts and time per
#         attempt at N = 64..800, and Nsight Compute's warp stall reasons for the one-member launch
set -u
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
B="python -u studies/bench_engine.py --dtypes float64 --relaxation-gate stress"
case "$1" in
team)
  timeout 420 $B --device cuda:0 --members 1 1000 10000 --lanes 32 --predict-switches on off \
    --out "$OUT/bench_team_stress.json" 2>&1 | tail -6
  timeout 120 python -u - <<'PY' 2>&1 | tail -3 | tee "$OUT/queued_launches_check.txt"
import numpy as np, warpfric as wf
m = {"eccentricity": np.linspace(-0.2, 0.2, 64), "normal_force": np.geomspace(500, 5000, 64)}
runs = [wf.simulate(m, solver=wf.Solver(nodes=200, steps_per_launch=k), fronts=wf.Fronts(), device="cuda:0", progress=False)
        for k in (100_000, 7)]
bad = [v for v in runs[0].data_vars if np.issubdtype(runs[0][v].dtype, np.number)
       and not np.array_equal(runs[0][v].values, runs[1][v].values, equal_nan=True)]
print("queued launches, chunks of 7 vs 100000 attempts, lanes", runs[0].attrs["lanes"], ": differing outputs:", bad or "none",
      "| ok members:", int((runs[1].status.values == 0).sum()), "of 64")
PY
  ;;
thread)
  timeout 400 $B --device cuda:0 --members 1 1000 10000 --lanes 1 --predict-switches on off \
    --out "$OUT/bench_thread_stress.json" 2>&1 | tail -6
  timeout 150 $B --device cpu --members 1 4 16 --lanes 1 --out "$OUT/bench_hostcpu_stress.json" 2>&1 | tail -4
  ;;
more)
  timeout 300 $B --device cuda:0 --members 10000 --lanes 32 --fronts --out "$OUT/bench_team_stress_fronts.json" 2>&1 | tail -2
  timeout 250 $B --device cuda:0 --members 100000 --lanes 32 --out "$OUT/bench_team_stress_100k.json" 2>&1 | tail -2
  ;;
profile)
  timeout 600 python -u - <<'PY' 2>&1 | tail -8 | tee "$OUT/n_scan.txt"
import time, warpfric as wf
kw = dict(device="cuda:0", progress=False, fronts=None)
wf.simulate(solver=wf.Solver(nodes=64, lanes=32), **kw)  # compile
print(f"{'N':>5} {'wall s':>8} {'attempts':>8} {'newton':>7} {'us/attempt':>10} {'us/newton':>9}")
for n in (64, 128, 200, 400, 800):
    best = 1e9
    for _ in range(3):
        t0 = time.perf_counter(); ds = wf.simulate(solver=wf.Solver(nodes=n, lanes=32), **kw); best = min(best, time.perf_counter() - t0)
    att = int(ds.steps_accepted[0] + ds.steps_rejected[0]); nw = int(ds.newton_iterations[0])
    print(f"{n:5d} {best:8.3f} {att:8d} {nw:7d} {1e6 * best / att:10.1f} {1e6 * best / nw:9.1f}")
PY
  NCU=$(command -v ncu || ls /usr/local/cuda*/bin/ncu 2>/dev/null | head -1)
  cat > /tmp/one_member.py <<'PY'
import warpfric as wf
for _ in range(2):
    wf.simulate(solver=wf.Solver(nodes=200, lanes=32), device="cuda:0", progress=False, fronts=None)
PY
  timeout 240 "$NCU" -k regex:integrate --launch-skip 2 --launch-count 1 \
    --section LaunchStats --section Occupancy --section WarpStateStats --section ComputeWorkloadAnalysis \
    --section MemoryWorkloadAnalysis --section SchedulerStats --section InstructionStats \
    --metrics regex:smsp__average_warps_issue_stalled_.*_per_issue_active\.ratio,gpu__time_duration.sum,smsp__inst_executed.sum \
    python /tmp/one_member.py > "$OUT/ncu_one_member_stress_l32.txt" 2>&1
  grep -E "Duration|Warp Cycles Per Issued|Issued Ipc|stalled_.*ratio|inst_executed.sum|Local Memory|Registers Per|Stack" \
    "$OUT/ncu_one_member_stress_l32.txt" | awk '$NF+0 > 0.05 || !/stalled/' | head -40
  ;;
accuracy)  # the issue's accuracy (mu_s within 1e-4): rtol 1e-4
  timeout 400 $B --device cuda:0 --members 1 1000 10000 --lanes 32 --rtol 1e-4 --out "$OUT/bench_team_stress_rtol1e-4.json" 2>&1 | tail -4
  ;;
esdirk4)
  for r in 1e-5 1e-6 1e-7; do
    timeout 500 python -u studies/bench_engine.py --dtypes float64 --relaxation-gate none --device cuda:0 --members 1 10000 \
      --lanes 32 --methods "$2" --rtol $r --out "$OUT/bench_team_none_$2_$r.json" 2>&1 | tail -2
  done
  ;;
sources)  # Nsight Compute's stall sampling by source line of the one-member launch (kernels compiled with line info)
  NCU=$(command -v ncu || ls /usr/local/cuda*/bin/ncu 2>/dev/null | head -1)
  cat > /tmp/one_member_lines.py <<'PY'
import warp as wp
wp.config.lineinfo = True
import warpfric as wf
for _ in range(2):
    wf.simulate(solver=wf.Solver(nodes=200, lanes=32), device="cuda:0", progress=False, fronts=None)
PY
  timeout 550 "$NCU" -k regex:integrate --launch-skip 2 --launch-count 1 --section SourceCounters --section WarpStateStats \
    --import-source yes -o "$OUT/one_member_sources" python /tmp/one_member_lines.py > "$OUT/ncu_sources.log" 2>&1
  tail -3 "$OUT/ncu_sources.log"
  "$NCU" -i "$OUT/one_member_sources.ncu-rep" --page source --csv --print-source cuda 2> /dev/null > "$OUT/source_lines.csv"
  "$NCU" -i "$OUT/one_member_sources.ncu-rep" --page details --section SourceCounters > "$OUT/source_counters.txt" 2>&1
  ls -la "$OUT"; head -c 3000 "$OUT/source_counters.txt"
  ;;
esac
