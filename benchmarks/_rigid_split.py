"""The difference of two point sets that moved from the same rest points, split three ways.

Used by the benchmarks that compare a model's (or a variant truth's) motion with a twin's
truth: how much of the difference is a common shift (the sample slid too far or too little),
how much is left without that shift, how much is left once the best rigid motion of one set
onto the other is removed (Kabsch: the shape's own error), and the angle of that rigid turn.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def split_difference(moved_mm: np.ndarray, truth_mm: np.ndarray) -> dict:
    """``moved_mm`` and ``truth_mm``: (n, 3) positions of the same n material points (mm).

    Returns µm figures: ``rms_um`` (the whole difference), ``shift_um`` (the norm of its mean),
    ``without_shift_um``, ``without_rigid_motion_um``, the turn between the two in degrees
    (``turn_deg``) and its rotation vector (``turn_vector_deg``: the axis times the angle,
    taking ``moved_mm`` onto ``truth_mm``)."""
    diff = moved_mm - truth_mm
    mean = diff.mean(axis=0)
    cm, ct = moved_mm.mean(axis=0), truth_mm.mean(axis=0)
    w, _, vt = np.linalg.svd((moved_mm - cm).T @ (truth_mm - ct))
    d = np.sign(np.linalg.det(w @ vt))
    turn = (w @ np.diag([1.0, 1.0, d]) @ vt).T
    rigid = ((moved_mm - cm) @ turn.T + ct) - truth_mm
    return {"rms_um": float(np.sqrt((diff ** 2).sum(1).mean()) * 1000),
            "shift_um": float(np.linalg.norm(mean) * 1000),
            "without_shift_um": float(np.sqrt(((diff - mean) ** 2).sum(1).mean()) * 1000),
            "without_rigid_motion_um": float(np.sqrt((rigid ** 2).sum(1).mean()) * 1000),
            "turn_deg": float(np.degrees(np.arccos(np.clip((np.trace(turn) - 1) / 2, -1.0, 1.0)))),
            "turn_vector_deg": np.degrees(Rotation.from_matrix(turn).as_rotvec()).tolist()}

