"""Warp's start-up and the choice of device, shared by every module that launches kernels
(warpfric.simulate, warpfric.fronts, the CPU worker pool and the sweep runner), so that none of
them imports another for it."""

from __future__ import annotations

# device=None runs ensembles up to this size on the CPU where the GPU would run the cooperative
# kernel (float64, the automatic lanes). A lone member is a serial chain of steps that a CPU core and
# the GPU's team of lanes run about as fast (H100: 0.038 s against 0.039 s on a core of its host, the
# benchmark's first member, N = 200, the contact front), and a process that never touches the GPU
# starts ~0.3 s sooner; from two members on the GPU's time barely grows while the core's doubles
# with each doubling (2 / 16 / 64 members: 0.042 / 0.037 / 0.054 s against 0.106 / 0.453 / 1.939
# s). studies/device_crossover.py, docs/performance.md "Where device=None runs"
SMALL_ENSEMBLE = 1
# ... and up to this size where the GPU would run the thread-per-member kernel (float32,
# Solver(lanes=1), fewer than 16 nodes), in which one GPU thread takes a member's whole serial chain:
# with lanes=1 the same members take 0.606 / 1.080 / 1.175 / 1.425 s on the H100 for 1 / 16 / 32 / 64
# members against 0.042 / 0.432 / 0.853 / 2.574 s on a core of its host, warm (in fresh processes
# 2.31 / 2.80 / 3.41 / 3.17 s against 2.10 / 2.03 / 2.50 / 3.83 s): the crossover lies between 32 and 64
SMALL_ENSEMBLE_THREAD_KERNEL = 32


def init_warp():
    """Import and initialise Warp quietly (no per-kernel load lines); returns the module."""
    import warp as wp

    wp.config.quiet = True
    if wp.config.log_level < wp.LOG_WARNING:  # no per-kernel "Module ... load" lines
        wp.config.log_level = wp.LOG_WARNING
    wp.init()
    return wp


def cpu_ensemble_limit(solver=None) -> int:
    """The most members that ``device=None`` runs on the CPU: SMALL_ENSEMBLE where a GPU would run
    the cooperative kernel (float64 with the automatic lanes; ``solver`` None: the default
    Solver), SMALL_ENSEMBLE_THREAD_KERNEL where it would run the thread-per-member kernel."""
    if solver is None:
        return SMALL_ENSEMBLE
    from .engine import choose_lanes

    return SMALL_ENSEMBLE if choose_lanes(solver, "cuda:0") > 1 else SMALL_ENSEMBLE_THREAD_KERNEL


def default_device(n_members: int | None = None, solver=None) -> str:
    """The device for ``device=None``: 'cpu' for an ensemble of at most cpu_ensemble_limit(solver)
    members (a lone member; up to 32 where the GPU would run the thread-per-member kernel), else
    'cuda:0' when Warp sees a CUDA device, else 'cpu'. Pass a device to force either."""
    wp = init_warp()
    if wp.get_cuda_device_count() == 0 or (n_members is not None and n_members <= cpu_ensemble_limit(solver)):
        return "cpu"
    return "cuda:0"


def check_device(device: str | None, n_members: int | None = None, solver=None) -> str:
    """A device name Warp knows ('cpu', 'cuda:0', ...; 'cuda' means 'cuda:0'), or for None the
    default_device of an ensemble of n_members run with ``solver``; ValueError naming the valid ones
    otherwise."""
    wp = init_warp()
    if device is None:
        return default_device(n_members, solver)
    names = [str(d) for d in wp.get_devices()]
    if str(device) == "cuda" and wp.get_cuda_device_count() > 0:
        return "cuda:0"
    if str(device) not in names:
        asked_gpu = str(device).lower().startswith("cuda")
        gpus = "" if wp.get_cuda_device_count() > 0 or not asked_gpu else " (no CUDA GPU or driver found on this machine)"
        if str(device).lower() in names and str(device).lower() != str(device):
            gpus = f" (device names are lower case: {str(device).lower()!r})"
        raise ValueError(f"device {device!r} is not available{gpus}; valid: {', '.join(names)}, or None (Python; on "
                         "the command line, leave --device out): a GPU where there is one and the ensemble is large "
                         "enough, else the CPU")
    return str(device)
