"""Example (untested here: we have no SLURM cluster): a warpfric sweep on a SLURM cluster with
dask-jobqueue, one single-GPU job per Dask worker.

    pip install "warpfric[distributed]" dask-jobqueue
    python studies/slurm_sweep.py studies/sweeps/map_gpu.toml map.nc --jobs 4 --queue gpu

Each job runs one worker with one thread on one GPU (SLURM sets CUDA_VISIBLE_DEVICES, so the
worker's GPU is cuda:0); the chunks of the sweep are Dask tasks, written into map.nc.parts/ as they
finish; if the client dies, `warpfric run SWEEP -o map.nc --resume` finishes the run (here or on a
new cluster). Adapt the resources (memory, walltime, account) to your site.
"""

import argparse
from pathlib import Path

import warpfric.sweep


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sweep")
    ap.add_argument("output")
    ap.add_argument("--jobs", type=int, default=2, help="SLURM jobs = Dask workers = GPUs")
    ap.add_argument("--queue", default="gpu")
    ap.add_argument("--walltime", default="02:00:00")
    ap.add_argument("--memory", default="32GB")
    ap.add_argument("--chunk", type=int, default=20000)
    args = ap.parse_args()
    from dask_jobqueue import SLURMCluster  # here, so that --help works without them
    from distributed import Client

    # one worker with one thread per job (cores=1); the chunk files must be on a filesystem every node sees
    cluster = SLURMCluster(queue=args.queue, cores=1, processes=1, memory=args.memory, walltime=args.walltime,
                           job_extra_directives=["--gres=gpu:1"])
    cluster.scale(jobs=args.jobs)
    client = Client(cluster)
    print("dashboard:", client.dashboard_link)
    client.wait_for_workers(args.jobs)
    report = warpfric.sweep.run(args.sweep, Path(args.output).resolve(), client=client, chunk=args.chunk, device="cuda:0",
                                resume=False)
    print(f"{len(report.chunks)} chunks, {report.failed_members} failed members, wrote {report.output}")
    client.close()
    cluster.close()


if __name__ == "__main__":
    main()
