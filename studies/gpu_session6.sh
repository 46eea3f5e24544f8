#!/bin/bash
# Session 6 on the GPU host (issue 13): predicted gate switches and the queued launches, timed with
# studies/bench_engine.py (N = 200, rtol 1e-5, float64, stress gate, compile excluded).
#   export PYTHONPATH=/tmp/site:$PWD; bash studies/gpu_session6.sh team|thread|more
# team:   the cooperative kernel (32 lanes), predicted switches on and off, 1 / 1,000 / 10,000 members;
#         then the queued launches on the GPU: chunks of 7 and of 100,000 attempts, outputs compared bit for bit
# thread: the thread-per-member kernel, the same rows; and the host CPU for 1 / 4 / 16 members
# more:   the cooperative kernel with fronts (10,000 members) and at 100,000 members
set -u
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
B="python -u studies/bench_engine.py --dtypes float64 --relaxation-gate stress"
case "$1" in
team)
  timeout 420 $B --device cuda:0 --members 1 1000 10000 --lanes 32 --predict-switches on off \
    --out "$OUT/bench_team_stress.json" 2>&1 | tail -6
  timeout 120 python -u - <<'PY' 2>&1 | tail -3
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
esac
