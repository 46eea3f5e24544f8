"""Warp's start-up and the choice of device, shared by every module that launches kernels
(warpfric.simulate, warpfric.fronts, the CPU worker pool and the sweep runner), so that none of
them imports another for it."""

from __future__ import annotations

# device=None runs ensembles up to this size on the CPU. A lone member is a serial chain of steps
# that a CPU core and the GPU's team of lanes run about as fast (H100: 0.038 s against 0.039 s on a
# core of its host, the benchmark's first member, N = 200, the contact front), and a process that
# never touches the GPU starts ~0.3 s sooner; from two members on the GPU's time barely grows while
# the core's doubles with each doubling (2 / 16 / 64 members: 0.042 / 0.037 / 0.054 s against
# 0.106 / 0.453 / 1.939 s). studies/device_crossover.py, docs/performance.md "Where device=None runs"
SMALL_ENSEMBLE = 1


def init_warp():
    """Import and initialise Warp quietly (no per-kernel load lines); returns the module."""
    import warp as wp

    wp.config.quiet = True
    if wp.config.log_level < wp.LOG_WARNING:  # no per-kernel "Module ... load" lines
        wp.config.log_level = wp.LOG_WARNING
    wp.init()
    return wp


def default_device(n_members: int | None = None) -> str:
    """The device for ``device=None``: 'cpu' for a lone member (SMALL_ENSEMBLE), else 'cuda:0' when
    Warp sees a CUDA device, else 'cpu'. Pass a device to force either."""
    wp = init_warp()
    if n_members is not None and n_members <= SMALL_ENSEMBLE:
        return "cpu"
    return "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"


def check_device(device: str | None, n_members: int | None = None) -> str:
    """A device name Warp knows ('cpu', 'cuda:0', ...; 'cuda' means 'cuda:0'), or for None the
    default_device of an ensemble of n_members; ValueError naming the valid ones otherwise."""
    wp = init_warp()
    if device is None:
        return default_device(n_members)
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
