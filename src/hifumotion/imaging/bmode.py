"""A fast B-mode simulator: point scatterers, a depth-dependent pulse-echo PSF, attenuation
with imperfect time-gain compensation, envelope detection and log compression.

Model (in complex baseband, the standard convolution model of speckle):

* **Scatterers.** Random points with uniform positions, at least
  :attr:`Transducer.scatterers_per_cell` per resolution cell, each with a
  complex Gaussian amplitude (random phase) scaled by the square root of the
  local echogenicity (backscatter power relative to soft tissue). Positions
  are in *material* coordinates: a moving or deforming target moves its
  scatterers (:func:`simulate_frame` takes the current positions), so the
  speckle stays attached to the tissue across frames of a cine loop.
* **Pulse-echo PSF.** Axially a Gaussian envelope of the pulse at the centre
  frequency (RF: a Gaussian-modulated cosine; in baseband the carrier is the
  phase ``exp(-i 2 k z)`` of each scatterer); laterally a Gaussian whose
  width grows away from the focus like a Gaussian beam,
  ``σ_x(z) = σ_x0 √(1 + ((z − z_f) / z_R)²)``.
* **Attenuation.** Round-trip amplitude loss ``exp(−2 α f0 z)`` (α in
  dB/cm/MHz), compensated by a time-gain curve that is imperfect: a slope
  error and a smooth random ripple, so brightness is uneven with depth as in
  real HIFU images.
* **Detection.** Thermal noise is added to the IQ signal; the envelope
  ``|IQ|`` is log-compressed to a dynamic range and quantised to 8 bits.
* **Options.** Acoustic shadow or enhancement below the target (extra
  attenuation along each beam, i.e. image column, through the target), a
  bright specular reflection on the part of the boundary facing the probe.

Rows are depth (axial, z), columns lateral (x); everything in mm, seconds, MHz.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from hifumotion.errors import InputError

SPEED_OF_SOUND_MM_PER_US = 1.54
#: Gaussian σ from FWHM.
FWHM_TO_SIGMA = 1.0 / (2.0 * np.sqrt(2.0 * np.log(2.0)))


@dataclass(frozen=True)
class Transducer:
    """The imaging system.

    Attributes
    ----------
    center_frequency_mhz
        Centre frequency f0 (MHz). HIFU guidance probes: 3–5 MHz.
    axial_fwhm_mm
        FWHM of the pulse-echo envelope along the beam (mm): the axial resolution.
    lateral_fwhm_mm
        FWHM of the pulse-echo beam at the focus (mm): the lateral resolution.
    focus_depth_mm
        Depth of the transmit/receive focus (mm).
    rayleigh_length_mm
        Depth of field: the beam width grows by √2 this far from the focus (mm).
    attenuation_db_cm_mhz
        Attenuation coefficient α of the tissue (dB/cm/MHz); soft tissue ≈ 0.5.
    tgc_error
        Relative error of the time-gain compensation slope (0 = perfect).
    tgc_ripple_db
        Amplitude of the smooth random ripple of the gain curve (dB).
    dynamic_range_db
        Log-compression dynamic range (dB).
    noise_db
        Thermal noise level relative to the mean soft-tissue echo at the focus (dB).
    scatterers_per_cell
        Scatterers per resolution cell (≥ 10 for fully developed speckle).
    """

    center_frequency_mhz: float = 3.5
    axial_fwhm_mm: float = 0.45
    lateral_fwhm_mm: float = 1.1
    focus_depth_mm: float = 30.0
    rayleigh_length_mm: float = 25.0
    attenuation_db_cm_mhz: float = 0.5
    tgc_error: float = 0.15
    tgc_ripple_db: float = 2.0
    dynamic_range_db: float = 50.0
    noise_db: float = -45.0
    scatterers_per_cell: float = 12.0

    def __post_init__(self) -> None:
        for name in ("center_frequency_mhz", "axial_fwhm_mm", "lateral_fwhm_mm", "rayleigh_length_mm",
                     "dynamic_range_db", "scatterers_per_cell"):
            if not getattr(self, name) > 0:
                raise InputError(f"must be positive, got {getattr(self, name)!r}", f"transducer.{name}")
        if self.attenuation_db_cm_mhz < 0:
            raise InputError("must be ≥ 0", "transducer.attenuation_db_cm_mhz")

    @property
    def wavelength_mm(self) -> float:
        return SPEED_OF_SOUND_MM_PER_US / self.center_frequency_mhz

    def lateral_sigma_mm(self, depth_mm: np.ndarray) -> np.ndarray:
        """σ of the lateral pulse-echo PSF at each depth (Gaussian-beam widening off focus)."""
        z = (np.asarray(depth_mm, float) - self.focus_depth_mm) / self.rayleigh_length_mm
        return self.lateral_fwhm_mm * FWHM_TO_SIGMA * np.sqrt(1.0 + z * z)

    @property
    def axial_sigma_mm(self) -> float:
        return self.axial_fwhm_mm * FWHM_TO_SIGMA

    def resolution_cell_mm2(self) -> float:
        """Area of the resolution cell at the focus (FWHM × FWHM), mm²."""
        return self.axial_fwhm_mm * self.lateral_fwhm_mm


@dataclass
class Scatterers:
    """Point scatterers in material coordinates.

    Attributes
    ----------
    positions_mm
        ``(N, 2)`` material positions ``(x_mm, z_mm)`` (lateral, depth).
    amplitudes
        ``(N,)`` complex Gaussian amplitudes with unit mean power (multiplied by
        √echogenicity when imaged).
    """

    positions_mm: np.ndarray
    amplitudes: np.ndarray

    @classmethod
    def uniform(cls, extent_mm: tuple[float, float], transducer: Transducer, seed: int | np.random.Generator = 0,
                margin_mm: float = 3.0) -> "Scatterers":
        """Uniform random scatterers over ``extent_mm = (depth, width)`` plus a margin, at the
        transducer's density (``scatterers_per_cell`` per resolution cell)."""
        rng = np.random.default_rng(seed)
        depth, width = extent_mm
        area = (depth + 2 * margin_mm) * (width + 2 * margin_mm)
        n = int(np.ceil(transducer.scatterers_per_cell * area / transducer.resolution_cell_mm2()))
        x = rng.uniform(-margin_mm, width + margin_mm, n)
        z = rng.uniform(-margin_mm, depth + margin_mm, n)
        amp = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2.0)
        return cls(np.column_stack([x, z]), amp.astype(np.complex128))


@njit(cache=True)
def _splat(xs, zs, amps, two_k, h, w, dx, dz, out):
    """Bilinear splat of complex scatterers with carrier phase ``exp(−i 2k z)`` onto a grid."""
    for n in range(xs.shape[0]):
        fx = xs[n] / dx
        fz = zs[n] / dz
        j0 = int(np.floor(fx))
        i0 = int(np.floor(fz))
        tx = fx - j0
        tz = fz - i0
        phase = -two_k * zs[n]
        a = amps[n] * complex(np.cos(phase), np.sin(phase))
        for di in range(2):
            i = i0 + di
            if i < 0 or i >= h:
                continue
            wz = tz if di == 1 else 1.0 - tz
            for dj in range(2):
                j = j0 + dj
                if j < 0 or j >= w:
                    continue
                wx = tx if dj == 1 else 1.0 - tx
                out[i, j] += a * (wz * wx)


@njit(cache=True)
def _axial_blur(field, kernel):
    """Convolve each column with ``kernel`` (odd length), zero outside."""
    h, w = field.shape
    r = kernel.shape[0] // 2
    out = np.zeros_like(field)
    for i in range(h):
        for k in range(-r, r + 1):
            ii = i + k
            if ii < 0 or ii >= h:
                continue
            c = kernel[k + r]
            for j in range(w):
                out[i, j] += c * field[ii, j]
    return out


@njit(cache=True)
def _lateral_blur(field, sigmas_px):
    """Convolve each row i with a Gaussian of σ = ``sigmas_px[i]`` (normalised to unit peak gain)."""
    h, w = field.shape
    out = np.zeros_like(field)
    for i in range(h):
        s = sigmas_px[i]
        r = int(np.ceil(3.0 * s))
        ker = np.empty(2 * r + 1)
        for k in range(-r, r + 1):
            ker[k + r] = np.exp(-0.5 * (k / s) ** 2)
        for j in range(w):
            acc = 0.0 + 0.0j
            for k in range(-r, r + 1):
                jj = j + k
                if 0 <= jj < w:
                    acc += ker[k + r] * field[i, jj]
            out[i, j] = acc
    return out


@dataclass(frozen=True)
class BModeOptions:
    """Optional effects.

    Attributes
    ----------
    shadow_db_per_mm
        Extra round-trip attenuation per mm of path through the target (dB/mm):
        positive casts an acoustic shadow below it, negative an enhancement.
    specular_gain
        Amplitude of the specular echo on the boundary facing the probe,
        relative to a soft-tissue scatterer (0 = none).
    seed
        Seed of the TGC ripple and the noise.
    """

    shadow_db_per_mm: float = 0.0
    specular_gain: float = 0.0
    seed: int = 0


@dataclass
class BModeImage:
    """A simulated frame: the 8-bit image, its envelope (linear) and its geometry."""

    image: np.ndarray  # uint8 (H, W)
    envelope: np.ndarray  # float (H, W), linear, after TGC, before compression
    spacing_mm: tuple[float, float]
    extras: dict = field(default_factory=dict)


def tgc_gain_db(depth_mm: np.ndarray, transducer: Transducer, rng: np.random.Generator) -> np.ndarray:
    """The applied time-gain curve (dB): nominal compensation of the round-trip attenuation,
    with a slope error and a smooth random ripple (a sum of three low-frequency sines)."""
    z = np.asarray(depth_mm, float)
    nominal = 2.0 * transducer.attenuation_db_cm_mhz * transducer.center_frequency_mhz * z / 10.0
    span = max(float(z.max() - z.min()), 1e-6)
    ripple = np.zeros_like(z)
    for _ in range(3):
        freq = rng.uniform(0.5, 2.0) / span
        ripple += np.sin(2 * np.pi * freq * z + rng.uniform(0, 2 * np.pi))
    return nominal * (1.0 - transducer.tgc_error) + transducer.tgc_ripple_db * ripple / 3.0


def simulate_frame(echogenicity_at, scatterers: Scatterers, positions_mm: np.ndarray | None,
                   shape: tuple[int, int], spacing_mm: tuple[float, float], transducer: Transducer = Transducer(),
                   options: BModeOptions = BModeOptions(), target_mask: np.ndarray | None = None) -> BModeImage:
    """Simulate one B-mode frame.

    Parameters
    ----------
    echogenicity_at
        Function ``(N, 2) material positions (x_mm, z_mm) -> (N,)`` relative
        backscatter power (soft tissue 1, water ~0), evaluated at the scatterers'
        material positions, so each scatterer keeps its tissue's echogenicity.
    scatterers
        The scatterers (material positions and amplitudes).
    positions_mm
        Their current positions ``(N, 2)`` in the image (mm); ``None`` = material positions.
    shape, spacing_mm
        Output image size ``(H, W)`` and pixel size ``(row = depth, col = lateral)`` in mm.
    transducer, options
        The imaging system and optional effects.
    target_mask
        Boolean ``(H, W)`` mask of the target in this frame, needed for shadowing
        and the specular boundary.
    """
    h, w = int(shape[0]), int(shape[1])
    dz, dx = float(spacing_mm[0]), float(spacing_mm[1])
    if h < 2 or w < 2 or dz <= 0 or dx <= 0:
        raise InputError(f"expected an image of at least 2 x 2 px with positive spacing, got {shape}, {spacing_mm}")
    rng = np.random.default_rng(options.seed)
    pos = scatterers.positions_mm if positions_mm is None else np.asarray(positions_mm, float)
    power = np.maximum(np.asarray(echogenicity_at(scatterers.positions_mm), float), 0.0)
    amps = scatterers.amplitudes * np.sqrt(power)
    two_k = 4.0 * np.pi / transducer.wavelength_mm
    field_iq = np.zeros((h, w), np.complex128)
    # pixel centres at (j dx, i dz): shift positions so a scatterer at a centre lands on it
    _splat(pos[:, 0].copy(), pos[:, 1].copy(), amps, two_k, h, w, dx, dz, field_iq)
    if options.specular_gain > 0 and target_mask is not None:
        field_iq += _specular(target_mask, options.specular_gain, transducer, dz, dx, rng)
    # pulse-echo PSF: axial Gaussian envelope, lateral Gaussian widening off focus
    sz = transducer.axial_sigma_mm / dz
    r = int(np.ceil(3 * sz))
    axial = np.exp(-0.5 * (np.arange(-r, r + 1) / sz) ** 2)
    depth = np.arange(h) * dz
    iq = _lateral_blur(_axial_blur(field_iq, axial.astype(np.complex128)), transducer.lateral_sigma_mm(depth) / dx)
    # calibrate so that soft tissue (echogenicity 1) at the focus has unit mean power: a pixel
    # holds density·dz·dx scatterers, and the PSF (wider than a pixel) sums a scatterer's
    # bilinear weights coherently, as if it sat at its exact position
    density = len(scatterers.amplitudes) / max(_area(scatterers.positions_mm), 1e-9)
    lateral_focus_px = float(transducer.lateral_sigma_mm(np.array([transducer.focus_depth_mm]))[0] / dx)
    norm = np.sqrt(density * dz * dx * _psf_energy(axial, lateral_focus_px))
    iq /= max(norm, 1e-12)
    # attenuation (round trip) and the imperfect TGC, plus shadowing through the target
    loss_db = 2.0 * transducer.attenuation_db_cm_mhz * transducer.center_frequency_mhz * depth / 10.0
    gain_db = tgc_gain_db(depth, transducer, rng)
    profile = 10 ** ((gain_db - loss_db) / 20.0)
    iq *= profile[:, None]
    if options.shadow_db_per_mm and target_mask is not None:
        path_mm = np.cumsum(target_mask, axis=0) * dz  # path through the target above each pixel
        iq *= 10 ** (-options.shadow_db_per_mm * path_mm / 20.0)
    noise = 10 ** (transducer.noise_db / 20.0)
    iq += noise * (rng.standard_normal((h, w)) + 1j * rng.standard_normal((h, w))) / np.sqrt(2.0)
    envelope = np.abs(iq)
    image = log_compress(envelope, transducer.dynamic_range_db)
    return BModeImage(image, envelope, (dz, dx))


def _area(pos: np.ndarray) -> float:
    return float(np.ptp(pos[:, 0]) * np.ptp(pos[:, 1]))


def _psf_energy(axial: np.ndarray, lateral_sigma_px: float) -> float:
    """Σ|PSF|² of the discrete PSF (the power gain of one unit-power scatterer per pixel)."""
    return float(np.sum(axial**2) * np.sqrt(np.pi) * lateral_sigma_px)


def _specular(mask: np.ndarray, gain: float, transducer: Transducer, dz: float, dx: float,
              rng: np.random.Generator) -> np.ndarray:
    """Strong coherent reflectors on the boundary pixels whose outward normal faces the probe."""
    from scipy import ndimage

    m = mask.astype(float)
    gz, _ = np.gradient(ndimage.gaussian_filter(m, 1.5))
    boundary = mask & ~ndimage.binary_erosion(mask)
    facing = np.clip(gz, 0.0, None)  # intensity rises with depth: the upper boundary
    weight = np.where(boundary, facing / (facing.max() + 1e-12), 0.0)
    density = transducer.scatterers_per_cell * dz * dx / transducer.resolution_cell_mm2()
    phase = rng.uniform(0, 2 * np.pi, mask.shape) * 0.2  # nearly coherent along the interface
    return gain * np.sqrt(density) * weight * np.exp(1j * phase)


def log_compress(envelope: np.ndarray, dynamic_range_db: float, reference: float | None = None) -> np.ndarray:
    """8-bit log compression: ``255 (1 + 20 log10(env / ref) / DR)`` clipped to [0, 255].

    ``reference`` defaults to the 99.5th percentile of the envelope, so a few
    specular spikes do not dim the whole image.
    """
    ref = reference if reference is not None else float(np.percentile(envelope, 99.5)) or 1.0
    db = 20.0 * np.log10(np.maximum(envelope, 1e-12) / ref)
    return np.clip(np.rint(255.0 * (1.0 + db / dynamic_range_db)), 0, 255).astype(np.uint8)


def echogenicity_sampler(echogenicity: np.ndarray, spacing_mm: tuple[float, float]):
    """A function ``(N, 2) positions (x_mm, z_mm) -> echogenicity`` reading a map on a grid
    (nearest pixel; edge values outside), for :func:`simulate_frame`."""
    echo = np.asarray(echogenicity, float)
    dz, dx = spacing_mm
    h, w = echo.shape

    def at(positions: np.ndarray) -> np.ndarray:
        j = np.clip(np.rint(positions[:, 0] / dx).astype(int), 0, w - 1)
        i = np.clip(np.rint(positions[:, 1] / dz).astype(int), 0, h - 1)
        return echo[i, j]

    return at


def simulate_image(echogenicity: np.ndarray, spacing_mm: tuple[float, float], transducer: Transducer = Transducer(),
                   options: BModeOptions = BModeOptions(), seed: int = 0,
                   target_mask: np.ndarray | None = None) -> BModeImage:
    """A B-mode image of a static medium given as an echogenicity map on the image grid.

    ``echogenicity`` is ``(H, W)`` relative backscatter power (soft tissue 1,
    water ≈ 0) with rows = depth; ``spacing_mm`` its ``(row, col)`` pixel size.
    Scatterers are drawn from ``seed``; the TGC ripple and noise from ``options.seed``.
    """
    echo = np.asarray(echogenicity, float)
    if echo.ndim != 2 or np.any(echo < 0) or not np.all(np.isfinite(echo)):
        raise InputError("expected a 2D map of finite, non-negative echogenicity", "echogenicity")
    extent = (echo.shape[0] * spacing_mm[0], echo.shape[1] * spacing_mm[1])
    scat = Scatterers.uniform(extent, transducer, seed)
    return simulate_frame(echogenicity_sampler(echo, spacing_mm), scat, None, echo.shape, spacing_mm, transducer,
                          options, target_mask)
