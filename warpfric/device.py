"""Warp's start-up and the choice of device, shared by every module that launches kernels
(warpfric.simulate, warpfric.fronts, the CPU worker pool and the sweep runner), so that none of
them imports another for it."""

from __future__ import annotations

# device=None runs ensembles up to this size on the CPU: one member is a serial chain of dependent
# steps, which one CPU core runs ~30x faster than one GPU thread (H100: 0.58 s against 0.018 s, N =
# 200; docs/performance.md), and the GPU's time barely grows with the ensemble up to ~1,000 members,
# so the break-even lies near 30 members; 16 keeps the CPU side of it
SMALL_ENSEMBLE = 16


def init_warp():
    """Import and initialise Warp quietly (no per-kernel load lines); returns the module."""
    import warp as wp

    wp.config.quiet = True
    if wp.config.log_level < wp.LOG_WARNING:  # no per-kernel "Module ... load" lines
        wp.config.log_level = wp.LOG_WARNING
    wp.init()
    return wp


def default_device(n_members: int | None = None) -> str:
    """The device for ``device=None``: 'cpu' for an ensemble of at most SMALL_ENSEMBLE (16) members,
    else 'cuda:0' when Warp sees a CUDA device, else 'cpu'. Pass a device to force either."""
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
