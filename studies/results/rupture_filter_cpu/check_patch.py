import os, warp as wp
if os.environ.get("WF_CACHE"): wp.config.kernel_cache_dir = os.environ["WF_CACHE"]
import warpfric as wf, warpfric.kernels.esdirk as E, inspect, warnings
print(wf.__file__, E.__file__)
src = inspect.getsource(E)
print([l for l in src.splitlines() if "DIAGNOSTIC" in l])
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    ds = wf.simulate({"viscous_coefficient": [0.0]}, scene=wf.Parameters(end_time=20.6), solver=wf.Solver(nodes=25, rtol=1e-5, max_steps=10**6, stall_factor=float("inf")), device="cpu", progress=False, workers=1)
print(int(ds.steps_accepted[0]), int(ds.steps_rejected[0]))
