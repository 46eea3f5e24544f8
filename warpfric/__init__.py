"""warpfric: batched GPU/CPU ensembles of the friction detachment of an eccentrically loaded pad
(Papangelo, Stingl, Hoffmann & Ciavarella 2014), on NVIDIA Warp."""

import importlib.util as _ilu
import os as _os
import sys as _sys

__version__ = "0.1.0"

# A worker process that warpfric's local Dask cluster is starting (warpfric.runner.STARTING_WORKER
# holds the command's pid): a terminal's Ctrl-C, or a batch system's SIGTERM to the job's processes,
# reaches it too, and the command, its parent, stops it; both ignored from here on, before the
# imports below, so that it does not die mid-import (warpfric.cluster_worker ignores them once the
# worker has started)
if _os.environ.get("WARPFRIC_STARTING_CLUSTER_WORKER") == str(_os.getppid()):
    import signal as _signal

    _signal.signal(_signal.SIGINT, _signal.SIG_IGN)
    _signal.signal(_signal.SIGTERM, _signal.SIG_IGN)


def _attach_kernels():
    """The Warp kernels live in the top-level folder kernels/. An install maps it to
    warpfric.kernels (pyproject.toml); in a plain source checkout (PYTHONPATH=repo) load it from
    there under the same name."""
    if _ilu.find_spec("warpfric.kernels") is not None:
        return
    src = _os.path.join(_os.path.dirname(_os.path.dirname(_os.path.abspath(__file__))), "kernels")
    spec = _ilu.spec_from_file_location(
        "warpfric.kernels", _os.path.join(src, "__init__.py"), submodule_search_locations=[src]
    )
    module = _ilu.module_from_spec(spec)
    _sys.modules["warpfric.kernels"] = module
    spec.loader.exec_module(module)


_attach_kernels()

from .parameters import PARAMETER_NAMES, Fronts, Model, Parameters, Record, Solver  # noqa: E402
from .device import default_device  # noqa: E402
from .simulate import simulate  # noqa: E402

# the documented submodules, imported on first use so that `import warpfric` stays light:
# `wf.io.write_ensemble(...)` works after `import warpfric as wf` alone (PEP 562)
_SUBMODULES = ("fronts", "io", "plots", "sensitivity", "sweep")


def __getattr__(name: str):
    if name in _SUBMODULES:
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'warpfric' has no attribute {name!r}")


__all__ = ["Parameters", "Model", "Solver", "Fronts", "Record", "simulate", "default_device", "PARAMETER_NAMES", "__version__"]
