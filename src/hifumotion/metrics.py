"""Segmentation and prediction scores: DSC, MSSD, Hausdorff distance (and HD95), centroid distance.

All functions take two masks of the same shape (non-zero = target). With
``spacing`` (a pixel size in mm, scalar or ``(row, col)``) distances are in mm
and MSSD in mm²; without it, in pixels and pixels².

Boundaries are compared as sub-pixel curves (the 0.5 iso-line of each mask, see
:func:`hifumotion.contour.mask_boundaries_px`), sampled uniformly in arc length,
and each sample's distance to the other boundary is the exact distance to its
nearest polyline segment. So a contour against itself scores exactly 0 and two
concentric circles score the difference of their radii, up to the polygonal
approximation of the curves.

References
----------
.. [1] Dice LR. Measures of the amount of ecologic association between species.
   Ecology 1945; 26(3): 297-302 (the paper's [36]).
.. [2] Dietenbeck T, Alessandrini M, Friboulet D, Bernard O. CREASEG: a free
   software for the evaluation of image segmentation algorithms based on
   level-set. ICIP 2010, 665-668 (the paper's [37]: MSSD and Hausdorff).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from hifumotion.contour import Contour, as_mask, mask_boundaries_px, resample_closed
from hifumotion.errors import InputError
from hifumotion.sequence import as_spacing_mm

#: Arc-length step of the boundary samples, as a fraction of the smallest pixel size.
SAMPLE_STEP_PX = 0.25


def _pair(a: Any, b: Any) -> tuple[np.ndarray, np.ndarray]:
    ma = as_mask(a, "first mask", require_foreground=False)
    mb = as_mask(b, "second mask", require_foreground=False)
    if ma.shape != mb.shape:
        raise InputError(f"masks differ in shape: {ma.shape} and {mb.shape}")
    return ma, mb


def _spacing(spacing: Any) -> tuple[float, float]:
    return as_spacing_mm(spacing, "spacing")


def dice(a: Any, b: Any) -> float:
    """Dice similarity coefficient ``2 |A ∩ B| / (|A| + |B|)`` of two masks, in [0, 1].

    Two empty masks are a perfect agreement (1.0); one empty mask scores 0.0.
    """
    ma, mb = _pair(a, b)
    total = int(ma.sum()) + int(mb.sum())
    if total == 0:
        return 1.0
    return 2.0 * float(np.logical_and(ma, mb).sum()) / total


def _curves_mm(mask: np.ndarray, spacing: tuple[float, float]) -> list[np.ndarray]:
    scale = np.array([spacing[1], spacing[0]])
    return [c * scale for c in mask_boundaries_px(mask)]


class _Polylines:
    """Closed polylines with an exact point-to-polyline distance query."""

    def __init__(self, curves: list[np.ndarray], step: float):
        dense = [resample_closed(c, step=step) for c in curves]
        self.vertices = np.vstack(dense)
        # index of the next and previous vertex along each (closed) curve
        nxt, prv, start = [], [], 0
        for c in dense:
            idx = np.arange(start, start + len(c))
            nxt.append(np.roll(idx, -1))
            prv.append(np.roll(idx, 1))
            start += len(c)
        self.next = np.concatenate(nxt)
        self.prev = np.concatenate(prv)
        self.tree = cKDTree(self.vertices)

    @staticmethod
    def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        ab = b - a
        denom = np.einsum("ij,ij->i", ab, ab)
        t = np.einsum("ij,ij->i", p - a, ab) / np.where(denom > 0, denom, 1.0)
        t = np.clip(t, 0.0, 1.0)
        closest = a + t[:, None] * ab
        return np.linalg.norm(p - closest, axis=1)

    def distance(self, points: np.ndarray) -> np.ndarray:
        _, j = self.tree.query(points)
        v = self.vertices
        d_next = self._segment_distance(points, v[j], v[self.next[j]])
        d_prev = self._segment_distance(points, v[self.prev[j]], v[j])
        return np.minimum(d_next, d_prev)


def boundary_distances(a: Any, b: Any, spacing: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Distances between the boundaries of two masks (or two :class:`~hifumotion.contour.Contour`).

    Returns ``(d_ab, d_ba)``: for uniform arc-length samples of A's boundary,
    the distance of each to B's boundary, and the reverse. In mm with
    ``spacing`` (or a Contour's own spacing), else in px. Raises
    :class:`InputError` when either has no boundary.
    """
    if isinstance(a, Contour) and isinstance(b, Contour):
        sp = a.spacing_mm
        curves_a, curves_b = [a.points_mm], [b.points_mm]
    else:
        ma, mb = _pair(a, b)
        if not ma.any() or not mb.any():
            raise InputError("a mask has no foreground, so it has no boundary to measure distances from")
        sp = _spacing(spacing)
        curves_a, curves_b = _curves_mm(ma, sp), _curves_mm(mb, sp)
    step = SAMPLE_STEP_PX * min(sp)
    samples_a = np.vstack([resample_closed(c, step=step) for c in curves_a])
    samples_b = np.vstack([resample_closed(c, step=step) for c in curves_b])
    d_ab = _Polylines(curves_b, step).distance(samples_a)
    d_ba = _Polylines(curves_a, step).distance(samples_b)
    return d_ab, d_ba


def mssd(a: Any, b: Any, spacing: Any = None) -> float:
    """Mean sum of squared distances between the two boundaries (the paper's [37]).

    ``MSSD = (Σ_{p∈∂A} d(p, ∂B)² + Σ_{q∈∂B} d(q, ∂A)²) / (N_A + N_B)``, with ``p``
    and ``q`` uniform arc-length samples of each boundary: the mean squared
    distance over both contours, symmetric in A and B. mm² with ``spacing``,
    else px². See ``docs/decisions.md`` for why this definition.
    """
    return _mssd(*boundary_distances(a, b, spacing))


def _mssd(d_ab: np.ndarray, d_ba: np.ndarray) -> float:
    return float((np.sum(d_ab**2) + np.sum(d_ba**2)) / (d_ab.size + d_ba.size))


def _hausdorff(d_ab: np.ndarray, d_ba: np.ndarray, percentile: float) -> float:
    if percentile == 100:
        return float(max(d_ab.max(), d_ba.max()))
    return float(max(np.percentile(d_ab, percentile), np.percentile(d_ba, percentile)))


def hausdorff(a: Any, b: Any, spacing: Any = None, percentile: float = 100) -> float:
    """Symmetric Hausdorff distance between two boundaries, mm with ``spacing`` else px.

    ``percentile=100`` is the classical ``max(sup_a d(a, ∂B), sup_b d(b, ∂A))``;
    ``percentile=95`` gives HD95: the larger of the two directed 95th percentiles,
    robust to a few outlying boundary points.
    """
    if not 0 < percentile <= 100:
        raise InputError(f"percentile must be in (0, 100], got {percentile}", "percentile")
    return _hausdorff(*boundary_distances(a, b, spacing), percentile)


def centroid(mask: Any, spacing: Any = None) -> np.ndarray:
    """Area centroid ``(x, y)`` of a mask, in mm with ``spacing`` else px (x = column)."""
    m = as_mask(mask, "mask")
    sp = _spacing(spacing)
    rows, cols = np.nonzero(m)
    return np.array([cols.mean() * sp[1], rows.mean() * sp[0]])


def centroid_distance(a: Any, b: Any, spacing: Any = None) -> float:
    """Distance between the area centroids of two masks, mm with ``spacing`` else px."""
    ma, mb = _pair(a, b)
    return float(np.linalg.norm(centroid(ma, spacing) - centroid(mb, spacing)))


def score(predicted: Any, reference: Any, spacing: Any = None) -> dict[str, float]:
    """Every score at once: ``dsc``, ``mssd``, ``hausdorff``, ``hd95``, ``centroid_distance``.

    When either mask is empty the distance scores are ``inf`` and DSC is 0
    (or 1 if both are empty), so a failed segmentation still fills a table row.
    """
    ma, mb = _pair(predicted, reference)
    out = {"dsc": dice(ma, mb)}
    if not ma.any() or not mb.any():
        return out | {"mssd": np.inf, "hausdorff": np.inf, "hd95": np.inf, "centroid_distance": np.inf}
    d_ab, d_ba = boundary_distances(ma, mb, spacing)
    out["mssd"] = _mssd(d_ab, d_ba)
    out["hausdorff"] = _hausdorff(d_ab, d_ba, 100)
    out["hd95"] = _hausdorff(d_ab, d_ba, 95)
    out["centroid_distance"] = centroid_distance(ma, mb, spacing)
    return out
