"""hifumotion: keep a HIFU focus on a target tissue that moves and deforms.

The package follows Liao et al., "Modeling and Predicting Tissue Movement and
Deformation for HIFU Therapy" (PLoS ONE): segment the target in B-mode images
with level sets, reconstruct a 3D tissue model, simulate tissue, water and a
pushing bar with a particle framework, estimate the unknown parameters from
training frames and predict the contours of later frames.

Units: millimetres and seconds at every public interface; SI inside the
physics kernels. Each quantity's unit is in its name or its docstring.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("hifumotion")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

from hifumotion._lazy import lazy_exports  # noqa: E402
from hifumotion.errors import HifuError, InputError  # noqa: E402

# the image and contour types are imported on first use: they pull SciPy and Numba, which a
# command's ``--help`` or a configuration's validation should not wait for
_LAZY = {"ImageSequence": "hifumotion.sequence", "Contour": "hifumotion.contour", "Ellipse": "hifumotion.contour",
         "ClickedPoints": "hifumotion.contour"}


__getattr__ = lazy_exports(__name__, _LAZY)


__all__ = [
    "__version__",
    "HifuError",
    "InputError",
    "ImageSequence",
    "Contour",
    "Ellipse",
    "ClickedPoints",
]
