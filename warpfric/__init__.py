"""warpfric: batched GPU/CPU ensembles of the friction detachment of an eccentrically loaded pad
(Papangelo, Stingl, Hoffmann & Ciavarella 2014), on NVIDIA Warp."""

__version__ = "0.1.0"

from .parameters import PARAMETER_NAMES, Model, Parameters, Solver  # noqa: E402
from .simulate import default_device, simulate  # noqa: E402

__all__ = ["Parameters", "Model", "Solver", "simulate", "default_device", "PARAMETER_NAMES", "__version__"]
