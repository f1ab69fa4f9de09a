"""Contours that follow the material: frame 0's contour carried by the speckle's displacement.

Re-segmenting every frame sees only the boundary, and only as well as the bar's blur
and the speckle let it: a bright bar read as tissue drags the contour with it. Here the
target is segmented once, on frame 0 (GLCV from the clinician's contour, the known
solids excluded), and every later contour is the same material boundary moved by the
tissue's measured displacement (:func:`~hifumotion.speckle.displacement`): the points
``A`` of the paper's Eq. 20 carried by ``D_t``. Optionally a few level-set iterations in
a narrow band around the carried contour then let the image correct it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hifumotion.contour import Contour
from hifumotion.errors import InputError
from hifumotion.observed.solids import Solids
from hifumotion.speckle.displacement import DisplacementSeries, displacement as track_speckle, unit_frames


@dataclass
class FollowResult:
    """Every frame's target, carried from frame 0.

    Attributes
    ----------
    masks
        bool ``(T, H, W)``.
    contours
        The contour of each frame (px and mm); frame ``t``'s points are frame 0's points
        moved by the displacement, so point ``i`` is the same material point in every frame.
    displacement
        The speckle-tracked displacement the contours were carried by.
    quality
        ``(T, N)`` the displacement's quality at each contour point (1 = the speckle
        matches frame 0; 0 = occluded, filled from its neighbours).
    seconds_per_frame
        Wall time of each frame (speckle tracking + carrying), s.
    first
        Frame 0's segmentation (:func:`segment_target`).
    """

    masks: np.ndarray
    contours: list[Contour]
    displacement: DisplacementSeries
    quality: np.ndarray
    seconds_per_frame: np.ndarray
    first: "TargetSegmentation | None" = None

    @property
    def points_px(self) -> np.ndarray:
        """``(T, N, 2)`` the contour's material points in every frame (px, (x, y))."""
        return np.stack([c.points_px for c in self.contours])


def tracker_solids(solids: Solids | None) -> dict:
    """The known solids as :func:`~hifumotion.speckle.displacement`'s (and
    :class:`~hifumotion.speckle.SpeckleTracker`'s) keyword arguments: the floor's and the bar's
    masks, and their signed distances where the geometry gave them; none without solids."""
    if solids is None:
        return {}
    return {"exclude": solids.floor, "rigid": solids.bar, "exclude_distance_px": solids.floor_distance_px,
            "rigid_distance_px": solids.bar_distance_px}


def carry_contour(contour_px: np.ndarray, series: DisplacementSeries, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame-0 contour points ``(N, 2)`` px moved to ``frame``: their positions (px) and quality."""
    return carry_points(contour_px, series.displacement_mm[frame], series.quality[frame], series.spacing_mm)


def carry_points(points_px: np.ndarray, displacement_mm: np.ndarray, quality: np.ndarray,
                 spacing_mm) -> tuple[np.ndarray, np.ndarray]:
    """Frame-0 points ``(N, 2)`` px moved by one frame's field (``(H, W, 2)`` mm, its quality
    ``(H, W)``, pixel ``spacing_mm`` (row, col)): their positions (px) and quality."""
    from hifumotion.speckle.displacement import sample_field

    disp_mm, q = sample_field(displacement_mm, quality, points_px)
    row, col = spacing_mm
    moved = np.asarray(points_px, np.float64) + np.nan_to_num(disp_mm, nan=0.0) / np.array([col, row])
    return moved, q


@dataclass
class TargetSegmentation:
    """Frame 0's target as :func:`segment_target` found it.

    ``mask``: the target; ``excluded``: the pixels masked out of the image before the level
    set ran (the solids and the bar's bloom); ``bloom_px``: the bar's measured bloom
    ``(rows, cols)``; ``speckle_fwhm_px``: the speckle's size ``(rows, cols)``;
    ``outside_fraction``: the share of the level set's segmentation that lay beyond the given
    region's margin (:data:`REGION_MARGIN`); ``given_region_kept``: True when that share passed
    :data:`REGION_LEAK_FRACTION` and the given region was followed instead;
    ``bloom_continued_px``: the pixels of the bloom's strip given back to the target
    (:func:`~hifumotion.observed.solids.continue_into_bloom`).
    """

    mask: np.ndarray
    excluded: np.ndarray
    bloom_px: tuple[int, int]
    speckle_fwhm_px: tuple[float, float]
    outside_fraction: float = 0.0
    given_region_kept: bool = False
    bloom_continued_px: int = 0


#: How far outside the given initial region frame 0's segmentation may reach, as a fraction of
#: the region's equivalent radius √(area/π): a clinician's rough contour is off by a fraction of
#: the target's size (≤ 0.17 on the twins), a level set that leaked into the neighbouring tissue
#: is off by its whole size.
REGION_MARGIN = 0.25
#: The share of the segmentation beyond that margin at which it is taken for a leak and not
#: followed: the given region is followed instead, and the result says so.
REGION_LEAK_FRACTION = 0.10


def region_leak(mask: np.ndarray, given: np.ndarray) -> float:
    """The share of ``mask`` lying beyond the ``given`` region grown by :data:`REGION_MARGIN` of
    its equivalent radius (0 for an empty mask)."""
    from scipy import ndimage

    if not mask.any() or not given.any():
        return 0.0
    radius_px = np.sqrt(given.sum() / np.pi)
    beyond = ndimage.distance_transform_edt(~given) > REGION_MARGIN * radius_px
    return float((mask & beyond).sum() / mask.sum())


def segment_target(image: np.ndarray, init: Any, spacing_mm=None, *, solids: Solids | None = None,
                   boundary_offset_mm: float = 0.0, method: str = "glcv", continue_bloom: bool = False,
                   bloom_shape_mm: np.ndarray | None = None, **params: Any) -> TargetSegmentation:
    """Segment the target on one frame with the known solids taken out of the image.

    1. The tissue's and the background's grey levels are read inside and well outside the
       initial contour; the bar's bloom is measured on the image
       (:func:`~hifumotion.observed.solids.measure_bloom_px`, with the speckle's size from
       :func:`~hifumotion.speckle.speckle_fwhm_px`).
    2. The solids (floor, bar + bloom) are set to the background level *before* the level set
       runs, so it cannot bridge the water gap to a bright bar (cutting them out afterwards
       leaves the bridge).
    3. The segmentation, less the solids, is moved inwards by ``boundary_offset_mm`` (the
       imaging system's, measured on a phantom) on its free boundary only: where it lies on a
       solid it is already where the solid's surface is.
    4. With ``continue_bloom``, the strip the bloom hid is given back: tissue pressed by the
       bar reaches the bar, and a section cut off at the bloom's edge is biased away from it in
       every frame it is carried to (off by default: docs/decisions.md, "Frame 0's target
       reaches the bar"). Where ``bloom_shape_mm`` is given — the resting tissue's signed
       distance (mm, positive inside) at this frame's pixels, known apart from it (the sweep's
       reconstruction, its top continued under the bar) — a hidden pixel is target where that
       shape holds tissue, so the strip follows the tissue's own surface, touching the face
       where it does and curving away from it where it does; without it, where tissue is seen
       at the bloom's edge on the line from the bar
       (:func:`~hifumotion.observed.solids.continue_into_bloom`), which fills the strip up to
       the face.
    5. A segmentation that leaves the given region (more than :data:`REGION_LEAK_FRACTION` of
       it beyond :data:`REGION_MARGIN` of the region's radius) is not the target drawn: the given
       region is kept instead, and ``given_region_kept`` says so.
    """
    from scipy import ndimage

    from hifumotion.observed import shift_boundary
    from hifumotion.observed.solids import bloom_mask, continue_into_bloom, measure_bloom_px
    from hifumotion.segmentation import _resolve_init, segment
    from hifumotion.segmentation.levelset import initial_phi
    from hifumotion.sequence import as_spacing_mm
    from hifumotion.speckle._speckle_size import speckle_fwhm_px

    img = np.asarray(image, np.float32)
    init = _resolve_init(init, None)
    start = initial_phi(init, img.shape) > 0
    solid = solids.any if solids is not None else np.zeros(img.shape, bool)
    inside = start & ~solid
    if inside.sum() < 16:
        raise InputError("the initial contour holds fewer than 16 pixels off the known solids", "init")
    outside = ~ndimage.binary_dilation(start | solid, iterations=10)
    tissue = float(np.median(img[inside]))
    background = float(np.median(img[outside])) if outside.any() else float(img.min())
    fwhm = speckle_fwhm_px(img, inside if inside.sum() > 64 else None)
    excluded = solid.copy()
    bloom = (0, 0)
    if solids is not None and solids.bar.any():
        bloom = measure_bloom_px(img, solids.bar, 0.5 * (tissue + background), fwhm)
        excluded |= bloom_mask(solids.bar, bloom)
    masked = np.where(excluded, np.float32(background), img)
    mask = segment(masked, init, method, spacing_mm, **params).mask & ~excluded
    if boundary_offset_mm:
        pixel = float(np.mean(as_spacing_mm(spacing_mm)))
        mask = shift_boundary(mask | excluded, boundary_offset_mm, pixel) & ~excluded
    continued = 0
    if continue_bloom and mask.any() and max(bloom) > 0:
        # the strip the bloom hid (it lies on the bar, so the free boundary's offset does not
        # apply to it): by the known shape where there is one, else by the image's edge
        if bloom_shape_mm is not None:
            shape = np.asarray(bloom_shape_mm, float)
            if shape.shape != mask.shape:
                raise InputError(f"the bloom's shape has {shape.shape} pixels, the frame {mask.shape}", "bloom_shape_mm")
            hidden = bloom_mask(solids.bar, bloom) & ~solid & (shape > 0)
            # only what joins the target: another body the shape holds is not this one
            labels, _ = ndimage.label(mask | hidden)
            grown = np.isin(labels, np.unique(labels[mask])) & (mask | hidden)
        else:
            grown = continue_into_bloom(mask, solids.bar, bloom) & ~solid
        continued = int(grown.sum() - mask.sum())
        mask = grown
    if not mask.any():
        raise InputError("the target's segmentation is empty once the known solids are removed; "
                         "check the initial contour", "init")
    leak = region_leak(mask, inside)
    if leak > REGION_LEAK_FRACTION:
        # the level set left the region it was given (into tissue of the same grey level): what
        # it found is not the target the user drew, and carried through the cine it would be
        # followed as if it were
        return TargetSegmentation(inside, excluded, bloom, fwhm, leak, True)
    return TargetSegmentation(mask, excluded, bloom, fwhm, leak, False, continued)


def refine_in_band(image: np.ndarray, carried: np.ndarray, excluded: np.ndarray, background: float,
                   band_px: int, iterations: int, method: str, spacing_mm, boundary_offset_mm: float,
                   params: dict) -> np.ndarray:
    """The carried mask corrected by a few level-set iterations on ``image`` (the solids set to
    the background level), allowed to move the boundary by at most ``band_px`` either way,
    then moved inwards by the boundary offset on its free boundary, as frame 0 was."""
    from scipy import ndimage

    from hifumotion.observed import shift_boundary
    from hifumotion.segmentation import local_params, segment
    from hifumotion.sequence import as_spacing_mm

    masked = np.where(excluded, np.float32(background), image)
    # the segmentation's own boundary lies outside the true one by the offset: start it there
    pixel = float(np.mean(as_spacing_mm(spacing_mm)))
    start = shift_boundary(carried, -boundary_offset_mm, pixel) if boundary_offset_mm else carried
    got = segment(masked, start, method, spacing_mm, **{"multiscale": False, "max_iterations": iterations,
                                                        **local_params(method), **params}).mask
    inner = ndimage.binary_erosion(carried, iterations=band_px)
    outer = ndimage.binary_dilation(carried, iterations=band_px)
    got = (got & outer) | inner
    got &= ~excluded
    if boundary_offset_mm:
        got = shift_boundary(got | excluded, boundary_offset_mm, pixel) & ~excluded
    return got if got.any() else carried


def follow(frames: Any, init: Any, spacing_mm=None, *, solids: Solids | None = None,
           boundary_offset_mm: float = 0.0, method: str = "glcv", series: DisplacementSeries | None = None,
           point_step_px: float = 1.0, refine_iterations: int = 0, refine_band_px: int = 2,
           progress: bool = False, continue_bloom: bool = False, bloom_shape_mm: np.ndarray | None = None,
           **params: Any) -> FollowResult:
    """Segment frame 0 and carry its contour through the cine loop by speckle tracking.

    Parameters
    ----------
    frames
        ``(T, H, W)`` in [0, 1] or an :class:`~hifumotion.sequence.ImageSequence`.
    init
        Frame 0's initial contour (anything :func:`~hifumotion.segmentation.segment` takes).
    spacing_mm
        Pixel size (mm), scalar or ``(row, col)``.
    solids
        The known solids on frame 0 (:func:`~hifumotion.observed.solids.known_solids`): the
        floor (static) and the bar (moving rigidly); neither can be target, and neither's
        motion is read as the tissue's.
    boundary_offset_mm
        How far outside the true boundary the imaging system's segmentations lie (mm,
        measured on a phantom); frame 0's free boundary is moved inwards by it.
    method, params
        The level set of frame 0's segmentation and its parameters.
    series
        A displacement already computed for these frames (else
        :func:`~hifumotion.speckle.displacement` runs).
    point_step_px
        Spacing of the carried material points along frame 0's contour (px).
    refine_iterations, refine_band_px
        With ``refine_iterations`` > 0, each carried mask is corrected by that many iterations
        of ``method`` on its frame, within ``refine_band_px`` of the carried boundary
        (:func:`refine_in_band`); 0 (the default, chosen by measurement: docs/decisions.md)
        keeps the carried contour as it is.
    progress
        Show a progress bar.
    continue_bloom, bloom_shape_mm
        Give frame 0's target the strip the bar's bloom hides: where the known resting shape
        (signed distance, mm, positive inside, at frame 0's pixels) holds tissue, or without
        one where tissue is seen at the bloom's edge (:func:`segment_target`).
    """
    from hifumotion.observed.solids import bloom_mask
    from hifumotion.sequence import ImageSequence
    from hifumotion.speckle.displacement import _shifted

    if isinstance(frames, ImageSequence):
        spacing_mm = spacing_mm if spacing_mm is not None else frames.spacing_mm
        frames = frames.frames
    frames = unit_frames(frames)
    shape = frames.shape[1:]
    t0 = time.perf_counter()
    first = segment_target(frames[0], init, spacing_mm, solids=solids, boundary_offset_mm=boundary_offset_mm,
                           method=method, continue_bloom=continue_bloom, bloom_shape_mm=bloom_shape_mm, **params)
    contour0 = Contour.from_mask(first.mask, spacing_mm)
    points0 = contour0.resampled(point_step_px).points_px
    first_s = time.perf_counter() - t0
    if series is None:
        series = track_speckle(frames, spacing_mm, progress=progress, **tracker_solids(solids))
    contours, masks, quality = [], [], []
    # the water's grey level, for the solids in a refined frame (frame 0 away from target and solids)
    background = float(np.median(frames[0][~first.mask & ~first.excluded])) if refine_iterations > 0 else 0.0
    seconds = np.array(series.seconds_per_frame, float)
    seconds[0] += first_s
    for t in range(frames.shape[0]):
        t1 = time.perf_counter()
        pts, q = carry_contour(points0, series, t) if t else (points0, np.ones(len(points0), np.float32))
        c = Contour(pts, contour0.spacing_mm)
        contours.append(c)
        # the material as the image shows it: not clipped at the solids (a penalty contact in
        # a simulation, or a compliant membrane, lets tissue past where the solid was)
        mask = c.to_mask(shape) if t else first.mask
        if t and refine_iterations > 0:
            excluded = np.zeros(shape, bool)
            if solids is not None:
                bar = solids.bar
                if series.rigid_shift_mm is not None:
                    row, col = series.spacing_mm
                    bar = _shifted(bar, series.rigid_shift_mm[t] / np.array([col, row]))
                excluded = solids.floor | bloom_mask(bar, first.bloom_px)
            mask = refine_in_band(frames[t], mask, excluded, background, refine_band_px, refine_iterations,
                                  method, spacing_mm, boundary_offset_mm, params)
        masks.append(mask)
        quality.append(q)
        seconds[t] += time.perf_counter() - t1
    return FollowResult(np.stack(masks), contours, series, np.stack(quality), seconds, first)


__all__ = ["FollowResult", "TargetSegmentation", "follow", "carry_contour", "carry_points", "segment_target",
           "tracker_solids"]
