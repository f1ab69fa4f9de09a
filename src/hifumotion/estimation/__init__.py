"""Estimate the particle model's parameters from an observed push (the paper's Section 2.2.2).

One order, each step usable alone: :func:`~.prepare.prepare` (segment the sweep,
reconstruct, track the frames) → :func:`~.model.model_spec` (the particle scene at the
paper's resolution) → :func:`~.calibrate.calibrate` (search on Dask: least squares,
CMA-ES or the paper's Table 1; space mapping to the final model; uncertainty) →
:func:`~.store.save_calibration`. Prediction is :mod:`hifumotion.prediction`.
"""

from hifumotion.estimation.model import ModelRun, ModelSettings, ModelSpec, Parameters, model_spec, run_model
from hifumotion.estimation.objective import TrainingData, frame_sums_mm, residuals_mm
from hifumotion.estimation.prepare import Observation, prepare
from hifumotion.estimation.protocol import default_frames

__all__ = ["ModelRun", "ModelSettings", "ModelSpec", "Parameters", "model_spec", "run_model", "TrainingData",
           "frame_sums_mm", "residuals_mm", "Observation", "prepare", "default_frames"]
