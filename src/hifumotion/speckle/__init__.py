"""Speckle tracking: the motion of the tissue's material points in a B-mode cine loop.

* :func:`displacement` — the Lagrangian displacement of frame 0's pixels at every frame,
  with a per-pixel quality (:mod:`.displacement`);
* :func:`follow` — the frame-0 contour carried by that displacement and refined by GLCV
  in a narrow band (:mod:`.follow`).
"""

from hifumotion.speckle.displacement import DisplacementSeries, SpeckleTracker, displacement, local_ncc, sample_field
from hifumotion.speckle._speckle_size import speckle_fwhm_px
from hifumotion.speckle.follow import FollowResult, carry_contour, follow, segment_target
from hifumotion.speckle.points import PointTrack, PointTracker, track_points

__all__ = ["DisplacementSeries", "FollowResult", "PointTrack", "PointTracker", "track_points", "SpeckleTracker", "carry_contour", "displacement", "follow",
           "local_ncc", "sample_field", "segment_target", "speckle_fwhm_px"]
