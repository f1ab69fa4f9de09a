"""The synthetic HIFU experiment: a digital twin of the paper's cow-tissue experiment.

The paper's data cannot be had, so this package makes an equivalent experiment
whose truth is known (Section 3.2, Fig. 1): a seeded irregular tissue sample in
a water pool, pushed by a hand-held metal bar, simulated with the particle
framework at a finer resolution than the model that will be fitted to it,
and imaged with the B-mode simulator — a spatial sweep at rest, a time series
of one plane during the push, a clinician's rough contour on the first frame.

>>> from hifumotion.experiment import twin_config, generate_twin
>>> result = generate_twin(twin_config("small", seed=1), "twin")   # doctest: +SKIP

``observed/`` holds what a device's user has; ``truth/`` what only scoring may read.
"""

from hifumotion.experiment.blob import Blob
from hifumotion.experiment.config import PRESETS, TwinConfig, twin_config
from hifumotion.experiment.stored import StoredTwin, bundled_twin, read_twin
from hifumotion.experiment.twin import TwinResult, generate_twin, motion_summary, resolution, summary_line

__all__ = ["Blob", "PRESETS", "TwinConfig", "twin_config", "TwinResult", "generate_twin", "motion_summary",
           "resolution", "summary_line", "StoredTwin", "bundled_twin", "read_twin"]
