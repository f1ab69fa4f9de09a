"""Estimate the particle model's parameters from an observed push (the paper's Section 2.2.2).

One order, each step usable alone: :func:`~.prepare.prepare` (segment the sweep,
reconstruct, track the frames) → :func:`~.model.model_spec` (the particle scene at the
paper's resolution) → :func:`~.calibrate.calibrate` (search on Dask: least squares,
CMA-ES or the paper's Table 1; space mapping to the final model; uncertainty) →
:func:`~.store.save_calibration`. Prediction is :mod:`hifumotion.prediction`.
"""

from hifumotion._lazy import lazy_exports

# names → their modules, imported on first use (the forward model pulls the solvers)
_WHERE = {"ModelRun": "model", "ModelSettings": "settings", "ModelSpec": "model", "Parameters": "model",
          "model_spec": "model", "run_model": "model", "TrainingData": "objective", "frame_sums_mm": "objective",
          "residuals_mm": "objective", "Observation": "prepare", "prepare": "prepare", "default_frames": "protocol"}


__getattr__ = lazy_exports(__name__, _WHERE)
__all__ = sorted(_WHERE)
