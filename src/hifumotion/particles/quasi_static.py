"""Quasi-static runs: how long a mass-scaled tissue takes to settle under its weight.

A slow push is quasi-static; the explicit framework runs it with the inertia scaled up
``s``-fold (weights unchanged), which slows every elastic mode by √s. Before the push the
tissue settles under gravity with critical damping of its slowest mode, a quarter wave of
shear over its height H:

    ω = (π/2) √(E/ρ) / H / √s            (rad/s)

Critical damping 2ω relaxes it fastest; ``periods``/ω (6 by default) leaves e⁻⁶ of the
initial sag. Used by the synthetic twin's truth and by the fitted model alike.
"""

from __future__ import annotations

import math


def slowest_mode_rad_s(youngs_modulus_pa: float, density_kg_m3: float, height_mm: float,
                       mass_scaling: float = 1.0) -> float:
    """ω (rad/s) of the tissue's slowest elastic mode (module docstring)."""
    omega = 0.5 * math.pi * math.sqrt(youngs_modulus_pa / density_kg_m3) / (height_mm * 1e-3)
    return omega / math.sqrt(mass_scaling)


def settling(youngs_modulus_pa: float, density_kg_m3: float, height_mm: float, mass_scaling: float = 1.0,
             periods: float = 6.0) -> tuple[float, float]:
    """Settling time (s) and critical damping rate (1/s) of the module docstring."""
    omega = slowest_mode_rad_s(youngs_modulus_pa, density_kg_m3, height_mm, mass_scaling)
    return periods / omega, 2.0 * omega


__all__ = ["slowest_mode_rad_s", "settling"]
