export PYTHONPATH=/tmp/site:$PWD
OUT=${OUT:-out}; mkdir -p $OUT
C=9838f22
nvidia-smi --query-gpu=name --format=csv,noheader
python3 -m warpfric run --device cuda:0 > $OUT/run_cuda_$C.txt 2>&1; tail -5 $OUT/run_cuda_$C.txt
WARPFRIC_TEST_DEVICE=cuda:0 timeout 330 python3 -m pytest -q -p no:cacheprovider tests/test_trust.py tests/test_fronts.py tests/test_plots.py "tests/test_gate.py::test_a_disc_stopped_before_it_slid_the_peak_travel_ends_at_the_stop" > $OUT/tests_cuda_$C.txt 2>&1; tail -2 $OUT/tests_cuda_$C.txt
WARPFRIC_COMMIT=$C timeout 200 python3 studies/bench_engine.py --device cuda:0 --dtypes float64 --members 1 10000 --repeat 2 --out /tmp/b.json --jsonl $OUT/bench_$C.jsonl > $OUT/bench_$C.txt 2>&1; tail -8 $OUT/bench_$C.txt
