#!/usr/bin/env bash
# Issue 14's benchmark on a host with 2 GPUs (the lent nvidia-h200-x2), after the Warp install of
# shared/device/README.md, carrying .dask_wheels/ (pip download of distributed + dask for Python 3.12):
#   bash studies/gpu_dask_bench.sh [SWEEP]
# The same sweep file (default studies/sweeps/bench_200k.toml: 200,000 members) run (1) in one process
# on cuda:0, (2) on a local Dask cluster with 1 worker (cuda:0), (3) with 2 workers (cuda:0, cuda:1);
# the combined files of (2) and (3) are compared with (1) bit for bit. Logs under $OUT.
set -uo pipefail
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
OUT=${OUT:-out}; mkdir -p "$OUT"
SWEEP=${1:-studies/sweeps/bench_200k.toml}
WHEELS=${DASK_WHEELS:-.dask_wheels}; python3 -m pip install -q --no-index --no-deps --target /tmp/site "$WHEELS"/*.whl 2>&1 | tail -2
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
rm -f "$OUT"/*.nc
cat "$OUT/times.txt"
