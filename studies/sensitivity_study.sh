#!/usr/bin/env bash
# The Sobol study of studies/README.md ("Sensitivity") on a GPU host: a 163,840-member Saltelli
# design (studies/sweeps/sensitivity_gpu.toml), then the indices of mu_s, mu_s_time and the front
# speeds. Needs warpfric and SALib importable (here from /tmp/site and /tmp/salib, for a host
# without a package index). Results under $OUT.
#   bash studies/sensitivity_study.sh
set -uo pipefail
export PYTHONPATH=/tmp/site:$PWD:/tmp/salib PYTHONUNBUFFERED=1
OUT=${OUT:-out}; mkdir -p "$OUT"
start=$SECONDS
python3 -m warpfric run studies/sweeps/sensitivity_gpu.toml -o /tmp/sens.nc --device cuda:0 --overwrite 2>&1 \
  | tee "$OUT/sensitivity_run.log" | tail -4
echo "run command: $((SECONDS - start)) s (kernel compilation and netCDF writing included)" | tee -a "$OUT/sensitivity_run.log"
python3 -m warpfric info /tmp/sens.nc 2>&1 | tee "$OUT/sensitivity_info.log"
python3 -m warpfric sensitivity /tmp/sens.nc --output mu_s --output mu_s_time -o "$OUT/sensitivity_gpu.nc" 2>&1 \
  | tee "$OUT/sensitivity_indices.log"
# front speeds are heavy-tailed (a middle front that detaches at once has a huge speed): log, and
# members without a left/right front are filled with the mean (counted in the output)
python3 -m warpfric sensitivity /tmp/sens.nc --output v_middle --output v_left --output v_right --log \
  --on-failure fill-mean -o "$OUT/sensitivity_gpu_fronts.nc" 2>&1 | tee -a "$OUT/sensitivity_indices.log"
