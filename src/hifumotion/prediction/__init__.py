"""Where the target will be: the fitted model run forward and every predictor it is measured against.

- :mod:`.physics` — the fitted model's sections and aim point (Section 2.2, Table 4);
  :mod:`.pipeline` — from a calibration folder to ``prediction/``; :mod:`.band` — the aim with the
  fit moved along its least determined direction;
- :mod:`.online` — the online loop: each tracked frame assimilated by the reduced model, t + k
  predicted (the Discussion's estimation and prediction "carried out consecutively and
  repetitively"); :mod:`.assimilate` — its filter;
- the peers that know the same inputs: :mod:`.baselines` (holding still, the constant-velocity
  Kalman filter, NCC), :mod:`.surrogates` (regressions on the announced drive, offline and online);
  :mod:`.choice` — which predictor the training frames support; :mod:`.evaluate` — every one
  scored against a truth; :mod:`.masks` — moving a seen section by a sub-pixel shift.
"""

from hifumotion.prediction.baselines import (hold_last, kalman_predict, ncc_shift, ncc_track, star_descriptor,
                                             star_mask)

__all__ = ["hold_last", "kalman_predict", "ncc_shift", "ncc_track", "star_descriptor", "star_mask"]
