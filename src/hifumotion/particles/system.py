"""The particle system: one state for water, tissue, bar and tank (SI units).

Particles are stored by phase, contiguously: fluid, then tissue, then the
rigid bodies' particles, then the tank walls (which never move). Positions in
m, velocities in m/s, masses in kg, rest volumes in m³.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hifumotion.physical import STANDARD_GRAVITY_M_S2, TISSUE_DENSITY_KG_M3, WATER_DENSITY_KG_M3
from hifumotion.particles._numba import FLUID, RIGID, TISSUE, WALL
from hifumotion.particles.elastic import RestNeighbourhoods, TissueParameters, rest_neighbourhoods
from hifumotion.particles.kernels import kernel_derivative
from hifumotion.particles.rigid import RigidBody
from hifumotion.scene.geometry import lattice



@dataclass(frozen=True)
class FluidParameters:
    """The water (SI).

    Attributes
    ----------
    rest_density_kg_m3
        ρ0 (kg/m³).
    stiffness_m2_s2
        K of ``p = K (ρ − ρ0)`` (m²/s², the square of the speed of sound); ``None``: c²
        with c ten times the fastest free-fall speed over the water depth (density
        variation ≈ 1 %), the usual weakly compressible choice.
    viscosity_pa_s
        μ of Eq. 12 (Pa·s). Water's is 1e-3; the default is larger, as SPH needs some
        numerical viscosity to stay quiet at this resolution.
    """

    rest_density_kg_m3: float = WATER_DENSITY_KG_M3
    stiffness_m2_s2: float | None = None
    viscosity_pa_s: float = 0.02


@dataclass(frozen=True)
class CouplingParameters:
    """Multiphase coupling (Eq. 18–20) and contact (SI).

    Attributes
    ----------
    fluid_coefficient
        K_c (N·m⁴/kg²) of Eq. 18 between water and solids. Default 0: the water's
        pressure already couples it to the solids (see :mod:`.fluid`), and adding the
        penalty lifted a floating cube by 1.4 particle spacings in the buoyancy case;
        ``None`` sets the largest pair force to the tank-floor pressure on one particle face.
    wall_coefficient
        K_c (N·m⁴/kg²) of Eq. 18 between water and the tank's walls, with a kernel of
        support ¾ of a spacing, so it is zero for water resting on the lattice and
        acts only on water squeezed against a wall: pressure alone cannot stop a water
        particle that a compressed tissue pushes into the floor (measured: pushed through
        two wall layers at 1.4 s of the synthetic push). ``None``: its largest pair force is
        ``contact_pressure_factor`` × E × Δx², like the solids' contact.
    contact_coefficient
        K_c (N·m⁴/kg²) of Eq. 18 between solids (tissue–bar, tissue–floor, bar–floor).
        ``None``: the largest pair force between a tissue particle and the heaviest solid
        particle equals ``contact_pressure_factor`` × E × Δx².
    contact_pressure_factor
        See above (dimensionless).
    friction
        Coulomb friction coefficient between solids (dimensionless; 0 = frictionless).
    slip_speed_m_s
        Sliding speed below which friction is regularised (m/s).
    contact_support_factor
        Support of the Eq. 18 kernel, in particle spacings (see :mod:`.fluid`).
    """

    fluid_coefficient: float | None = 0.0
    wall_coefficient: float | None = None
    contact_coefficient: float | None = None
    contact_pressure_factor: float = 4.0
    friction: float = 0.5
    slip_speed_m_s: float = 1e-4
    contact_support_factor: float = 1.0


@dataclass
class ParticleSystem:
    """State and parameters of a particle scene (SI inside).

    Attributes
    ----------
    x, v
        ``(N, 3)`` positions (m) and velocities (m/s).
    mass, rest_volume
        ``(N,)`` masses (kg) and rest volumes (m³).
    phase
        ``(N,)`` int8: 0 fluid, 1 tissue, 2 rigid, 3 wall.
    support_m
        Kernel support radius h (m); the particle spacing is ``spacing_m``.
    tissue_rest
        Rest positions of the tissue particles (m).
    tissue_held, tissue_held_velocity_m_s
        ``(n_tissue, 3)``: velocity components prescribed (clamps, rollers, pulled
        ends) and their values (m/s; 0 holds the particle in place).
    bodies
        The rigid bodies (their particles are the rigid block, in order).
    domain_lo_m, domain_hi_m
        Box a particle may not leave (m); leaving it stops the run.
    """

    x: np.ndarray
    v: np.ndarray
    mass: np.ndarray
    rest_volume: np.ndarray
    phase: np.ndarray
    counts: dict
    support_m: float
    spacing_m: float
    fluid: FluidParameters
    tissue: TissueParameters
    coupling: CouplingParameters
    gravity_m_s2: np.ndarray
    domain_lo_m: np.ndarray
    domain_hi_m: np.ndarray
    tissue_rest: np.ndarray
    rest: RestNeighbourhoods | None
    tissue_held: np.ndarray
    tissue_held_velocity_m_s: np.ndarray
    bodies: list[RigidBody] = field(default_factory=list)
    time_s: float = 0.0
    step: int = 0
    fluid_stiffness_m2_s2: float = 0.0
    fluid_coefficient: float = 0.0
    wall_coefficient: float = 0.0
    contact_coefficient: float = 0.0
    density: np.ndarray = field(default=None)
    pressure: np.ndarray = field(default=None)
    strain: np.ndarray = field(default=None)
    deform: np.ndarray = field(default=None)

    # -- phase ranges -------------------------------------------------------
    @property
    def n_fluid(self) -> int:
        return self.counts["fluid"]

    @property
    def n_tissue(self) -> int:
        return self.counts["tissue"]

    @property
    def n_rigid(self) -> int:
        return self.counts["rigid"]

    @property
    def n_wall(self) -> int:
        return self.counts["wall"]

    @property
    def n_moving(self) -> int:
        """Particles that move (fluid, tissue, rigid): ``0 … n_moving − 1``."""
        return self.n_fluid + self.n_tissue + self.n_rigid

    def slice_of(self, phase: int) -> slice:
        starts = np.cumsum([0, self.n_fluid, self.n_tissue, self.n_rigid, self.n_wall])
        return slice(int(starts[phase]), int(starts[phase + 1]))

    @property
    def tissue_slice(self) -> slice:
        return self.slice_of(TISSUE)

    @property
    def fluid_slice(self) -> slice:
        return self.slice_of(FLUID)

    def tissue_density_kg_m3(self) -> float:
        sl = self.tissue_slice
        return float(self.mass[sl].sum() / self.rest_volume[sl].sum()) if self.n_tissue else 0.0

    def momentum(self) -> np.ndarray:
        """Total linear momentum of moving particles (kg·m/s; rigid bodies through their particles)."""
        n = self.n_moving
        return (self.mass[:n, None] * self.v[:n]).sum(0)

    def kinetic_energy(self) -> float:
        n = self.n_moving
        return float(0.5 * (self.mass[:n] * (self.v[:n] ** 2).sum(1)).sum())


def build_system(*, spacing_m: float, support_factor: float = 2.0,
                 fluid_positions_m: np.ndarray | None = None,
                 tissue_positions_m: np.ndarray | None = None,
                 tissue_volumes_m3: np.ndarray | None = None,
                 tissue_density_kg_m3: float = TISSUE_DENSITY_KG_M3,
                 tissue_fixed: np.ndarray | None = None,
                 tissue_held_velocity_m_s: np.ndarray | None = None,
                 bodies: list[dict] | None = None,
                 wall_positions_m: np.ndarray | None = None,
                 fluid: FluidParameters = FluidParameters(),
                 tissue: TissueParameters = TissueParameters(),
                 coupling: CouplingParameters = CouplingParameters(),
                 gravity_m_s2=(0.0, -STANDARD_GRAVITY_M_S2, 0.0),
                 domain_lo_m=None, domain_hi_m=None,
                 water_depth_m: float | None = None) -> ParticleSystem:
    """Assemble a :class:`ParticleSystem` from particle positions per phase (all SI).

    ``bodies`` is a list of dicts with ``positions_m``, ``density_kg_m3`` and any
    :class:`~hifumotion.particles.rigid.RigidBody` keyword (``force_n``,
    ``force_direction``, ``axis``, ``fixed``, ``prescribed_velocity_m_s``, ``name``).
    Particle volumes are ``spacing³`` unless ``tissue_volumes_m3`` is given.
    ``tissue_fixed`` holds tissue particles in place: ``(n,)`` for all axes or ``(n, 3)``
    per axis; held components move at ``tissue_held_velocity_m_s`` (default 0).
    """
    dx = float(spacing_m)
    if not dx > 0:
        raise ValueError(f"spacing_m must be > 0, got {spacing_m}")
    h = support_factor * dx
    empty = np.zeros((0, 3))
    xf = np.asarray(fluid_positions_m if fluid_positions_m is not None else empty, float).reshape(-1, 3)
    xt = np.asarray(tissue_positions_m if tissue_positions_m is not None else empty, float).reshape(-1, 3)
    xw = np.asarray(wall_positions_m if wall_positions_m is not None else empty, float).reshape(-1, 3)
    bodies = bodies or []
    xr = [np.asarray(b["positions_m"], float).reshape(-1, 3) for b in bodies]
    cell = dx ** 3
    rho0 = fluid.rest_density_kg_m3
    vt = (np.full(len(xt), cell) if tissue_volumes_m3 is None
          else np.asarray(tissue_volumes_m3, float).reshape(-1))
    if len(vt) != len(xt):
        raise ValueError("tissue_volumes_m3 must have one value per tissue particle")
    parts_x = [xf, xt, *xr, xw]
    x = np.concatenate(parts_x) if sum(len(p) for p in parts_x) else empty
    vol = np.concatenate([np.full(len(xf), cell), vt, *[np.full(len(p), cell) for p in xr],
                          np.full(len(xw), cell)])
    mass = np.concatenate([np.full(len(xf), rho0 * cell), tissue_density_kg_m3 * vt,
                           *[b.get("density_kg_m3", 7800.0) * np.full(len(p), cell)
                             for b, p in zip(bodies, xr)],
                           np.full(len(xw), rho0 * cell)])
    phase = np.concatenate([np.full(len(xf), FLUID), np.full(len(xt), TISSUE),
                            np.full(sum(len(p) for p in xr), RIGID), np.full(len(xw), WALL)]
                           ).astype(np.int8)
    counts = {"fluid": len(xf), "tissue": len(xt), "rigid": sum(len(p) for p in xr), "wall": len(xw)}
    first = len(xf) + len(xt)
    rigid_bodies = []
    for b, p in zip(bodies, xr):
        kw = {k: v for k, v in b.items() if k not in ("positions_m", "density_kg_m3")}
        if "force_n" in kw and not callable(kw["force_n"]):
            value = float(kw["force_n"])
            kw["force_n"] = lambda t, value=value: value
        rigid_bodies.append(RigidBody.from_particles(first, p, mass[first:first + len(p)], **kw))
        first += len(p)
    g = np.asarray(gravity_m_s2, float)
    if len(x):
        lo = x.min(0) if domain_lo_m is None else np.asarray(domain_lo_m, float)
        hi = x.max(0) if domain_hi_m is None else np.asarray(domain_hi_m, float)
    else:
        lo = hi = np.zeros(3)
    if water_depth_m is None:
        water_depth_m = float(np.ptp(xf[:, 1])) + dx if len(xf) else 0.0
    stiffness = fluid.stiffness_m2_s2
    if stiffness is None:
        c = 10.0 * math.sqrt(2.0 * float(np.linalg.norm(g)) * max(water_depth_m, dx))
        stiffness = max(c, 1.0) ** 2
    h_c = coupling.contact_support_factor * dx
    dw_max = float(np.abs(kernel_derivative(np.array([h_c / 3.0]), h_c))[0])  # |dW/dr| peaks at q = 1/3
    m_t = float(mass[len(xf):len(xf) + len(xt)].mean()) if len(xt) else rho0 * cell
    m_f = rho0 * cell
    kc_fluid = coupling.fluid_coefficient
    if kc_fluid is None:
        kc_fluid = rho0 * float(np.linalg.norm(g)) * max(water_depth_m, dx) * dx * dx / (m_f * m_t * dw_max)
    kc_wall = coupling.wall_coefficient
    if kc_wall is None:
        dw_wall = float(np.abs(kernel_derivative(np.array([0.25 * h_c]), 0.75 * h_c))[0])
        kc_wall = coupling.contact_pressure_factor * tissue.youngs_modulus_pa * dx * dx / (m_f * m_f * dw_wall)
    kc_contact = coupling.contact_coefficient
    if kc_contact is None:
        # calibrated on the heaviest pair the tissue meets (usually tissue–bar): Eq. 18 scales
        # with the product of the masses, so lighter pairs (tissue–floor) are softer
        m_heavy = max([m_t] + [float(b.get("density_kg_m3", 7800.0)) * cell for b in bodies])
        kc_contact = coupling.contact_pressure_factor * tissue.youngs_modulus_pa * dx * dx / (m_t * m_heavy * dw_max)
    rest = rest_neighbourhoods(xt, tissue.support_factor * dx, tissue.moment_floor,
                               tissue.mls_order, near_m=h) if len(xt) else None
    held = np.zeros((len(xt), 3), bool)
    if tissue_fixed is not None:
        tf = np.asarray(tissue_fixed, bool)
        held[:] = tf[:, None] if tf.ndim == 1 else tf
    held_v = np.zeros((len(xt), 3)) if tissue_held_velocity_m_s is None else \
        np.broadcast_to(np.asarray(tissue_held_velocity_m_s, float), (len(xt), 3)).copy()
    n = len(x)
    return ParticleSystem(
        x=np.ascontiguousarray(x), v=np.zeros((n, 3)), mass=mass, rest_volume=vol, phase=phase,
        counts=counts, support_m=h, spacing_m=dx, fluid=fluid, tissue=tissue, coupling=coupling,
        gravity_m_s2=g, domain_lo_m=lo, domain_hi_m=hi, tissue_rest=xt.copy(), rest=rest,
        tissue_held=held, tissue_held_velocity_m_s=held_v, bodies=rigid_bodies, fluid_stiffness_m2_s2=float(stiffness),
        fluid_coefficient=float(kc_fluid), wall_coefficient=float(kc_wall),
        contact_coefficient=float(kc_contact),
        density=np.full(len(xf), rho0), pressure=np.zeros(len(xf)), strain=np.zeros(len(xt)),
        deform=np.tile(np.eye(3), (len(xt), 1, 1)),
    )


def tank_walls(inner_lo_m, inner_hi_m, spacing_m: float, layers: int = 2,
               open_top: bool = True) -> np.ndarray:
    """Wall particles (m) around a box ``[inner_lo, inner_hi)``: ``layers`` deep, y up, top open."""
    lo = np.asarray(inner_lo_m, float)
    hi = np.asarray(inner_hi_m, float)
    pad = layers * spacing_m
    outer_lo = lo - pad
    outer_hi = hi + pad
    if open_top:
        outer_hi[1] = hi[1] + pad  # walls rise a little above the water line
    pts = lattice(outer_lo, outer_hi, spacing_m)
    inside = np.all((pts > lo) & (pts < hi), axis=1)
    if open_top:
        inside |= np.all((pts[:, [0, 2]] > lo[[0, 2]]) & (pts[:, [0, 2]] < hi[[0, 2]]), axis=1) & \
            (pts[:, 1] > lo[1])
    return pts[~inside]
