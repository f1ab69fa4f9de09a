"""Implicit rheological viscosity: conservation laws, an analytic decay rate, the explicit scheme's limit."""

import numpy as np
import pytest

from hifumotion.particles.elastic import TissueParameters
from hifumotion.particles.solver import Solver, SolverSettings
from hifumotion.particles.system import build_system
from hifumotion.scene.geometry import lattice

DX = 1e-3


def _block(beta1, beta2=0.0, size=(8e-3, 6e-3, 5e-3), youngs=13e3):
    x = lattice(np.zeros(3), np.array(size), DX)
    tissue = TissueParameters(youngs_modulus_pa=youngs, beta1=beta1, beta2=beta2, mu_max_pa_s=1e12)
    return build_system(spacing_m=DX, tissue_positions_m=x, tissue=tissue, gravity_m_s2=(0, 0, 0))


def test_momentum_conserved_and_energy_falls_at_any_viscosity():
    # μ ≈ 10⁵ Pa·s: the explicit limit ρΔx²/(4μ) would be 3×10⁻⁹ s; we step 10⁴ × larger
    system = _block(beta1=1e5, beta2=0.0)
    rng = np.random.default_rng(4)
    system.v[:] = rng.normal(0.0, 1e-3, system.v.shape)
    p0 = (system.mass[:, None] * system.v).sum(0)
    e0 = 0.5 * (system.mass[:, None] * system.v ** 2).sum()
    solver = Solver(system, SolverSettings())
    energies = []
    for _ in range(100):
        solver.step()
        energies.append(0.5 * (system.mass[:, None] * system.v ** 2).sum())
    rho = system.mass[0] / system.rest_volume[0]
    assert solver.dt > 1e3 * rho * DX ** 2 / (4 * solver.tissue_mu_max)   # no viscous step limit
    p1 = (system.mass[:, None] * system.v).sum(0)
    scale = np.abs(system.mass[:, None] * system.v).sum(0).max() + np.abs(p0).max()
    assert np.abs(p1 - p0).max() < 1e-5 * scale
    assert np.all(np.isfinite(system.x))
    assert energies[-1] < 1e-2 * e0          # a viscous solid at rest, not an explosion


def test_shear_mode_decays_at_the_navier_stokes_rate():
    # v_x = A cos(π y / L): the slowest shear mode of a slab with free faces at y = 0, L;
    # with elasticity negligible it decays as exp(−μ (π/L)² t / ρ)
    L = 12e-3
    system = _block(beta1=20.0, beta2=0.0, size=(6e-3, L, 6e-3), youngs=1.0)
    y = system.x[:, 1]
    y0, y1 = y.min() - DX / 2, y.max() + DX / 2
    mode = np.cos(np.pi * (y - y0) / (y1 - y0))
    system.v[:, 0] = 1e-3 * mode
    rho = system.mass[0] / system.rest_volume[0]
    rate = 20.0 * (np.pi / (y1 - y0)) ** 2 / rho
    solver = Solver(system, SolverSettings(max_step_s=1e-5))
    t_end = 0.5 / rate
    while system.time_s < t_end:
        solver.step()
    amplitude = float(system.v[:, 0] @ mode / (mode @ mode))
    measured = -np.log(amplitude / 1e-3) / system.time_s
    # measured 18 % slow at 12 particles across: Müller's viscosity-kernel Laplacian (Eq. 12)
    # is not exactly consistent and is truncated at the free faces (docs/decisions.md)
    assert measured == pytest.approx(rate, rel=0.25)
    assert measured < rate


def test_implicit_matches_explicit_when_the_step_is_small():
    results = []
    for implicit in (False, True):
        system = _block(beta1=100.0, beta2=0.5)
        rng = np.random.default_rng(2)
        system.v[:] = rng.normal(0.0, 1e-3, system.v.shape)
        solver = Solver(system, SolverSettings(implicit_viscosity=implicit))
        for _ in range(300):
            solver.dt = 2e-7
            solver.step()
        results.append(system.v.copy())
    explicit, implicit = results
    assert np.abs(implicit - explicit).max() < 0.02 * np.abs(explicit).max()


def test_eq16_law_floors_the_rate_and_caps_mu():
    """Eq. 16's μ = β1 γ̇^β2 with its two regularisations, on rates chosen by hand."""
    from hifumotion.rheology import viscosity_pa_s

    rates = np.array([[0.0, 0.01], [4.0, 1e12]])
    mu = viscosity_pa_s(rates, beta1=3.0, beta2=0.5, rate_floor_per_s=0.04, mu_max_pa_s=1e5)
    # below the floor: β1 √0.04 = 0.6; 4 1/s: 3·2 = 6; 10¹² 1/s: 3·10⁶ capped at 10⁵
    np.testing.assert_allclose(mu, [[0.6, 0.6], [6.0, 1e5]], rtol=1e-12)
    # a general exponent (not the √ fast path): 3 · 8^(1/3) = 6
    np.testing.assert_allclose(viscosity_pa_s([8.0], 3.0, 1 / 3, 0.04, 1e5), [6.0], rtol=1e-12)


def test_pair_rate_is_the_relative_velocity_across_the_pair():
    """Eq. 16's pair rate |v_ij × r_ij| / |r_ij|²: sliding past at 2 mm/s across 1 mm is 2 1/s,
    moving along the pair is no shear at all (the floor)."""
    from hifumotion.particles.viscosity import rheological_mu

    across = rheological_mu(0.002, 0.0, 0.0, 0.0, 0.001, 0.0, 0.001, 1.0, 1.0, 1e7, 1e-6)
    along = rheological_mu(0.0, 0.002, 0.0, 0.0, 0.001, 0.0, 0.001, 1.0, 1.0, 1e7, 1e-6)
    assert abs(across - 2.0) < 1e-9 and abs(along - 1e-6) < 1e-15
