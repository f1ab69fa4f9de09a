"""The twin's spatial sweep alone: the sample at rest, its true sections and their B-mode images.

:func:`~hifumotion.experiment.generate_twin` images the sweep of the sample resting in
the pool before the bar pushes. Segmenting and reconstructing that sweep needs none of
the physics, so :func:`rest_sweep` makes exactly that part of a twin — the same seeded
sample, probe, pool floor, resting bar, texture, scatterers and clinician's contour —
in seconds instead of the minutes of the simulation, with the sample's exact volume
beside it. It is what the sweep's benchmark (``benchmarks/bench_sweep.py``) segments
on many twins. The sample is the one the full twin would have before it settles under
gravity (the settling moves it by a fraction of a millimetre).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hifumotion.contour import Contour
from hifumotion.experiment import imaging as im
from hifumotion.experiment.blob import Blob
from hifumotion.experiment.config import TwinConfig
from hifumotion.experiment.twin import (
    _seeds,
    clinician_contour,
    echo_maps,
    operator_setup,
    resolution,
    sweep_images,
)
from hifumotion.observed import Setup
from hifumotion.scene.geometry import bar_particles_mm
from hifumotion.particles.section import mapped_section


@dataclass
class RestSweep:
    """A twin's sweep at rest and its truth.

    Attributes
    ----------
    images
        uint8 ``(S, H, W)`` B-mode images of the sweep's planes.
    masks
        bool ``(S, H, W)`` true sections.
    z_mm
        ``(S,)`` plane positions (mm).
    pixel_mm
        Pixel size (mm).
    start
        The sweep plane through the imaging plane, where the clinician clicked.
    initial_contour
        The clinician's rough contour on plane ``start``.
    setup
        What the operator knows (``setup.json``), for the known solids.
    volume_mm3
        The sample's volume (mm³, by quadrature of its shape).
    """

    images: np.ndarray
    masks: np.ndarray
    z_mm: np.ndarray
    pixel_mm: float
    start: int
    initial_contour: Contour
    setup: Setup
    volume_mm3: float


def rest_sweep(cfg: TwinConfig) -> RestSweep:
    """The sweep of the twin ``cfg`` describes, without its physics (module docstring)."""
    seeds = _seeds(cfg)
    blob = Blob.random(cfg.blob.size_mm, cfg.blob.irregularity, cfg.blob.lobes, cfg.blob.bottom_cut, int(seeds[0]))
    res = resolution(cfg, blob)
    dx = res["model_spacing_mm"]
    # the resting frame's origin in the middle of the tank floor, as the full twin places it
    placement = np.array([cfg.tank.size_mm[0] / 2, 0.0, cfg.tank.size_mm[2] / 2])
    rest = blob.particles(dx) + placement
    if cfg.bar.enabled:
        _, axis, tip = bar_particles_mm(cfg.bar, rest, dx)
    else:
        axis, tip = np.array([0.0, -1.0, 0.0]), np.full(3, 1e9)
    probe = im.make_probe(cfg.imaging, rest)
    shift = placement + blob.offset_mm()

    def inside(points_mm):
        return blob.inside(points_mm - shift)

    sections = [mapped_section(rest, rest, dx, probe.plane(z), inside) for z in probe.sweep_z_mm]
    masks = np.stack([s.mask for s in sections])
    trans = im.transducer(cfg.imaging, probe, rest)
    images = sweep_images(probe, masks, echo_maps(cfg, probe, tip, axis, seeds), trans, seeds)
    start = int(np.argmin(np.abs(np.asarray(probe.sweep_z_mm) - probe.z_frames_mm)))
    clicked = clinician_contour(sections[start].contour_mm, cfg.clinician.points, cfg.clinician.error_mm,
                                np.random.default_rng(seeds[6]))
    px = probe.pixel_mm
    return RestSweep(images, masks, np.asarray(probe.sweep_z_mm, float), px, start, Contour.from_mm(clicked, px),
                     operator_setup(cfg, probe, tip, axis, cfg.imaging.frames), res["blob_volume_mm3"])


__all__ = ["RestSweep", "rest_sweep"]
