#!/usr/bin/env bash
# The Sobol study of studies/README.md ("Sensitivity") on a GPU host: a 163,840-member Saltelli
# design (studies/sweeps/sensitivity_gpu.toml, the default front event: the contact front, read front
# by front), then the indices of mu_s, mu_s_time and the front speeds. Needs warpfric and SALib
# importable by $PYTHON (e.g. PYTHON=.venv/bin/python with the [sensitivity] extra); where they are
# not, from /tmp/site, the repository and ./.salib (a host without a package index, as the lent GPU
# hosts: a copy of SALib, multiprocess and dill from a venv with the [sensitivity] extra). Results under $OUT;
# sensitivity_members.nc keeps every member's inputs and scalar outputs (the design's rows), so that
# `warpfric sensitivity` can be run again elsewhere without the simulation.
#   bash studies/sensitivity_study.sh
set -uo pipefail
OUT=$(realpath -m "${OUT:-out}")  # where it was started (default ./out), before the cd
cd "$(dirname "$0")/.."  # the repository root: the sweep file's path below is relative to it
PYTHON=${PYTHON:-python3}  # e.g. PYTHON=.venv/bin/python where warpfric[sensitivity] is installed
if ! $PYTHON -c "import warpfric, SALib" 2>/dev/null; then  # the copies of a host without a package index
  export PYTHONPATH=/tmp/site:$PWD:$PWD/.salib:/tmp/salib${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONUNBUFFERED=1
mkdir -p "$OUT"
start=$SECONDS
$PYTHON -m warpfric run studies/sweeps/sensitivity_gpu.toml -o /tmp/sens.nc --device cuda:0 --overwrite 2>&1 \
  | tee "$OUT/sensitivity_run.log" | tail -4
echo "run command: $((SECONDS - start)) s (kernel compilation and netCDF writing included)" | tee -a "$OUT/sensitivity_run.log"
$PYTHON -m warpfric info /tmp/sens.nc 2>&1 | tee "$OUT/sensitivity_info.log"
$PYTHON - "$OUT/sensitivity_members.nc" <<'PY'
import json, sys
import warpfric as wf
ds = wf.io.open_ensemble("/tmp/sens.nc")
names = json.loads(ds.attrs["sensitivity_design"])["names"]
outputs = ["status", "mu_s", "mu_s_time", "front_count", "v_first", "v_second", "v_middle", "v_left", "v_right"]
wf.io.write_ensemble(ds[names + outputs].drop_vars("member_id"), sys.argv[1])
PY
$PYTHON -m warpfric sensitivity /tmp/sens.nc --output mu_s --output mu_s_time -o "$OUT/sensitivity_gpu.nc" 2>&1 \
  | tee "$OUT/sensitivity_indices.log"
# front speeds are heavy-tailed (a front that detaches nearly at once has a huge speed): log; members
# without a second front (or a segment) are filled with the mean (counted in the output)
$PYTHON -m warpfric sensitivity /tmp/sens.nc --output v_first --output v_second --output v_middle --log \
  --on-failure fill-mean -o "$OUT/sensitivity_gpu_fronts.nc" 2>&1 | tee -a "$OUT/sensitivity_indices.log"
# whether a second front exists: the indices of front_count (1, 2 or 3)
$PYTHON -m warpfric sensitivity /tmp/sens.nc --output front_count -o "$OUT/sensitivity_gpu_front_count.nc" 2>&1 \
  | tee -a "$OUT/sensitivity_indices.log"
