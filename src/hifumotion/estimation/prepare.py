"""Step 1 of the estimation: from an observed experiment to what the model is fitted to.

Only the observer's data is read (``observed/``, :func:`~hifumotion.observed.load_observed`):

1. the spatial sweep is segmented with GLCV from the clinician's contour
   (:func:`~hifumotion.segmentation.sweep.segment_sweep`), starting in the sweep plane
   nearest the imaging plane (the contour was clicked there, on the resting tissue);
2. the masks are reconstructed into the 3D tissue (:func:`~hifumotion.reconstruction.reconstruct`)
   and placed in the tank frame from the image geometry of ``setup.json``;
3. the time series is tracked: by default frame 0 is segmented with GLCV from the same
   contour (the known solids taken out of the image) and its contour carried through the
   frames by the speckle's measured displacement (:func:`~hifumotion.speckle.follow`),
   whose material points are kept for the fit; ``tracking="glcv"`` re-segments every
   frame instead (:func:`~hifumotion.segmentation.track`, what the paper did). Where the
   user gives contours of their own (a CSV; the paper used a physician's), those replace
   the tracked ones.

Coordinates: the reconstruction is in image mm (x = column × pixel, y = row ×
pixel, z = the plane's position); the tank frame adds ``offset_mm``
(``setup.json``: ``imaging.row0_col0_mm``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.errors import InputError
from hifumotion.estimation.settings import BLOOM_RULES, DEFAULT_BLOOM_RULE
from hifumotion.observed import Observed
from hifumotion.scene import Plane
from hifumotion.reconstruction import Reconstruction, reconstruct
from hifumotion.segmentation.sweep import SweepSegmentation, segment_sweep

Progress = Callable[[str, float], None]


@dataclass
class Observation:
    """An observed experiment made ready for fitting.

    Attributes
    ----------
    observed
        The raw data (images, geometry, the clinician's contour).
    sweep
        The sweep's masks (GLCV).
    reconstruction
        The resting tissue in 3D (image mm; add ``offset_mm`` for the tank frame).
    offset_mm
        ``(3,)`` tank position of the image origin (mm).
    frame_masks
        ``(T, H, W)`` bool: the target in every frame (tracked, or the user's where given).
    contour_source
        ``"speckle"``, ``"glcv"`` or the path of the user's contour file.
    motion
        The speckle tracking (:class:`~hifumotion.speckle.FollowResult`: the displacement
        field, the carried contour points and their quality); ``None`` with GLCV tracking.
    timings_s
        Wall time of each step (s).
    bar_cap
        What the continuation of the top under the resting bar did
        (:class:`~hifumotion.observed.bar_cap.BarCap`); ``None`` when it was not asked for.
    bloom_continuation
        Whether frame 0's target was given the strip the bar's bloom hides (:func:`prepare`'s
        ``bloom_continuation``); the online loop segments frame 0 the same way.
    bloom_continued_by
        What decided which of the strip's pixels are target: ``"reconstruction"`` (its top
        continued under the bar) or ``"image"`` (tissue at the bloom's edge); ``""`` without
        the continuation.
    """

    observed: Observed
    sweep: SweepSegmentation
    reconstruction: Reconstruction
    offset_mm: np.ndarray
    frame_masks: np.ndarray
    contour_source: str
    timings_s: dict = field(default_factory=dict)
    motion: object | None = None
    bar_cap: object | None = None
    bloom_continuation: bool = False
    bloom_continued_by: str = ""

    @property
    def pixel_mm(self) -> float:
        return self.observed.pixel_mm

    @property
    def frame_plane(self) -> Plane:
        """The time series' imaging plane in the tank frame."""
        from hifumotion.observed.solids import imaging_plane

        return imaging_plane(self.observed.setup)

    def reference_shape(self):
        """The frame-0 shape the predictions carry: the frame-0 mask in the imaging plane,
        continued out of it by the reconstruction (tank frame)."""
        from hifumotion.estimation.reference import ReferenceShape

        rec = self.reconstruction
        return ReferenceShape(self.frame0_mask(), self.frame_plane, rec.distance_mm, rec.voxel_mm,
                              tuple(float(v) for v in np.asarray(rec.origin_mm) + self.offset_mm))

    def frame0_mask(self) -> np.ndarray:
        """The frame-0 target the predictions carry: the observed one, with its top under the
        resting bar continued up to the reconstruction's where the sweep's top was continued
        (:func:`~hifumotion.observed.bar_cap.fill_section_under_bar`): the observed contour
        stops at the bar's bloom, the tissue does not."""
        mask = self.frame_masks[0]
        cap = self.bar_cap
        if cap is None or cap.skipped or not cap.filled_voxels:
            return mask
        from hifumotion.observed.bar_cap import fill_section_under_bar

        b = self.observed.setup.bar
        pts = self.frame_plane.points_mm()
        inside = self.inside_tank(pts.reshape(-1, 3)).reshape(mask.shape)
        return fill_section_under_bar(mask, pts, inside, b.tip_at_rest_mm, b.direction, b.radius_mm, BAR_MARGIN_MM)

    def inside_tank(self, points_mm: np.ndarray) -> np.ndarray:
        """Signed distance (mm, positive inside) of tank points to the reconstructed resting tissue."""
        return self.reconstruction.inside(np.asarray(points_mm, float) - self.offset_mm)


#: Margin (mm) around the resting bar whose pixels the sweep's segmentation may not enter (the
#: bar's blur; the time series measures the blur instead, :func:`~hifumotion.speckle.segment_target`).
BAR_MARGIN_MM = 0.5


def read_user_contours(path: str | Path, observed: Observed) -> dict[int, np.ndarray]:
    """Masks of the frames a user's contour CSV (``frame, x_px, y_px`` or ``x_mm, y_mm``) outlines."""
    from hifumotion.io.writers import read_contours_csv

    masks = {}
    shape = observed.frames.shape[1:]
    for label, contour in read_contours_csv(path, spacing_mm=observed.pixel_mm).items():
        try:
            frame = int(float(label))
        except ValueError:
            raise InputError(f"frame label {label!r} is not a frame number", path) from None
        if not 0 <= frame < len(observed.frames):
            raise InputError(f"frame {frame} is outside the {len(observed.frames)} observed frames", path)
        masks[frame] = contour.to_mask(shape)
    return masks


def frame_solids(observed: Observed):
    """The known solids (:class:`~hifumotion.observed.solids.Solids`) on the time series' plane."""
    from hifumotion.observed.solids import check_bar_in_image, imaging_plane, known_solids

    solids = known_solids(imaging_plane(observed.setup), observed.setup)
    check_bar_in_image(observed.frames[0], solids, "setup.json")
    return solids


def known_solid_mask(setup, z_mm: float) -> np.ndarray:
    """``(H, W)`` bool: what the operator knows cannot be tissue in the plane at ``z_mm`` (the
    pool's floor, and the bar where it rests, grown by :data:`BAR_MARGIN_MM`), from ``setup.json``."""
    from hifumotion.observed.solids import imaging_plane, known_solids

    return known_solids(imaging_plane(setup, z_mm), setup, BAR_MARGIN_MM).any


def _fill_bar_cap(masks: np.ndarray, observed: Observed, boundary_offset_mm: float):
    """The sweep's masks with the top the bar's exclusion cut continued under it."""
    from hifumotion.observed.bar_cap import fill_under_bar
    from hifumotion.observed.solids import imaging_plane

    z = np.asarray(observed.sweep_z_mm, float)
    points = np.stack([imaging_plane(observed.setup, zk).points_mm() for zk in z])
    gap = float(np.median(np.abs(np.diff(np.sort(z))))) if len(z) > 1 else observed.pixel_mm
    b = observed.setup.bar
    return fill_under_bar(masks, points, b.tip_at_rest_mm, b.direction, b.radius_mm, BAR_MARGIN_MM,
                          (observed.pixel_mm, gap), boundary_offset_mm)


def prepare(observed: Observed, contours_csv: str | Path | None = None, method: str = "glcv",
            progress: Progress | None = None, boundary_offset_mm: float = 0.0,
            tracking: str = "speckle", fill_bar_cap: bool = True, bloom_continuation: str = DEFAULT_BLOOM_RULE
            ) -> Observation:
    """Segment, reconstruct and track an observed experiment (module docstring).

    ``boundary_offset_mm``: how far outside the true boundary the imaging system's
    segmentations lie, measured on a phantom of known size
    (for instance :func:`~hifumotion.experiment.boundary_offset.measure_boundary_offset` on a
    simulated one); the sweep's and
    the tracked frames' masks are moved inwards by it (the user's own contours are not).

    ``fill_bar_cap``: continue the sweep's top into the band around the resting bar that its
    segmentation had to leave out (:func:`~hifumotion.observed.bar_cap.fill_under_bar`), so the
    reconstructed tissue touches the bar as the real one does.

    ``bloom_continuation`` (one of :data:`BLOOM_RULES`), with speckle tracking: what gives frame
    0's target the strip the bar's bloom hides, so that the tracked frame 0 and the model's shape
    agree there. ``"reconstruction"``: where the reconstruction (its top continued under the bar,
    ``fill_bar_cap``) holds tissue; without a bar cap the strip stays cut. ``"image"``: the same,
    and without a bar cap where tissue is seen at the bloom's edge
    (:func:`~hifumotion.speckle.segment_target`). ``"off"``: the strip stays cut.
    """
    if tracking not in ("speckle", "glcv"):
        raise InputError(f"unknown tracking {tracking!r}; expected speckle or glcv", "tracking")
    if bloom_continuation not in BLOOM_RULES:
        raise InputError(f"unknown rule {bloom_continuation!r}; expected {', '.join(BLOOM_RULES)}",
                         "bloom_continuation")
    tell = progress or (lambda stage, fraction: None)
    timings: dict[str, float] = {}
    sweep, rec, cap = _sweep_and_reconstruction(observed, method, fill_bar_cap, boundary_offset_mm, tell, timings)
    t2 = time.perf_counter()
    given = read_user_contours(contours_csv, observed) if contours_csv is not None else {}
    if observed.initial_frame != 0:
        raise InputError("the initial contour must be on frame 0 to track the series", "initial_contour.csv")
    # with a bar cap, the reconstruction says where the bloom hides tissue at frame 0
    shape = (_reconstruction_in_frame_plane(observed, rec) if tracking == "speckle" and bloom_continuation != "off"
             and cap is not None and not cap.skipped else None)
    continue_bloom = shape is not None or bloom_continuation == "image"
    masks, motion = _track_frames(observed, method, tracking, boundary_offset_mm, continue_bloom, shape)
    for frame, m in given.items():   # the user's contours replace the tracked ones where given
        masks[frame] = m
    source = str(contours_csv) if given else tracking
    tell("track frames", 1.0)
    timings["track_s"] = time.perf_counter() - t2
    continued = continue_bloom and motion is not None
    return Observation(observed, sweep, rec, observed.setup.image_origin_mm, masks, source, timings, motion, cap,
                       continued, ("reconstruction" if shape is not None else "image") if continued else "")


def _sweep_and_reconstruction(observed: Observed, method: str, fill_bar_cap: bool, boundary_offset_mm: float,
                              tell, timings: dict):
    """The sweep segmented (the known solids left out, the top continued under the resting bar
    where ``fill_bar_cap``) and reconstructed, its surface moved inwards by the boundary offset."""
    from hifumotion.observed import shift_boundary

    px, init = observed.pixel_mm, observed.initial_contour
    t0 = time.perf_counter()
    start = int(np.argmin(np.abs(observed.sweep_z_mm - observed.setup.imaging.frames_plane_z_mm)))
    exclude = np.stack([known_solid_mask(observed.setup, z) for z in observed.sweep_z_mm])
    sweep = segment_sweep(observed.sweep, init, start, method, spacing=px, exclude=exclude)
    cap = None
    if fill_bar_cap and observed.setup.bar.enabled:
        sweep.masks, cap = _fill_bar_cap(sweep.masks, observed, boundary_offset_mm)
        sweep.notes.append(f"under the resting bar: {cap.skipped}" if cap.skipped else
                           f"under the resting bar: {cap.filled_voxels} pixels of the top continued "
                           f"from {cap.fitted_columns} seen columns into {cap.cut_columns} cut ones")
    tell("segment sweep", 1.0)
    timings["segment_sweep_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    if sweep.present.sum() < 2:
        raise InputError("the sweep's segmentation holds the tissue in fewer than two planes; "
                         "check the initial contour", "sweep")
    # the surface moves inwards by the offset at sub-pixel accuracy; the stored masks by whole pixels
    rec = reconstruct(sweep.masks, px, observed.sweep_z_mm, boundary_offset_mm=boundary_offset_mm)
    if boundary_offset_mm:
        sweep.masks = np.stack([shift_boundary(m, boundary_offset_mm, px) if m.any() else m for m in sweep.masks])
    tell("reconstruct", 1.0)
    timings["reconstruct_s"] = time.perf_counter() - t1
    return sweep, rec, cap


def _reconstruction_in_frame_plane(observed: Observed, rec) -> np.ndarray:
    """The reconstruction's signed distance (mm, positive inside) at the frames' pixels."""
    from hifumotion.observed.solids import imaging_plane

    plane = imaging_plane(observed.setup)
    pts = plane.points_mm().reshape(-1, 3)
    return rec.inside(pts - observed.setup.image_origin_mm).reshape(tuple(plane.shape))


def _track_frames(observed: Observed, method: str, tracking: str, boundary_offset_mm: float,
                  continue_bloom: bool, bloom_shape_mm: np.ndarray | None):
    """Every frame's target mask (the online mode needs them all) and, with speckle tracking, the
    motion it followed. The floor, and the bar's place at rest, are left out: pushing along its
    axis the bar only moves away from there, into the tissue, so no frame has tissue there."""
    from hifumotion.observed import shift_boundary
    from hifumotion.segmentation import track

    px, init = observed.pixel_mm, observed.initial_contour
    if tracking == "speckle":
        from hifumotion.speckle import follow

        motion = follow(observed.frames.astype(np.float32) / 255.0, init, px, solids=frame_solids(observed),
                        boundary_offset_mm=boundary_offset_mm, method=method, continue_bloom=continue_bloom,
                        bloom_shape_mm=bloom_shape_mm)
        return motion.masks.copy(), motion
    exclude = known_solid_mask(observed.setup, observed.setup.imaging.frames_plane_z_mm)
    masks = track(observed.frames, init, method, spacing=px, exclude=exclude).masks
    if boundary_offset_mm:
        masks = np.stack([shift_boundary(m, boundary_offset_mm, px) for m in masks])
    return masks, None


__all__ = ["Observation", "frame_solids", "known_solid_mask", "prepare", "read_user_contours"]
