"""Whether a determined value survives leaving the last training frames out.

A fit's standard errors (:func:`~.fit.uncertainty`: the Gauss–Newton covariance and the
delete-one-frame jackknife) measure how the training frames scatter about the fitted model. They
cannot see an error every frame shares — the fitted model's own form against the tissue's — and
a coordinate can then be "determined" many of its own standard errors from the truth
(docs/decisions.md, "A fit's standard errors count frames, not points": ν 5.4σ off on a reversal).

Where the predictor choice runs (:mod:`hifumotion.prediction.choice`) a second calibration
already exists, on the earlier training frames only. Under the errors the fit reports, the two
estimates differ by less than the earlier fit's own standard error: the later frames add data
(Var(θ_earlier − θ_all) = Var(θ_earlier) − Var(θ_all) for nested efficient fits, so the
earlier fit's σ bounds the difference's from above). A coordinate that moves by more than
:data:`LIMIT_SIGMA` of those when the last frames are added is not determined, whatever its
σ says: which frames are fitted decides its value. A block of frames in time, not one frame,
because a model-form error grows with the motion, and the motion grows with time.

Coordinates are those of :mod:`.space` (ln E, ν, ln β1, β2, ln μ_f).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: how many of the earlier fit's standard errors a determined coordinate may move when the last
#: training frames are added (the usual three-sigma consistency bound)
LIMIT_SIGMA = 3.0
#: each coordinate as the operator reads it (E and β1 are at the nominal force: F/E and β1/E)
LABELS = {"log_E": "F/E", "nu": "ν", "log_beta1": "β1/E", "beta2": "β2", "log_mu": "the friction μ_f"}


@dataclass(frozen=True)
class HoldoutShift:
    """The fit on every training frame against the fit on the earlier ones.

    Attributes
    ----------
    earlier_frames
        The training frames of the earlier fit.
    shift
        Coordinate → the fit's value minus the earlier fit's (coordinate units).
    earlier_std
        Coordinate → the earlier fit's standard error (inf: no data bound it).
    limit_sigma
        The bound on ``|shift| / earlier_std``.
    """

    earlier_frames: tuple[int, ...]
    shift: dict
    earlier_std: dict
    limit_sigma: float = LIMIT_SIGMA

    @property
    def shift_sigma(self) -> dict:
        """Coordinate → ``|shift|`` in the earlier fit's standard errors (0 where that is infinite)."""
        return {n: _in_sigma(d, self.earlier_std[n]) for n, d in self.shift.items()}

    @property
    def moved(self) -> list[str]:
        """The coordinates that moved by more than ``limit_sigma`` of the earlier fit's errors."""
        return [n for n, s in self.shift_sigma.items() if s > self.limit_sigma]

    def reason(self, name: str) -> str:
        return (f"it moves {self.shift_sigma[name]:.1f} standard errors of the fit on training frames "
                f"{self.earlier_frames[0]}–{self.earlier_frames[-1]} when the later frames are added "
                f"(more than {self.limit_sigma:g}): which frames are fitted decides it")

    def as_dict(self) -> dict:
        return {"earlier_frames": [self.earlier_frames[0], self.earlier_frames[-1]],
                "shift": self.shift, "earlier_std": self.earlier_std, "shift_sigma": self.shift_sigma,
                "limit_sigma": self.limit_sigma, "moved": self.moved}


def _in_sigma(shift: float, std: float) -> float:
    if np.isinf(std):        # no data bound the earlier fit: any move is within its error
        return 0.0
    if std > 0:
        return abs(shift) / std
    return 0.0 if shift == 0 else float("inf")


def holdout_shift(theta: dict, earlier_theta: dict, earlier_std: dict, earlier_frames,
                  limit_sigma: float = LIMIT_SIGMA) -> HoldoutShift:
    """Compare the fit ``theta`` (coordinate → value) with the fit on ``earlier_frames`` only
    (``earlier_theta``, its standard errors ``earlier_std``), coordinate by coordinate on the
    coordinates both have."""
    names = [n for n in theta if n in earlier_theta and n in earlier_std]
    if not names:
        raise ValueError("the two fits share no coordinate")
    frames = tuple(sorted(int(f) for f in earlier_frames))
    if not frames:
        raise ValueError("the earlier fit has no training frames")
    return HoldoutShift(frames, {n: float(theta[n]) - float(earlier_theta[n]) for n in names},
                        {n: float(earlier_std[n]) for n in names}, float(limit_sigma))


__all__ = ["LABELS", "LIMIT_SIGMA", "HoldoutShift", "holdout_shift"]
