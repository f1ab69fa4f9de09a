"""An ``observed/`` folder: what a HIFU device's user has, and nothing of the truth.

Written by the synthetic twin (:func:`hifumotion.experiment.generate_twin`) and by
``hifumotion run`` from a user's files, both through :func:`write_observed`; read by the
estimation through :func:`load_observed`. Layout (lengths in mm, times in s)::

    setup.json             the Setup (image geometry, frame interval, pool, bar, push shape)
    sweep/slice_NNN.png    parallel planes through the resting tissue (8-bit B-mode)
    sweep.nii.gz           the same as a 3D volume (3D Slicer)
    sweep_positions.csv    slice, z_mm
    frames/frame_NNNN.png  the imaging plane's time series during the push
    frames.nii.gz          the same as 2D+t
    initial_contour.csv    the clinician's clicked contour (frame, point, x_px, y_px, x_mm, y_mm)

The PNGs are what every command reads; a NIfTI beside them (for 3D Slicer) must hold the same
images on the same grid, or the folder is refused: two versions of one series that disagree
would leave which one a result came from to chance (``track`` and ``calibrate`` once read one
each).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hifumotion.contour import Contour
from hifumotion.errors import InputError
from hifumotion.observed.setup import Setup, read_setup, write_setup


@dataclass
class Observed:
    """An observed experiment.

    Attributes
    ----------
    sweep
        ``(S, H, W)`` uint8 B-mode images of parallel planes through the resting tissue.
    sweep_z_mm
        ``(S,)`` plane positions (mm, along the pool's z).
    frames
        ``(T, H, W)`` uint8 B-mode frames of the imaging plane during the push.
    initial_contour
        The clinician's contour on frame ``setup.initial_contour_frame``.
    setup
        What the operator knows (:class:`~hifumotion.observed.setup.Setup`).
    """

    sweep: np.ndarray
    sweep_z_mm: np.ndarray
    frames: np.ndarray
    initial_contour: Contour
    setup: Setup

    @property
    def frame_interval_s(self) -> float:
        return self.setup.frame_interval_s

    @property
    def pixel_mm(self) -> float:
        return self.setup.imaging.pixel_mm

    @property
    def initial_frame(self) -> int:
        return self.setup.initial_contour_frame

    @property
    def times_s(self) -> np.ndarray:
        return np.arange(len(self.frames)) * self.frame_interval_s


def numbered_files(folder: Path, prefix: str, suffix: str = ".png") -> list[Path]:
    """``folder``'s ``PREFIXNNNN.png`` files in the order of their numbers (``frame_10`` after
    ``frame_9``, not after ``frame_1``): numbered from 0, with no gap and no number twice, or
    one error naming the file or the missing number."""
    files = [p for p in folder.glob(f"{prefix}*{suffix}")] if folder.is_dir() else []
    if not files:
        raise InputError(f"no {prefix}NNNN{suffix} images", folder)
    numbered: dict[int, Path] = {}
    for p in files:
        digits = p.name[len(prefix):-len(suffix)]
        if not (digits.isascii() and digits.isdigit()):
            raise InputError(f"not a numbered image (expected {prefix}NNNN{suffix})", p)
        n = int(digits)
        if n in numbered:
            raise InputError(f"number {n} twice: {numbered[n].name} and {p.name}", folder)
        numbered[n] = p
    order = sorted(numbered)
    if order[0] != 0:
        raise InputError(f"the images are numbered from {order[0]}; expected from 0 ({prefix}0000{suffix}: "
                         "setup.json's frame numbers count from it)", folder)
    if order[-1] != len(order) - 1:
        missing = next(i for i, n in enumerate(order) if i != n)
        raise InputError(f"{prefix}{missing:04d}{suffix} is missing ({len(order)} images numbered up to "
                         f"{order[-1]})", folder)
    return [numbered[n] for n in order]


def _stack(folder: Path, prefix: str, shape: tuple[int, int]) -> np.ndarray:
    from hifumotion.io.raster import read_raster_array

    files = numbered_files(folder, prefix)
    images = []
    for p in files:
        image = read_raster_array(p)[0]
        if image.ndim != 2 or image.shape != tuple(shape):
            raise InputError(f"image of shape {image.shape}; setup.json's imaging.image_shape is {tuple(shape)}", p)
        images.append(image)
    return np.stack(images)


def load_observed(folder: str | Path) -> Observed:
    """Read ``folder`` (module docstring); a missing or malformed part is one clear error."""
    from hifumotion.io.files import require_regular_file

    root = Path(folder)
    if not root.is_dir():
        raise InputError("no such folder (expected an observed experiment: setup.json, sweep/, frames/)", root)
    setup_path = root / "setup.json"
    if not setup_path.exists() and not setup_path.is_symlink():
        raise InputError("not an observed experiment folder (no setup.json)", root)
    require_regular_file(setup_path, "setup.json")     # a folder or a FIFO of that name: said as such
    setup = read_setup(setup_path)
    shape = setup.imaging.image_shape
    sweep = _stack(root / "sweep", "slice_", shape)
    frames = _stack(root / "frames", "frame_", shape)
    if len(frames) != setup.frames:
        raise InputError(f"{len(frames)} frame images; setup.json says frames = {setup.frames}", root / "frames")
    _same_as_pngs(root / "frames.nii.gz", frames, "frames/", setup.pixel_mm, spacing_t=setup.frame_interval_s,
                  what_t="setup.json's frame_interval_s", unit_t="s", stepped_dimension=4)
    pos_path = require_regular_file(root / "sweep_positions.csv", "sweep_positions.csv")
    with open(pos_path, newline="", encoding="utf-8-sig") as fh:
        try:
            z = np.array([float(r["z_mm"]) for r in csv.DictReader(fh)])
        except (KeyError, ValueError, TypeError):
            raise InputError("expected a z_mm column of numbers", pos_path) from None
    if len(z) != len(sweep):
        raise InputError(f"{len(z)} positions for {len(sweep)} sweep images", pos_path)
    if not np.all(np.isfinite(z)) or (len(z) > 1 and not np.all(np.diff(z) > 0)):
        raise InputError("the planes' z_mm must be finite and increasing", pos_path)
    said = setup.imaging.sweep_z_mm
    if said and (len(said) != len(z) or not np.allclose(said, z, rtol=0, atol=1e-3)):
        raise InputError(f"imaging.sweep_z_mm lists {len(said)} planes that do not match sweep_positions.csv's "
                         f"{len(z)} ({pos_path.name}); give the same positions in both, or leave sweep_z_mm empty",
                         setup_path)
    steps = np.diff(z)
    even = len(z) > 1 and np.allclose(steps, steps[0], rtol=1e-3, atol=1e-6)
    _same_as_pngs(root / "sweep.nii.gz", sweep, "sweep/", setup.pixel_mm,
                  spacing_t=float(steps[0]) if even else None, what_t="sweep_positions.csv's spacing", unit_t="mm", stepped_dimension=3)
    contour = read_initial_contour(root, setup)
    from hifumotion.segmentation.levelset import check_init_region

    check_init_region(contour, frames.shape[1:], str(root / "initial_contour.csv"))
    return Observed(sweep, z, frames, contour, setup)


def read_initial_contour(folder: str | Path, setup: Setup) -> Contour:
    """The clinician's contour of ``setup.initial_contour_frame`` from ``folder/initial_contour.csv``."""
    from hifumotion.io.writers import read_contours_csv

    path = Path(folder) / "initial_contour.csv"
    contours = read_contours_csv(path, spacing_mm=setup.pixel_mm)
    wanted = [c for label, c in contours.items() if _frame_label(label) == setup.initial_contour_frame]
    if not wanted:
        raise InputError(f"no contour of frame {setup.initial_contour_frame} (setup.json's initial_contour_frame)",
                         path)
    return wanted[0]


def _same_as_pngs(path: Path, stack: np.ndarray, pngs: str, pixel_mm: float, spacing_t: float | None,
                  what_t: str, unit_t: str, stepped_dimension: int) -> None:
    """A NIfTI ``path`` beside the PNG ``stack`` holds the same images on the same grid
    (module docstring); absent, nothing to check. The step between images (``spacing_t``,
    in ``unit_t``) is compared where the volume records one: an image of ``stepped_dimension``
    dimensions (a cine written as 2D+t has four, its last the frame interval)."""
    if not path.exists() and not path.is_symlink():
        return
    import SimpleITK as sitk

    from hifumotion.io.files import require_regular_file

    require_regular_file(path, "NIfTI volume")
    from hifumotion.io.itk import check_nifti

    check_nifti(path)       # a truncated volume is said to be truncated, not to differ from the PNGs
    try:
        image = sitk.ReadImage(str(path))
    except RuntimeError:
        raise InputError(f"not a readable NIfTI volume (it should hold the images of {pngs})", path) from None
    volume = sitk.GetArrayViewFromImage(image)
    volume = volume.reshape((-1,) + volume.shape[-2:]) if volume.ndim >= 2 else volume
    if volume.shape != stack.shape:
        raise InputError(f"holds images of shape {tuple(volume.shape)}; {pngs} holds {tuple(stack.shape)} "
                         "(remove one, or write both again)", path)
    differ = np.flatnonzero(np.any(volume.reshape(len(stack), -1) != stack.reshape(len(stack), -1), axis=1))
    if differ.size:
        raise InputError(f"image {differ[0]} differs from {pngs}'s ({differ.size} of {len(stack)} differ; "
                         "remove one, or write both again)", path)
    spacing = image.GetSpacing()
    if not np.allclose(spacing[:2], pixel_mm, rtol=1e-3):
        raise InputError(f"pixel size {spacing[0]:.6g} × {spacing[1]:.6g} mm; setup.json's imaging.pixel_mm "
                         f"is {pixel_mm:.6g}", path)
    if spacing_t is not None and len(stack) > 1 and image.GetDimension() == stepped_dimension:
        step = spacing[-1]
        if not np.isclose(step, spacing_t, rtol=1e-3):
            raise InputError(f"spacing {step:.6g} {unit_t} between images; {what_t} is {spacing_t:.6g} {unit_t}", path)


def _frame_label(label: str) -> int | None:
    try:
        return int(float(label))
    except ValueError:
        return None


def write_observed(folder: str | Path, setup: Setup, sweep: np.ndarray, sweep_z_mm: np.ndarray,
                   frames: np.ndarray, initial_contour: Contour) -> Path:
    """Write the layout of the module docstring into ``folder``; ``sweep``/``frames`` are
    uint8 ``(N, H, W)`` stacks on the grid of ``setup.imaging``."""
    from hifumotion.io.files import write_text
    from hifumotion.io.writers import write_contours_csv, write_nifti, write_png_stack

    folder = Path(folder)
    px = setup.pixel_mm
    z = np.asarray(sweep_z_mm, float)
    if len(z) != len(sweep) or len(frames) != setup.frames:
        raise ValueError("the sweep's positions and the frames must match the setup")
    write_png_stack(folder / "frames", frames, prefix="frame_", digits=4)
    write_nifti(folder / "frames.nii.gz", frames, (px, px), frame_interval_s=setup.frame_interval_s)
    write_png_stack(folder / "sweep", sweep, prefix="slice_", digits=3)
    write_nifti(folder / "sweep.nii.gz", sweep, (px, px), slice_positions_mm=z)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["slice", "z_mm"])
    w.writerows([i, f"{v:.6f}"] for i, v in enumerate(z))
    write_text(folder / "sweep_positions.csv", buf.getvalue())
    write_contours_csv(folder / "initial_contour.csv", {setup.initial_contour_frame: initial_contour})
    write_setup(folder / "setup.json", setup)
    return folder


__all__ = ["Observed", "load_observed", "read_initial_contour", "write_observed"]
