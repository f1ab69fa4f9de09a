"""Validation cases of the particle framework against known solutions (SI units).

Each case builds a small scene, runs it and compares one measured quantity
with an analytic or conservation-law reference:

==============  ===========================================================  =========
case            reference                                                    tolerance
==============  ===========================================================  =========
hydrostatic     p = ρ0 g (H − y) away from walls; water at rest stays at rest  5 %
cantilever      tip deflection 3 ρ g L⁴ / (2 E h²) (Euler–Bernoulli)           5 %
plate           period from ω² = E H² k⁴ / (12 ρ (1 − ν²)), kL = 1.875         10 %
hertz           F = 4/3 E/(1 − ν²) √R δ^{3/2} for δ/R ≤ 0.1                     10 %
poisson         lateral / axial strain at 1 % stretch = −ν                     5 %
rotation        free rotation keeps angular momentum over 1,000 steps          1e-6
buoyancy        a light cube floats at the Archimedes draft; a dense one sinks one spacing
momentum        fluid + tissue + bar: momentum conserved; its change = impulse  1e-9
==============  ===========================================================  =========

:func:`run_case` returns a :class:`CaseResult` (``parameters``, ``measured``,
``reference``, ``rel_error``, ``passed``), printed as JSON by
``hifumotion validate CASE --json``. Static cases are relaxed to equilibrium
with the solver's global damping (dynamic relaxation), which changes the path
but not the equilibrium.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from hifumotion.particles.elastic import TissueParameters
from hifumotion.particles.solver import Solver, SolverSettings, smoothed_pressure
from hifumotion.particles.system import (STANDARD_GRAVITY_M_S2, CouplingParameters, build_system,
                                         lattice, tank_walls)

G = STANDARD_GRAVITY_M_S2


@dataclass
class CaseResult:
    """Outcome of one validation case (all SI)."""

    case: str
    parameters: dict
    measured: float
    reference: float
    rel_error: float
    tolerance: float
    passed: bool
    details: dict = field(default_factory=dict)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return asdict(self)


def _result(case, parameters, measured, reference, tolerance, details=None, error=None):
    rel = abs(measured - reference) / abs(reference) if error is None else error
    return CaseResult(case, parameters, float(measured), float(reference), float(rel),
                      float(tolerance), bool(rel <= tolerance), details or {})


# ---------------------------------------------------------------------------
def hydrostatic(spacing_m: float = 0.002, width_m: float = 0.03, depth_m: float = 0.03,
                thickness_m: float = 0.012) -> CaseResult:
    """Water settles in a tank; its pressure must be ρ0 g (H − y) and it must stay at rest."""
    dx = spacing_m
    water = lattice([0, 0, 0], [width_m, depth_m, thickness_m], dx)
    walls = tank_walls([0, 0, 0], [width_m, depth_m + 4 * dx, thickness_m], dx)
    system = build_system(spacing_m=dx, fluid_positions_m=water, wall_positions_m=walls)
    speed_scale = math.sqrt(2 * G * depth_m)
    settle = Solver(system, SolverSettings(damping_per_s=100.0))
    settle.run(0.25)
    free = Solver(system, SolverSettings())
    free.run(0.05)
    x = system.x[: system.n_fluid]
    table = free.grid.query(system.x, 0, system.n_fluid)
    p = smoothed_pressure(system.x, system.mass, system.density, system.pressure, system.n_fluid,
                          table.indices, table.counts, system.support_m)
    per_layer = int(round(width_m / dx)) * int(round(thickness_m / dx))
    surface = float(np.sort(x[:, 1])[-per_layer:].mean() + dx / 2)
    h = system.support_m
    inner = ((x[:, 0] > h) & (x[:, 0] < width_m - h) & (x[:, 2] > h) & (x[:, 2] < thickness_m - h)
             & (x[:, 1] > h) & (x[:, 1] < surface - h))
    depth = surface - x[inner, 1]
    rho0 = system.fluid.rest_density_kg_m3
    slope = float(np.polyfit(depth, p[inner], 1)[0])
    reference = rho0 * G
    mean_err = float(np.abs(p[inner] - rho0 * G * depth).mean() / (rho0 * G * surface))
    v_max = float(np.linalg.norm(system.v[: system.n_fluid], axis=1).max())
    rel = max(abs(slope / reference - 1), mean_err)
    out = _result("hydrostatic", {"spacing_m": dx, "width_m": width_m, "depth_m": depth_m,
                                  "rest_density_kg_m3": rho0, "gravity_m_s2": G},
                  slope, reference, 0.05, error=rel,
                  details={"pressure_gradient_pa_m": slope, "mean_abs_error_over_bottom_pressure": mean_err,
                           "max_speed_m_s": v_max, "max_speed_over_free_fall_speed": v_max / speed_scale,
                           "particles_compared": int(inner.sum())})
    if v_max > 0.05 * speed_scale:
        out.passed = False
    return out


def _beam(length_m, thickness_m, width_m, spacing_m, clamp_layers=3):
    dx = spacing_m
    pts = lattice([-clamp_layers * dx, 0, 0], [length_m, thickness_m, width_m], dx)
    return pts, pts[:, 0] < 0


def cantilever(particles_through_thickness: int = 5, youngs_modulus_pa: float = 1e7,
               poisson_ratio: float = 0.0, density_kg_m3: float = 1000.0,
               length_m: float = 0.08, thickness_m: float = 0.01, width_m: float = 0.006
               ) -> CaseResult:
    """A clamped beam sags under its weight; tip deflection against Euler–Bernoulli."""
    dx = thickness_m / particles_through_thickness
    pts, clamp = _beam(length_m, thickness_m, width_m, dx)
    tissue = TissueParameters(youngs_modulus_pa=youngs_modulus_pa, poisson_ratio=poisson_ratio,
                              beta1=0.0)
    system = build_system(spacing_m=dx, tissue_positions_m=pts, tissue_density_kg_m3=density_kg_m3,
                          tissue_fixed=clamp, tissue=tissue)
    omega = 3.516 * math.sqrt(youngs_modulus_pa * thickness_m ** 2 / (12 * density_kg_m3 * length_m ** 4))
    solver = Solver(system, SolverSettings(damping_per_s=2 * omega))
    tip = pts[:, 0] > length_m - dx
    reference = 3 * density_kg_m3 * G * length_m ** 4 / (2 * youngs_modulus_pa * thickness_m ** 2)
    history = []
    for _ in range(8):
        solver.run(math.pi / omega)
        history.append(float(-(system.x[tip, 1] - pts[tip, 1]).mean()))
        if len(history) > 1 and abs(history[-1] - history[-2]) < 1e-4 * abs(history[-1]):
            break
    return _result("cantilever", {"youngs_modulus_pa": youngs_modulus_pa, "poisson_ratio": poisson_ratio,
                                  "density_kg_m3": density_kg_m3, "length_m": length_m,
                                  "thickness_m": thickness_m, "width_m": width_m, "spacing_m": dx},
                   history[-1], reference, 0.05, details={"deflection_history_m": history})


def _mode_shape(x, k, length):
    kl = k * length
    a = (math.cos(kl) + math.cosh(kl)) / (math.sin(kl) + math.sinh(kl))
    return (np.cos(k * x) - np.cosh(k * x)) - a * (np.sin(k * x) - np.sinh(k * x))


def plate(particles_through_thickness: int = 5, youngs_modulus_pa: float = 2e6,
          poisson_ratio: float = 0.3975, density_kg_m3: float = 1000.0, length_m: float = 0.2,
          thickness_m: float = 0.02, velocity_fraction: float = 0.002) -> CaseResult:
    """Gray, Monaghan & Swift (2001): a clamped plate set vibrating in its first mode.

    Plane strain (motion held in x–y); the tip velocity starts at ``velocity_fraction``
    × the sound speed with the first cantilever mode shape; the period is measured
    from the tip's zero crossings.
    """
    dx = thickness_m / particles_through_thickness
    pts, clamp = _beam(length_m, thickness_m, 3 * dx, dx)
    tissue = TissueParameters(youngs_modulus_pa=youngs_modulus_pa, poisson_ratio=poisson_ratio,
                              beta1=0.0)
    system = build_system(spacing_m=dx, tissue_positions_m=pts, tissue_density_kg_m3=density_kg_m3,
                          tissue_fixed=clamp, tissue=tissue, gravity_m_s2=(0, 0, 0))
    k = 1.875 / length_m
    omega = math.sqrt(youngs_modulus_pa * thickness_m ** 2 * k ** 4
                      / (12 * density_kg_m3 * (1 - poisson_ratio ** 2)))
    reference = 2 * math.pi / omega
    c = math.sqrt(youngs_modulus_pa / density_kg_m3)
    shape = np.where(pts[:, 0] > 0, _mode_shape(np.maximum(pts[:, 0], 0), k, length_m), 0.0)
    system.v[: len(pts), 1] = velocity_fraction * c * shape / _mode_shape(np.array([length_m]), k, length_m)[0]
    solver = Solver(system, SolverSettings(frozen_axes=(2,)))
    tip = pts[:, 0] > length_m - dx
    times, disp = [], []

    def record(s):
        times.append(s.system.time_s)
        disp.append(float((s.system.x[tip, 1] - pts[tip, 1]).mean()))

    solver.run(1.6 * reference, callback=record, every_s=reference / 200)
    t = np.asarray(times)
    d = np.asarray(disp)
    crossings = []
    for a in range(1, len(d)):
        if d[a - 1] > 0 >= d[a] or d[a - 1] < 0 <= d[a]:
            crossings.append(t[a - 1] + (t[a] - t[a - 1]) * d[a - 1] / (d[a - 1] - d[a]))
    measured = 2 * float(np.mean(np.diff(crossings))) if len(crossings) >= 2 else float("nan")
    return _result("plate", {"youngs_modulus_pa": youngs_modulus_pa, "poisson_ratio": poisson_ratio,
                             "density_kg_m3": density_kg_m3, "length_m": length_m,
                             "thickness_m": thickness_m, "spacing_m": dx},
                   measured, reference, 0.10, details={"zero_crossings_s": crossings,
                                                       "tip_amplitude_m": float(np.abs(d).max())})


def poisson(poisson_ratio: float = 0.47, youngs_modulus_pa: float = 1e5, strain: float = 0.01,
            spacing_m: float = 0.002) -> CaseResult:
    """A block stretched 1 % between end layers free to contract: −lateral/axial strain = ν."""
    dx = spacing_m
    length, side = 20 * dx, 8 * dx
    pts = lattice([0, 0, 0], [length, side, side], dx)
    left = pts[:, 0] < 2 * dx
    right = pts[:, 0] > length - 2 * dx
    held = np.zeros((len(pts), 3), bool)
    held[left | right, 0] = True
    tissue = TissueParameters(youngs_modulus_pa=youngs_modulus_pa, poisson_ratio=poisson_ratio, beta1=0.0)
    system = build_system(spacing_m=dx, tissue_positions_m=pts, tissue_fixed=held, tissue=tissue,
                          gravity_m_s2=(0, 0, 0))
    system.x[: len(pts), 0] = pts[:, 0] + strain * (pts[:, 0] - pts[left, 0].mean())
    c = tissue.p_wave_speed(system.tissue_density_kg_m3())
    solver = Solver(system, SolverSettings(damping_per_s=2 * math.pi * c / length))
    solver.run(8 * length / c)
    mid = np.abs(pts[:, 0] - length / 2) < 2 * dx
    x = system.x[: len(pts)]
    axial = np.polyfit(pts[mid, 0], x[mid, 0], 1)[0] - 1
    lateral = 0.5 * (np.polyfit(pts[mid, 1], x[mid, 1], 1)[0] + np.polyfit(pts[mid, 2], x[mid, 2], 1)[0]) - 1
    measured = -lateral / axial
    force = float(solver.force[: len(pts)][right, 0].sum())
    modulus = -force / side ** 2 / axial
    return _result("poisson", {"poisson_ratio": poisson_ratio, "youngs_modulus_pa": youngs_modulus_pa,
                               "strain": strain, "spacing_m": dx},
                   measured, poisson_ratio, 0.05,
                   details={"axial_strain": float(axial), "lateral_strain": float(lateral),
                            "youngs_modulus_from_force_pa": float(modulus)})


def rotation(steps: int = 1000) -> CaseResult:
    """A free asymmetric rigid body spinning in empty space keeps its angular momentum.

    The angular momentum is recomputed from the particles' positions and
    velocities, Σ m (x − x_c) × v, so the check covers the whole chain
    L → ω → orientation → particle states.
    """
    dx = 0.002
    pts = lattice([0, 0, 0], [6 * dx, 4 * dx, 2 * dx], dx)
    system = build_system(spacing_m=dx, bodies=[{"positions_m": pts, "density_kg_m3": 2000.0}],
                          gravity_m_s2=(0, 0, 0))
    body = system.bodies[0]
    body.angular_momentum = body.inertia_body @ np.array([3.0, 20.0, 1.0])  # near the unstable axis
    system.x[:], system.v[:] = body.particle_states()
    solver = Solver(system, SolverSettings(max_step_s=1e-4))

    def particle_momentum():
        x, v = system.x, system.v
        m = system.mass[:, None]
        centre = (m * x).sum(0) / m.sum()
        return (m * np.cross(x - centre, v)).sum(0)

    before = particle_momentum()
    energy_before = body.kinetic_energy()
    for _ in range(steps):
        solver.step()
    after = particle_momentum()
    drift = float(np.linalg.norm(after - before) / np.linalg.norm(before))
    energy_drift = abs(body.kinetic_energy() / energy_before - 1)
    out = _result("rotation", {"steps": steps, "step_s": 1e-4, "particles": len(pts)},
                  float(np.linalg.norm(after)), float(np.linalg.norm(before)), 1e-6, error=drift,
                  details={"relative_energy_drift": float(energy_drift),
                           "turns": float(np.linalg.norm(body.angular_velocity()) * steps * 1e-4 / (2 * np.pi))})
    return out


def buoyancy(spacing_m: float = 0.002, light_density_kg_m3: float = 500.0,
             dense_density_kg_m3: float = 2000.0, side_m: float = 0.01, water_depth_m: float = 0.026,
             coupling: CouplingParameters = CouplingParameters()) -> CaseResult:
    """Two rigid cubes in one water tank, free to move vertically.

    The light one must float at the Archimedes draft ``side ρ_body / ρ_water`` (within
    one particle spacing); the dense one must sink to the floor (its bottom within one
    spacing of it). Both start off their equilibrium.
    """
    dx = spacing_m
    rho0 = 1000.0
    width, thickness = 5 * side_m, 2.4 * side_m
    light_centre = np.array([1.25 * side_m, water_depth_m - side_m * light_density_kg_m3 / rho0
                             + side_m / 2 + 0.25 * side_m, thickness / 2])
    dense_centre = np.array([width - 1.25 * side_m, side_m / 2 + 3 * dx, thickness / 2])
    cubes = [lattice(c - side_m / 2, c + side_m / 2, dx) for c in (light_centre, dense_centre)]
    water = lattice([0, 0, 0], [width, water_depth_m, thickness], dx)
    for cube in cubes:
        lo, hi = cube.min(0) - dx / 2, cube.max(0) + dx / 2
        water = water[~np.all((water > lo - 0.5 * dx) & (water < hi + 0.5 * dx), axis=1)]
    walls = tank_walls([0, 0, 0], [width, water_depth_m + side_m, thickness], dx)
    bodies = [{"positions_m": cubes[0], "density_kg_m3": light_density_kg_m3, "axis": (0.0, 1.0, 0.0),
               "name": "light"},
              {"positions_m": cubes[1], "density_kg_m3": dense_density_kg_m3, "axis": (0.0, 1.0, 0.0),
               "name": "dense"}]
    system = build_system(spacing_m=dx, fluid_positions_m=water, wall_positions_m=walls, bodies=bodies,
                          water_depth_m=water_depth_m, coupling=coupling)
    light, dense = system.bodies
    heave = 2 * math.pi * math.sqrt(side_m * light_density_kg_m3 / rho0 / G)  # period of bobbing
    solver = Solver(system, SolverSettings(damping_per_s=4 * math.pi / heave))
    solver.run(2.0 * heave)
    x = system.x[: system.n_fluid]
    between = np.abs(x[:, 0] - width / 2) < 0.5 * side_m
    surface = float(np.max(x[between, 1]) + dx / 2)
    draft = surface - float(light.centre_m[1] - side_m / 2)
    reference = side_m * light_density_kg_m3 / rho0
    dense_bottom = float(dense.centre_m[1] - side_m / 2)
    out = _result("buoyancy", {"spacing_m": dx, "light_density_kg_m3": light_density_kg_m3,
                               "dense_density_kg_m3": dense_density_kg_m3, "side_m": side_m,
                               "water_depth_m": water_depth_m},
                  draft, reference, dx, error=abs(draft - reference) / reference,
                  details={"draft_error_in_spacings": abs(draft - reference) / dx,
                           "surface_m": surface, "dense_bottom_above_floor_m": dense_bottom,
                           "simulated_s": system.time_s})
    out.passed = abs(draft - reference) <= dx and dense_bottom <= dx
    return out


def momentum(steps: int = 400, bar_force_n: float = 0.02, seed: int = 0) -> CaseResult:
    """Water, tissue and a bar collide in empty space (no gravity, no walls).

    Without an applied force the total momentum must stay constant to round-off;
    with the bar's force F on for the whole run, its change must equal F·t.
    """
    dx = 0.002
    rng = np.random.default_rng(seed)
    water = lattice([0, 0, 0], [0.02, 0.02, 0.02], dx)
    tissue = lattice([0.006, 0.006, 0.006], [0.014, 0.014, 0.014], dx)
    keep = ~np.all((water > 0.005) & (water < 0.015), axis=1)
    water = water[keep]
    bar = lattice([0.008, 0.021, 0.008], [0.012, 0.031, 0.012], dx)
    results = {}
    for force in (0.0, bar_force_n):
        system = build_system(spacing_m=dx, fluid_positions_m=water, tissue_positions_m=tissue,
                              bodies=[{"positions_m": bar, "density_kg_m3": 7800.0,
                                       "force_n": force, "force_direction": (0.0, -1.0, 0.0)}],
                              gravity_m_s2=(0, 0, 0), coupling=CouplingParameters(friction=0.3),
                              water_depth_m=0.02)
        n = system.n_fluid + system.n_tissue
        system.v[:n] = rng.normal(0, 0.05, (n, 3))
        body = system.bodies[0]
        body.velocity_m_s = np.array([0.0, -0.3, 0.0])
        system.x[n:n + len(bar)], system.v[n:n + len(bar)] = body.particle_states()
        solver = Solver(system, SolverSettings())
        p0 = system.momentum()
        for _ in range(steps):
            solver.step()
        p1 = system.momentum()
        scale = float((system.mass[: system.n_moving, None] * np.abs(system.v[: system.n_moving])).sum())
        impulse = force * system.time_s * np.array([0.0, -1.0, 0.0])
        results[force] = (float(np.linalg.norm(p1 - p0 - impulse) / max(scale, 1e-300)),
                          float(np.linalg.norm(p1 - p0)), float(np.linalg.norm(impulse)), system.time_s)
    error = max(results[0.0][0], results[bar_force_n][0])
    return _result("momentum", {"steps": steps, "bar_force_n": bar_force_n, "seed": seed},
                   results[bar_force_n][1], results[bar_force_n][2], 1e-9, error=error,
                   details={"free_relative_momentum_change": results[0.0][0],
                            "forced_relative_impulse_mismatch": results[bar_force_n][0],
                            "simulated_s": results[bar_force_n][3]})


def _sphere_shell(radius: float, spacing: float) -> np.ndarray:
    n = max(int(round(4 * math.pi * radius ** 2 / spacing ** 2)), 12)
    k = np.arange(n) + 0.5
    polar = np.arccos(1 - 2 * k / n)
    azimuth = math.pi * (1 + 5 ** 0.5) * k
    return radius * np.stack([np.sin(polar) * np.cos(azimuth), np.cos(polar),
                              np.sin(polar) * np.sin(azimuth)], axis=1)


def _lattice_ball(radius: float, spacing: float) -> np.ndarray:
    pts = lattice([-radius] * 3, [radius] * 3, spacing)
    pts = pts - pts.mean(0)
    return pts[np.linalg.norm(pts, axis=1) <= radius]


def hertz(spacing_m: float = 0.001, radius_spacings: int = 6, youngs_modulus_pa: float = 1e5,
          poisson_ratio: float = 0.3, depth_fraction: float = 0.08, block_radii: float = 2.5) -> CaseResult:
    """A rigid sphere pushed into an elastic block by a constant force (Hertz contact).

    The force is chosen so that Hertz predicts δ = ``depth_fraction`` × R; the block's
    indentation δ is read at the surface particles under the sphere's centre after
    relaxation, and the force Hertz gives for it is compared with the applied one.
    """
    dx = spacing_m
    radius = radius_spacings * dx
    e_star = youngs_modulus_pa / (1 - poisson_ratio ** 2)
    delta_target = depth_fraction * radius
    force = 4.0 / 3.0 * e_star * math.sqrt(radius) * delta_target ** 1.5
    half = block_radii * radius
    depth = block_radii * radius
    block = lattice([-half, -depth, -half], [half, 0.0, half], dx)
    base = block[:, 1] < -depth + 2 * dx
    # a smooth sphere: a Fibonacci shell of spacing ≈ Δx at R − Δx/2 around a lattice core
    # (a lattice ball would meet the block with a flat disc: a punch, not a sphere)
    centre = np.array([0.0, radius + 0.5 * dx, 0.0])
    ball = np.concatenate([_sphere_shell(radius - 0.5 * dx, dx), _lattice_ball(radius - 1.5 * dx, dx)]) + centre
    tissue = TissueParameters(youngs_modulus_pa=youngs_modulus_pa, poisson_ratio=poisson_ratio,
                              beta1=0.0)
    system = build_system(spacing_m=dx, tissue_positions_m=block, tissue_fixed=base, tissue=tissue,
                          tissue_density_kg_m3=1000.0,
                          bodies=[{"positions_m": ball, "density_kg_m3": 1000.0, "force_n": force,
                                   "force_direction": (0.0, -1.0, 0.0), "axis": (0.0, 1.0, 0.0)}],
                          coupling=CouplingParameters(friction=0.0), gravity_m_s2=(0, 0, 0))
    c = tissue.p_wave_speed(1000.0)
    solver = Solver(system, SolverSettings(damping_per_s=2 * math.pi * c / (2 * depth)))
    top = (block[:, 1] > -dx) & (np.hypot(block[:, 0], block[:, 2]) < 1.01 * dx)
    tissue_slice = system.tissue_slice
    history = []
    for _ in range(10):
        solver.run(6 * depth / c)
        history.append(float(-(system.x[tissue_slice][top, 1] - block[top, 1]).mean()))
        if len(history) > 1 and abs(history[-1] - history[-2]) < 2e-3 * abs(history[-1]):
            break
    delta = history[-1]
    hertz_force = 4.0 / 3.0 * e_star * math.sqrt(radius) * max(delta, 0.0) ** 1.5
    return _result("hertz", {"youngs_modulus_pa": youngs_modulus_pa, "poisson_ratio": poisson_ratio,
                             "radius_m": radius, "spacing_m": dx, "applied_force_n": force},
                   hertz_force, force, 0.10,
                   details={"indentation_m": delta, "indentation_over_radius": delta / radius,
                            "indentation_history_m": history})


CASES = {
    "hydrostatic": hydrostatic,
    "cantilever": cantilever,
    "plate": plate,
    "hertz": hertz,
    "poisson": poisson,
    "rotation": rotation,
    "buoyancy": buoyancy,
    "momentum": momentum,
}


def run_case(name: str, **kwargs) -> CaseResult:
    """Run the validation case ``name`` (one of :data:`CASES`) and time it."""
    if name not in CASES:
        raise KeyError(f"unknown validation case {name!r}; choose from {', '.join(CASES)}")
    start = time.perf_counter()
    result = CASES[name](**kwargs)
    result.seconds = time.perf_counter() - start
    return result
