#!/bin/bash
# every totals.py configuration of the report; log: /tmp/diag/totals.log
cd /tmp/diag
PY=/work/main/.venv/bin/python
{
for N in 25 50 100 200; do $PY totals.py $N; done
for N in 25 50 100 200; do for d in 1e4 1e5 1e6; do $PY totals.py $N $d; done; done
for N in 25 200; do $PY totals.py $N 0 none; done
# patched copies (velocity-error filter's g*J part scaled by S; /tmp/diag/wfcopy_S*/warpfric/kernels/esdirk.py)
WF_TAG=S64 PYTHONPATH=/tmp/diag/wfcopy_S64 $PY totals.py 25
WF_TAG=S16 PYTHONPATH=/tmp/diag/wfcopy_S16 $PY totals.py 50
WF_TAG=S4 PYTHONPATH=/tmp/diag/wfcopy_S4 $PY totals.py 100
WF_TAG=S0.015625 PYTHONPATH=/tmp/diag/wfcopy_S0.015625 $PY totals.py 200
for N in 25 200; do WF_TAG=S0 PYTHONPATH=/tmp/diag/wfcopy_S0 $PY totals.py $N; done
} 2>&1 | grep -v "CUDA warning" | tee /tmp/diag/totals.log
