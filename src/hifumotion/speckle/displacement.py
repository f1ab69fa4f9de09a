"""Displacement of the imaging plane's material points, from frame 0 to every frame, by speckle tracking.

The speckle of a B-mode image is made by the tissue's scatterers, so it moves with
the tissue: an optical-flow estimator that follows it measures the displacement of
material points, the paper's D_t (Section 2.2.2), at every pixel rather than only
at the boundary a segmentation sees.

The field is Lagrangian: ``u_t(X)`` (mm) is where the material at pixel ``X`` of
frame 0 has gone by frame ``t`` (``x = X + u_t(X)``). Per frame (:func:`displacement`):

1. **register directly** frame ``t`` to the reference frame (frame 0, or a later keyframe
   once the speckle has decorrelated from it), the flow started from the previous frame's
   estimate: a frame-to-frame chain would add every step's error (it drifted 2–3 × more
   on the twins, docs/decisions.md), a direct registration does not. Where the speckle
   decorrelates within a frame or two, as in real tongue cine, new references follow one
   another (at 0 … 84 % of the frames of three clips) and the field is chained after all;
2. **keep the solids out**: the bar is tracked on its own echo (:class:`RigidTracker`);
   where a solid (the bar, the floor, their measured blur) is in either image, frame
   ``t`` shows the reference moved by the current estimate, so the estimator's window
   never reads a solid's motion as the tissue's;
3. **grade and fill**: each pixel's *quality* is the local normalised cross-correlation
   of the reference with frame ``t`` pulled back through the estimate; tissue under a
   solid in frame ``t`` (occluded) gets quality 0; a quality-weighted normalised
   convolution at the speckle's scale smooths the field and fills what was not seen;
4. **keep the material out of the solids**: a point the field puts inside a solid (the bar
   where it is now, the floor) goes to the solid's surface — the fill under a pushing bar
   lags the push, and no tissue can be where the bar is.

Pixels of the solids on frame 0 carry no displacement (NaN) and quality 0.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from hifumotion.errors import InputError
from hifumotion.sequence import as_spacing_mm
from hifumotion.speckle._flow import _u8, estimator as flow_estimator

#: Side of the window (px) of the local normalised cross-correlation that grades each pixel.
QUALITY_WINDOW_PX = 9


def _remap(field: np.ndarray, map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    """``field`` (H, W[, C]) sampled bilinearly at ``(map_x, map_y)`` px; edges replicated."""
    import cv2

    return cv2.remap(np.ascontiguousarray(field, np.float32), map_x, map_y, cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def _remap_mask(mask: np.ndarray, map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    """A boolean mask sampled (nearest pixel) at ``(map_x, map_y)``; outside the image: False."""
    import cv2

    return cv2.remap(mask.view(np.uint8), map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=0).astype(bool)


def sample_field(displacement_mm: np.ndarray, quality: np.ndarray, points_px: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Displacement (mm, ``(N, 2)``) and quality ``(N,)`` of frame-0 material points
    ``points_px`` (``(N, 2)`` px, (x, y)) from one frame's field ``displacement_mm`` ``(H, W, 2)``
    and ``quality`` ``(H, W)``: bilinear, from the valid pixels nearest each point (a point on
    an excluded pixel takes its valid neighbours'; NaN and quality 0 where none is near)."""
    pts = np.asarray(points_px, np.float32).reshape(-1, 2)
    u = np.nan_to_num(displacement_mm, nan=0.0)
    valid = np.isfinite(displacement_mm[..., 0]).astype(np.float32)
    mx, my = pts[:, 0].reshape(1, -1), pts[:, 1].reshape(1, -1)
    w = _remap(valid, mx, my).ravel()
    du = _remap(u * valid[..., None], mx, my).reshape(-1, 2)
    q = _remap(quality * valid, mx, my).ravel()
    safe = np.maximum(w, 1e-6)[:, None]
    disp = np.where(w[:, None] > 1e-6, du / safe, np.nan)
    return disp.astype(np.float32), np.where(w > 1e-6, q / safe[:, 0], 0.0).astype(np.float32)


def local_ncc(a: np.ndarray, b: np.ndarray, window_px: int = QUALITY_WINDOW_PX) -> np.ndarray:
    """Normalised cross-correlation of ``a`` and ``b`` in a ``window_px`` box around each pixel, in [−1, 1]."""
    import cv2

    a = np.asarray(a, np.float32)
    b = np.asarray(b, np.float32)
    k = (int(window_px), int(window_px))

    def mean(x):
        return cv2.boxFilter(x, -1, k, borderType=cv2.BORDER_REFLECT)

    ma, mb = mean(a), mean(b)
    cov = mean(a * b) - ma * mb
    va = np.maximum(mean(a * a) - ma * ma, 0.0)
    vb = np.maximum(mean(b * b) - mb * mb, 0.0)
    return (cov / np.sqrt(va * vb + 1e-12)).astype(np.float32)


def unit_frames(frames) -> np.ndarray:
    """``(T, H, W)`` frames as float32 in [0, 1]: floats already there are kept, anything else
    is scaled as :func:`~hifumotion.sequence.scale_intensities` does (uint8: 0–255)."""
    from hifumotion.sequence import scale_intensities

    arr = np.asarray(frames)
    if arr.ndim != 3 or arr.shape[0] < 1 or min(arr.shape[1:]) < 8:
        raise InputError(f"expected frames (T, H, W) of at least 8 × 8 px, got shape {arr.shape}", "frames")
    if not np.issubdtype(arr.dtype, np.number) and arr.dtype != np.bool_:
        raise InputError(f"expected numeric pixel values, got {arr.dtype}", "frames")
    if np.issubdtype(arr.dtype, np.floating):
        if not np.all(np.isfinite(arr)):
            raise InputError("frames contain NaN or infinite values", "frames")
        if arr.min() >= 0.0 and arr.max() <= 1.0:
            return arr.astype(np.float32, copy=False)
    return scale_intensities(arr)


@dataclass
class DisplacementSeries:
    """The Lagrangian displacement of frame 0's pixels at every frame.

    Attributes
    ----------
    displacement_mm
        float32 ``(T, H, W, 2)``: ``(x, y)`` = (column, row) components in mm of where the
        material at each frame-0 pixel has moved by frame ``t``; frame 0 is zero; NaN on
        excluded pixels.
    quality
        float32 ``(T, H, W)``: local normalised cross-correlation (window
        :data:`QUALITY_WINDOW_PX`) of frame 0 with frame ``t`` pulled back through the
        displacement; 1 = the speckle matches, ≤ 0 = no information; 0 on excluded pixels.
    spacing_mm
        Pixel size ``(row, col)`` in mm.
    estimator
        Name of the optical-flow estimator.
    seconds_per_frame
        Wall time of each frame's estimate (s); frame 0 is 0.
    rigid_shift_mm
        ``(T, 2)`` the rigid solid's tracked translation (x, y) from frame 0 in mm (the bar's
        push as the image shows it); ``None`` without one.
    """

    displacement_mm: np.ndarray
    quality: np.ndarray
    spacing_mm: tuple[float, float]
    estimator: str = "dis"
    seconds_per_frame: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rigid_shift_mm: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return int(self.displacement_mm.shape[0])

    def displacement_px(self, frame: int) -> np.ndarray:
        """Frame ``frame``'s field in px, ``(H, W, 2)`` (NaN where excluded)."""
        row, col = self.spacing_mm
        return self.displacement_mm[frame] / np.array([col, row], np.float32)

    def at(self, points_px: np.ndarray, frame: int) -> tuple[np.ndarray, np.ndarray]:
        """Displacement (mm, ``(N, 2)``) and quality ``(N,)`` of frame-0 material points
        ``points_px`` (``(N, 2)`` px, (x, y)) at ``frame`` (:func:`sample_field`)."""
        return sample_field(self.displacement_mm[frame], self.quality[frame], points_px)

    def strain(self, frame: int) -> np.ndarray:
        """Small-strain tensor components ``(H, W, 3)`` = (ε_xx, ε_yy, ε_xy) of frame ``frame``
        (dimensionless, central differences of the field in mm over the pixel size)."""
        row, col = self.spacing_mm
        u = self.displacement_mm[frame]
        dux_dy, dux_dx = np.gradient(u[..., 0], row, col)
        duy_dy, duy_dx = np.gradient(u[..., 1], row, col)
        return np.dstack([dux_dx, duy_dy, 0.5 * (dux_dy + duy_dx)]).astype(np.float32)


#: Width of the Lucas–Kanade window in speckle sizes (σ = this × the speckle's FWHM / 2.355 per axis),
#: chosen on a twin outside the benchmark's (docs/decisions.md).
LK_WINDOW = 6.0
#: Start a new reference frame (keyframe) when the median quality of the tissue falls below this
#: fraction of the first frame's (docs/decisions.md, "Re-anchoring relative to the first match").
KEYFRAME_QUALITY = 0.85


class LucasKanade:
    """Dense Lucas–Kanade refinement of a flow against one reference frame (Lucas & Kanade 1981):
    the reference's gradients and their Gaussian-windowed structure tensor are computed once;
    each refinement pulls the moving frame back through the flow and solves, at every pixel,
    the 2 × 2 system of the windowed residual — one Gauss–Newton step on the speckle itself."""

    def __init__(self, reference: np.ndarray, sigma_px: tuple[float, float]):
        import cv2

        ref = np.asarray(reference, np.float32)
        self.reference = ref
        self.sigma = sigma_px
        self.ix = cv2.Sobel(ref, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        self.iy = cv2.Sobel(ref, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        a11, a12, a22 = (self._g(x) for x in (self.ix * self.ix, self.ix * self.iy, self.iy * self.iy))
        det = a11 * a22 - a12 * a12
        floor = 1e-3 * float(np.median(a11 + a22)) ** 2 + 1e-12
        ok = det > floor
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0).astype(np.float32)
        self.m11, self.m12, self.m22 = a22 * inv, -a12 * inv, a11 * inv

    def _g(self, x):
        import cv2

        sr, sc = self.sigma
        return cv2.GaussianBlur(x, (0, 0), sigmaX=float(sc), sigmaY=float(sr), borderType=cv2.BORDER_REFLECT)

    def refine(self, moving: np.ndarray, flow: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
        """The flow (px, reference grid) after one Gauss–Newton step (each component ≤ 1 px)."""
        pulled = _remap(moving, gx + flow[..., 0], gy + flow[..., 1])
        it = pulled - self.reference
        b1, b2 = self._g(self.ix * it), self._g(self.iy * it)
        step = np.dstack([self.m11 * b1 + self.m12 * b2, self.m12 * b1 + self.m22 * b2])
        return flow - np.clip(step, -1.0, 1.0)


def _fill_gap(field: np.ndarray, weight: np.ndarray, covered_now: np.ndarray, tissue: np.ndarray,
              sigma_px: float) -> np.ndarray:
    """Tissue pixels (``tissue``, reference grid) whose material lies under ``covered_now`` (a
    solid in the current frame) replaced by a local plane fitted to the visible tissue around
    them (:func:`~hifumotion.speckle._fill.linear_fill`). Computed only on the box around the
    solid, grown by the largest displacement and three windows: a thin gap costs its box."""
    from hifumotion.speckle._fill import linear_fill

    rows, cols = np.nonzero(covered_now)
    if rows.size == 0:
        return field
    h, w = covered_now.shape
    reach = int(np.ceil(np.abs(field).max())) + int(np.ceil(3 * sigma_px)) + 2
    r0, r1 = max(rows.min() - reach, 0), min(rows.max() + 1 + reach, h)
    c0, c1 = max(cols.min() - reach, 0), min(cols.max() + 1 + reach, w)
    box = (slice(r0, r1), slice(c0, c1))
    f = field[box]
    gy, gx = np.mgrid[r0:r1, c0:c1].astype(np.float32)
    gap = _remap_mask(covered_now, gx + f[..., 0], gy + f[..., 1]) & tissue[box]
    if not gap.any():
        return field
    out = field.copy()
    out[box] = linear_fill(f, weight[box] * tissue[box], gap, sigma_px)
    return out


def _shifted(mask: np.ndarray, shift_px: np.ndarray) -> np.ndarray:
    """``mask`` translated by ``shift_px`` (x, y) px (nearest pixel)."""
    import cv2

    h, w = mask.shape
    m = np.float32([[1, 0, shift_px[0]], [0, 1, shift_px[1]]])
    return cv2.warpAffine(mask.astype(np.uint8), m, (w, h), flags=cv2.INTER_NEAREST, borderValue=0).astype(bool)


def _grow(mask: np.ndarray, element: np.ndarray | None) -> np.ndarray:
    import cv2

    return mask if element is None else cv2.dilate(mask.astype(np.uint8), element).astype(bool)


class RigidTracker:
    """The translation of a rigid solid (the bar) from frame 0, by template matching.

    The solid's frame-0 appearance (its bounding box grown by ``margin_px``) is searched for
    in each frame around where it was last seen, moved on at its last velocity; the peak
    of the normalised cross-correlation is refined to sub-pixel by a parabola on each axis.
    """

    def __init__(self, frame0: np.ndarray, solid: np.ndarray, margin_px: int = 4):
        rows, cols = np.nonzero(solid)
        h, w = solid.shape
        self.r0, self.r1 = max(rows.min() - margin_px, 0), min(rows.max() + 1 + margin_px, h)
        self.c0, self.c1 = max(cols.min() - margin_px, 0), min(cols.max() + 1 + margin_px, w)
        self.template = np.ascontiguousarray(frame0[self.r0:self.r1, self.c0:self.c1], np.float32)
        self.shift = np.zeros(2, np.float32)
        self.velocity = np.zeros(2, np.float32)

    def update(self, frame: np.ndarray) -> np.ndarray:
        """The translation (x, y) px of the solid in ``frame`` from frame 0."""
        import cv2

        h, w = frame.shape
        guess = self.shift + self.velocity
        reach = int(np.ceil(4 + 2 * np.abs(self.velocity).max()))
        gx, gy = int(round(guess[0])), int(round(guess[1]))
        # the search window, clipped to the image
        r0, r1 = max(self.r0 + gy - reach, 0), min(self.r1 + gy + reach, h)
        c0, c1 = max(self.c0 + gx - reach, 0), min(self.c1 + gx + reach, w)
        th, tw = self.template.shape
        if r1 - r0 < th or c1 - c0 < tw:   # the solid has (nearly) left the image: keep it moving
            found = guess
        else:
            score = cv2.matchTemplate(np.ascontiguousarray(frame[r0:r1, c0:c1], np.float32), self.template,
                                      cv2.TM_CCOEFF_NORMED)
            _, _, _, (px, py) = cv2.minMaxLoc(score)

            def peak(a, b, c):
                den = a - 2 * b + c
                return 0.0 if abs(den) < 1e-12 else float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))

            sx = peak(score[py, px - 1], score[py, px], score[py, px + 1]) if 0 < px < score.shape[1] - 1 else 0.0
            sy = peak(score[py - 1, px], score[py, px], score[py + 1, px]) if 0 < py < score.shape[0] - 1 else 0.0
            found = np.array([c0 + px + sx - self.c0, r0 + py + sy - self.r0], np.float32)
        self.velocity = found - self.shift
        self.shift = found
        return found


class SpeckleTracker:
    """Speckle tracking one frame at a time: what :func:`displacement` runs over a cine, for
    frames that arrive from a scanner (:mod:`hifumotion.prediction.online`).

    Made from frame 0 (the speckle's size, the grey levels, the solids' bloom are measured
    on it); each :meth:`update` takes the next frame and returns the displacement of frame
    0's material points to it and its quality — frame t's estimate is computed from frames
    ≤ t only, so a cine tracked at once and frames fed one by one give the same fields.
    The parameters are :func:`displacement`'s. Frames are grey levels in [0, 1] or uint8.
    """

    def __init__(self, frame0: np.ndarray, spacing_mm, *, exclude: np.ndarray | None = None,
                 rigid: np.ndarray | None = None, estimator: str = "farneback", smoothing: float = 1.0,
                 keyframe_quality: float = KEYFRAME_QUALITY, fill: str = "plane", lk_iterations: int = 1,
                 lk_window: float = LK_WINDOW, keep_out_of_solids: bool = True,
                 exclude_distance_px: np.ndarray | None = None, rigid_distance_px: np.ndarray | None = None):
        import cv2

        from hifumotion.observed.solids import measure_bloom_px
        from hifumotion.speckle._solid_surface import SolidSurface
        from hifumotion.speckle._speckle_size import speckle_fwhm_px

        frame0 = unit_frames(np.asarray(frame0)[None])[0]
        self.spacing_mm = as_spacing_mm(spacing_mm)
        h, w = frame0.shape
        self.shape = (h, w)
        given = {}
        for name, m in (("exclude", exclude), ("rigid", rigid)):
            if m is not None:
                m = np.asarray(m, bool)
                if m.shape != (h, w):
                    raise InputError(f"expected a mask of shape {(h, w)}, got {m.shape}", name)
                given[name] = m if m.any() else None
        exclude, rigid = given.get("exclude"), given.get("rigid")
        static = exclude if exclude is not None else np.zeros((h, w), bool)
        self.rigid = rigid
        self.solid0 = static | (rigid if rigid is not None else False)
        if fill not in ("plane", "mean"):
            raise InputError(f"unknown fill {fill!r}; expected plane or mean", "fill")
        self.estimator = estimator.lower()
        self.flow = flow_estimator(estimator)
        if (~self.solid0).sum() < 64:
            raise InputError("the known solids cover (almost) the whole image: no tissue left to track", "exclude")
        self.smoothing, self.keyframe_quality, self.fill = smoothing, keyframe_quality, fill
        self.lk_iterations = lk_iterations
        # the speckle's size and the grey levels, measured on frame 0 away from the solids
        solid0 = self.solid0
        bright = (frame0 > np.percentile(frame0[~solid0], 50)) & ~solid0
        fwhm = speckle_fwhm_px(frame0, bright if bright.sum() > 64 else None)
        self.sigma = (smoothing * fwhm[0] / 2.355, smoothing * fwhm[1] / 2.355)
        self.lk_sigma = (lk_window * fwhm[0] / 2.355, lk_window * fwhm[1] / 2.355)
        # (rows, cols) px from the image's edge within which an estimate's window is cut short:
        # the flow's own, the Lucas–Kanade Gaussian's (2 σ) and the quality's
        support = getattr(self.flow, "support_px", 0)
        self.edge_margin_px = tuple(
            int(np.ceil(max(support, 2.0 * s if lk_iterations > 0 else 0.0, QUALITY_WINDOW_PX // 2)))
            for s in self.lk_sigma)
        tissue_level = float(np.median(frame0[bright])) if bright.any() else 1.0
        background = float(np.median(frame0[~bright & ~solid0])) if (~bright & ~solid0).any() else 0.0
        self.element = None
        if rigid is not None:
            bloom = measure_bloom_px(frame0, rigid, 0.5 * (tissue_level + background), fwhm)
            if max(bloom) > 0:
                self.element = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * bloom[1] + 1, 2 * bloom[0] + 1))
        self.rigid_tracker = RigidTracker(frame0, rigid) if rigid is not None else None
        # the solids themselves (not their bloom), which no material can enter
        self.rigid_surface = (SolidSurface(rigid, rigid_distance_px)
                              if keep_out_of_solids and rigid is not None else None)
        self.static_surface = (SolidSurface(static, exclude_distance_px)
                               if keep_out_of_solids and static.any() else None)
        self.grown_static = _grow(static, self.element) if static.any() else static   # it does not move
        self.gx, self.gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        self.frames_seen = 1
        self.key = 0                                       # the reference frame
        self.covered_key, _ = self._solids_at(np.zeros(2))  # the solids (and their bloom) in the reference
        self.reference = frame0
        self.reference_u8 = _u8(frame0)
        self.u_key = np.zeros((h, w, 2), np.float32)       # frame 0 → reference (frame-0 grid, px)
        self.v = np.zeros((h, w, 2), np.float32)           # reference → current (reference grid, px)
        self.step = np.zeros((h, w, 2), np.float32)        # the last frame's change of v (px; kept across a new reference)
        self.textured = None                               # frame-0 pixels with speckle to track (set at frame 1)
        self.first_quality = 1.0                           # their median quality at frame 1
        self.lk = None                                     # the Lucas–Kanade refinement against the reference
        self.tissue_key = None                             # the same pixels on the reference's grid
        self.rigid_shift_px = np.zeros(2, np.float32)

    def _solids_at(self, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The solids grown by their blur in a frame, and the rigid one alone."""
        bar = _grow(_shifted(self.rigid, shift), self.element) if self.rigid is not None else None
        return (self.grown_static | bar if bar is not None else self.grown_static), bar

    def update(self, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The next frame: ``(displacement_mm (H, W, 2), quality (H, W))`` of frame 0's
        material points (NaN displacement and quality 0 on the solids of frame 0)."""
        import cv2

        from hifumotion.speckle._fill import normalized_convolution

        frame = np.asarray(frame)
        if frame.shape != self.shape:
            raise InputError(f"expected a frame of shape {self.shape}, got {frame.shape}", "frame")
        frame = unit_frames(frame[None])[0]
        gx, gy, v_last = self.gx, self.gy, self.v
        # the estimate carried on at the last frame's rate: what the solids' pixels show and where
        # the flow starts. Shown the last frame's estimate instead, the tissue beside the bar is
        # pulled a frame behind — a lag each new reference keeps for good (docs/decisions.md)
        v = v_last + self.step
        shift = self.rigid_tracker.update(frame) if self.rigid_tracker is not None else np.zeros(2, np.float32)
        covered, bar_now = self._solids_at(shift)
        current = _u8(frame)
        any_solid = covered.any() or self.covered_key.any()
        if any_solid:
            # where a solid is (now, or was in the reference) frame t shows the reference moved
            # by the estimate carried on: those pixels agree with it, and no solid's motion
            # reaches the tissue through the estimator's window
            back_x, back_y = gx - v[..., 0], gy - v[..., 1]
            replace = covered | (_remap_mask(self.covered_key, back_x, back_y))
            moved = cv2.remap(self.reference_u8, back_x, back_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            current = np.where(replace, moved, current)
        # register frame t directly to the reference, starting from the estimate carried on
        v = self.flow(self.reference_u8, current, v)
        if self.lk_iterations > 0:
            # Farnebäck's polynomial model of the speckle leaves a bias where the tissue is
            # strained; Gauss–Newton on the speckle itself removes most of it
            if self.lk is None:
                self.lk = LucasKanade(self.reference, self.lk_sigma)
            moving = current.astype(np.float32) * np.float32(1.0 / 255.0)
            for _ in range(self.lk_iterations):
                v = self.lk.refine(moving, v, gx, gy)
        ahead_x, ahead_y = gx + v[..., 0], gy + v[..., 1]
        weight = np.clip(local_ncc(self.reference, _remap(frame, ahead_x, ahead_y)), 0.0, 1.0)
        weight *= weight
        if any_solid:   # the material now under a solid, and the reference's own solids
            weight[_remap_mask(covered, ahead_x, ahead_y) | self.covered_key] = 0.0
        # material that has left the image has no speckle to match, and the estimate of material
        # whose window holds some is pulled towards the edge's replicated pixels: both take
        # their neighbours' instead (docs/decisions.md, "Material that leaves the image")
        h, w = self.shape
        gone = (ahead_x < 0) | (ahead_x > w - 1) | (ahead_y < 0) | (ahead_y > h - 1)
        if gone.any():
            mr, mc = self.edge_margin_px
            weight[cv2.dilate(gone.view(np.uint8), np.ones((2 * mr + 1, 2 * mc + 1), np.uint8)).view(bool)] = 0.0
        if self.smoothing > 0:
            v = normalized_convolution(v, weight, self.sigma)
            if self.fill == "plane" and self.rigid is not None and self.tissue_key is not None:
                # tissue under the bar carries on the visible tissue's gradient (the push's
                # compression), not only its mean: a plane fitted around the gap
                v = _fill_gap(v, weight, bar_now, self.tissue_key, 4.0 * max(self.sigma))
        # back on frame 0's grid
        if self.key == 0:
            out = v
            quality = np.sqrt(weight)
        else:
            mx, my = gx + self.u_key[..., 0], gy + self.u_key[..., 1]
            out = self.u_key + _remap(v, mx, my)
            quality = np.sqrt(np.clip(_remap(weight, mx, my), 0.0, 1.0))
        out = self._outside_solids(out, shift)
        self.step = v - v_last
        self.v = v
        self.rigid_shift_px = np.asarray(shift, np.float32)
        t = self.frames_seen
        self.frames_seen += 1
        if self.textured is None:
            self.textured = (quality > 0.5) & ~self.solid0
            self.tissue_key = self.textured
            # the first frame's match: as good as a match gets in this noise (the threshold is
            # relative to it, so noisy images do not start a new reference at every frame)
            self.first_quality = float(np.median(quality[self.textured])) if self.textured.any() else 1.0
        if (self.keyframe_quality > 0 and self.textured.any()
                and np.median(quality[self.textured]) < self.keyframe_quality * self.first_quality):
            # a new reference: the speckle has decorrelated from the old one
            self.key, self.u_key, self.v = t, out.copy(), np.zeros_like(v)
            # frame 0's tissue pixels seen from the new reference (X ≈ Y − u(Y))
            self.tissue_key = _remap_mask(self.textured, gx - self.u_key[..., 0], gy - self.u_key[..., 1])
            self.covered_key, self.reference, self.reference_u8 = covered, frame, _u8(frame)
            self.lk = None
        row, col = self.spacing_mm
        disp = out * np.array([col, row], np.float32)
        disp[self.solid0] = np.nan
        quality = quality.astype(np.float32, copy=False)
        quality[self.solid0] = 0.0
        return disp, quality

    def _outside_solids(self, out: np.ndarray, shift: np.ndarray) -> np.ndarray:
        """Frame 0 → current displacement (px) with the material it puts inside a solid (the bar
        where it is now, the static ones) moved to the solid's surface
        (:mod:`~hifumotion.speckle._solid_surface`)."""
        if self.rigid_surface is not None:
            # what the bar covers it pushed ahead of it, along its motion
            out = self.rigid_surface.keep_out(out, shift, along=shift)
        if self.static_surface is not None:
            out = self.static_surface.keep_out(out)
        return out

    @property
    def rigid_shift_mm(self) -> np.ndarray | None:
        """The rigid solid's translation (x, y) from frame 0 in mm at the last frame; None without one."""
        if self.rigid is None:
            return None
        row, col = self.spacing_mm
        return self.rigid_shift_px * np.array([col, row], np.float32)


def displacement(frames: np.ndarray, spacing_mm=None, *, exclude: np.ndarray | None = None,
                 rigid: np.ndarray | None = None, estimator: str = "farneback", smoothing: float = 1.0,
                 keyframe_quality: float = KEYFRAME_QUALITY, fill: str = "plane", lk_iterations: int = 1,
                 lk_window: float = LK_WINDOW, keep_out_of_solids: bool = True,
                 exclude_distance_px: np.ndarray | None = None, rigid_distance_px: np.ndarray | None = None,
                 progress: bool = False) -> DisplacementSeries:
    """Track the speckle of a cine loop: the displacement of frame 0's material points at every frame.

    Each frame is registered directly to the current reference frame (frame 0, or the
    last keyframe), starting from the previous frame's estimate, so the error does not grow
    with the number of frames (no frame-to-frame drift). When the tissue's speckle has
    decorrelated from the reference (median quality below ``keyframe_quality`` times the
    first frame's), the current
    frame becomes the new reference and the maps are composed.

    Solids are known: ``exclude`` (static, such as the pool's floor) and ``rigid`` (one that
    moves by translation, such as the pushing bar, tracked on its own echo by
    :class:`RigidTracker`). Both, grown by their measured bloom
    (:func:`~hifumotion.observed.solids.measure_bloom_px`), are set to the background grey
    level in both images before the flow is computed, so the estimator's window never
    mixes a solid's motion into the tissue's; tissue a solid covers in the current frame is
    *occluded* and, like every weakly textured pixel, takes the displacement of the visible
    tissue around it (quality-weighted normalised convolution at the speckle's scale).

    Parameters
    ----------
    frames
        ``(T, H, W)`` grey levels in [0, 1], or an :class:`~hifumotion.sequence.ImageSequence`
        (its spacing is used when ``spacing_mm`` is not given).
    spacing_mm
        Pixel size in mm, scalar or ``(row, col)``.
    exclude, rigid
        ``(H, W)`` bool frame-0 masks of the static solids and of the rigidly moving one;
        both carry NaN displacement and quality 0 in the result.
    estimator
        The optical flow (:data:`hifumotion.speckle._flow.ESTIMATORS`); ``farneback`` by
        default (docs/decisions.md, "Seeing the motion: speckle tracking").
    smoothing
        Width of the quality-weighted smoothing in speckle sizes (σ = ``smoothing`` × the
        speckle's FWHM / 2.355 on each axis); 0 for none (occluded pixels are then left as
        the flow gave them).
    keyframe_quality
        The median quality, as a fraction of the first frame's match (the noise's own
        floor), below which a new reference frame is started (0: never).
    lk_iterations, lk_window
        Lucas–Kanade steps after the flow (:class:`LucasKanade`; 0 for none) and their
        window in speckle sizes.
    fill
        How the tissue under the bar is filled: ``"plane"`` (default) a local plane fitted to
        the visible tissue around it, so the push's compression carries on under the bar;
        ``"mean"`` only the normalised convolution's weighted mean (about 30 % faster, and
        15–25 % less accurate on the twins: docs/decisions.md).
    keep_out_of_solids
        Move material the field puts inside a solid (the bar where it is in that frame, the
        static ones; not their bloom) onto its surface — the bar's along the bar's motion, a
        static one's along its normal (default):
        under a pushing bar the fill from the visible tissue lags the push, and no tissue can
        be where the bar is (:mod:`~hifumotion.speckle._solid_surface`). Quality is unchanged.
    exclude_distance_px, rigid_distance_px
        The solids' signed distances (px, negative inside) where their geometry is known
        (:func:`~hifumotion.observed.solids.known_solids`): the surfaces material is kept out
        of, to a fraction of a pixel; without them, the masks' own (to half a pixel).
    progress
        Show a progress bar.

    Returns
    -------
    DisplacementSeries

    References
    ----------
    Farnebäck G. Two-frame motion estimation based on polynomial expansion. SCIA 2003. —
    Lubinski MA, Emelianov SY, O'Donnell M. Speckle tracking methods for ultrasonic
    elasticity imaging using short-time correlation. IEEE TUFFC 46(1), 1999. — Knutsson H,
    Westin C-F. Normalized and differential convolution. CVPR 1993.
    """
    from hifumotion.sequence import ImageSequence

    if isinstance(frames, ImageSequence):
        spacing_mm = spacing_mm if spacing_mm is not None else frames.spacing_mm
        frames = frames.frames
    frames = unit_frames(frames)
    tracker = SpeckleTracker(frames[0], spacing_mm, exclude=exclude, rigid=rigid, estimator=estimator,
                             smoothing=smoothing, keyframe_quality=keyframe_quality, fill=fill,
                             lk_iterations=lk_iterations, lk_window=lk_window,
                             keep_out_of_solids=keep_out_of_solids, exclude_distance_px=exclude_distance_px,
                             rigid_distance_px=rigid_distance_px)
    t_count, h, w = frames.shape
    out = np.zeros((t_count, h, w, 2), np.float32)
    quality = np.zeros((t_count, h, w), np.float32)
    out[0, tracker.solid0] = np.nan
    quality[0] = np.where(tracker.solid0, 0.0, 1.0)
    seconds = np.zeros(t_count)
    rigid_path = np.zeros((t_count, 2), np.float32)
    steps = range(1, t_count)
    if progress:
        from hifumotion.console import track as progress_bar

        steps = progress_bar(steps, "speckle tracking", total=t_count - 1)
    for t in steps:
        t0 = time.perf_counter()
        out[t], quality[t] = tracker.update(frames[t])
        seconds[t] = time.perf_counter() - t0
        if tracker.rigid is not None:
            rigid_path[t] = tracker.rigid_shift_mm
    return DisplacementSeries(out, quality, tracker.spacing_mm, tracker.estimator, seconds,
                              rigid_path if tracker.rigid is not None else None)


__all__ = ["DisplacementSeries", "SpeckleTracker", "displacement", "sample_field", "local_ncc", "QUALITY_WINDOW_PX", "KEYFRAME_QUALITY", "RigidTracker"]
