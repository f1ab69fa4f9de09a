"""Contour prediction: the physics-based predictor (issue 8, in progress) and its baselines."""

from hifumotion.prediction.baselines import (hold_last, kalman_predict, ncc_shift, ncc_track, star_descriptor,
                                             star_mask)

__all__ = ["hold_last", "kalman_predict", "ncc_shift", "ncc_track", "star_descriptor", "star_mask"]
