"""The finite-strain tissue law (issue 41) against closed-form solutions at 30 % strain.

A cube compressed between frictionless plates at a constant rate deforms homogeneously, so its
force has a closed form: for an incompressible neo-Hookean solid the nominal stress is
G (λ − λ⁻²); for the Kelvin–Voigt viscosity σ_v = 2 μ(γ̇) dev d with d = diag(λ̇/λ, −λ̇/2λ,
−λ̇/2λ) it adds 3 μ(γ̇) λ̇ / λ², γ̇ = √3 |λ̇| / λ (Trouton's ratio at finite strain). Neither
formula is the code's: they come from the kinematics of the homogeneous deformation.
"""

import numpy as np
import pytest

fem = pytest.importorskip("felupe")
pytest.importorskip("tensortrax")

from hifumotion.reference.finite_strain import TissueLaw  # noqa: E402


def _compress(law: TissueLaw, stretch: float, duration_s: float, steps: int) -> tuple[float, float]:
    """Nominal stress (MPa) on a unit cube (mm) compressed to ``stretch`` at a constant rate
    over ``duration_s`` in ``steps`` backward-Euler steps, and the final stretch."""
    mesh = fem.Cube(n=2)
    u = fem.Field(fem.RegionHexahedron(mesh), dim=3)
    field = fem.FieldContainer([u])
    elastic, viscous = law.bodies(field, duration_s / steps)
    items = [elastic] + ([viscous] if viscous is not None else [])
    boundaries = {"x0": fem.Boundary(u, fx=0.0, skip=(0, 1, 1)), "y0": fem.Boundary(u, fy=0.0, skip=(1, 0, 1)),
                  "z0": fem.Boundary(u, fz=0.0, skip=(1, 1, 0)), "move": fem.Boundary(u, fx=1.0, skip=(0, 1, 1))}
    table = np.linspace(0.0, stretch - 1.0, steps + 1)[1:]
    fem.Job([fem.Step(items, ramp={boundaries["move"]: table}, boundaries=boundaries)]).evaluate(tol=1e-9)
    force = sum(np.asarray(item.results.force.toarray()).ravel() for item in items).reshape(-1, 3)
    return float(force[boundaries["move"].points, 0].sum()), 1.0 + table[-1]


def test_neo_hooke_compressed_by_30_percent_gives_the_incompressible_stress():
    """E = 10 kPa, ν = 0.499: within 0.2 % of G (λ − λ⁻²) at λ = 0.7 (small strain would be 8 % off)."""
    law = TissueLaw(1e4, 0.499)
    stress, stretch = _compress(law, 0.7, 1.0, 8)
    g = law.shear_modulus_mpa
    assert stress == pytest.approx(g * (stretch - stretch ** -2), rel=2e-3)
    assert abs(stress / (3 * g * (stretch - 1.0)) - 1.0) > 0.05       # not the linear answer


@pytest.mark.parametrize("beta2", [0.5])   # β2 = 0 (Newtonian): the block test below
def test_eq16_viscosity_at_finite_strain_converges_to_trouton(beta2):
    """β1 = 10⁵ Pa·s^(1+β2), compressed 30 % in 3 s: the force converges at first order in the
    step to G (λ − λ⁻²) + 3 μ(γ̇) λ̇ / λ² (0.5 % at 80 steps, about four times closer than at 20)."""
    law = TissueLaw(1e4, 0.4999, beta1=1e5, beta2=beta2)
    rate = -0.3 / 3.0
    errors = []
    for steps in (20, 80):
        stress, stretch = _compress(law, 0.7, 3.0, steps)
        mu = law.beta1 * 1e-6 * (np.sqrt(3.0) * abs(rate) / stretch) ** beta2
        exact = law.shear_modulus_mpa * (stretch - stretch ** -2) + 3.0 * mu * rate / stretch ** 2
        errors.append(abs(stress / exact - 1.0))
    assert errors[1] < 6e-3 and errors[0] / errors[1] > 3.0


@pytest.mark.parametrize("beta2", [0.0, 0.5])
def test_the_viscous_tangent_is_the_derivative_of_its_force_at_rest_and_moving(beta2):
    """The viscous body's matrix is the derivative of its nodal forces — checked by central
    differences at the step's start (C = Cₙ, zero rate: every step's first Newton iteration,
    where a max(·, 0) once cost the tangent its deviatoric part) and in a moving state."""
    law = TissueLaw(1.3e4, 0.47, beta1=2000.0, beta2=beta2)
    mesh = fem.Cube(n=3)
    field = fem.FieldContainer([fem.Field(fem.RegionHexahedron(mesh), dim=3)])
    _, viscous = law.bodies(field, 0.05)
    rng = np.random.default_rng(3)
    u = field[0]
    u.values[:] = 1e-3 * rng.normal(size=u.values.shape)
    viscous.assemble.vector(field)
    viscous.results.update_statevars()            # Cₙ: the current shape
    direction = 1e-2 * rng.normal(size=u.values.size)

    def force(values):
        trial = field.copy()
        trial[0].values[:] = values.reshape(u.values.shape)
        return np.asarray(viscous.assemble.vector(trial).toarray()).ravel()

    for moved in (0.0, 1e-3):
        x = u.values.ravel() + moved * rng.normal(size=u.values.size)
        u.values[:] = x.reshape(u.values.shape)
        tangent = viscous.assemble.matrix(field) @ direction
        h = 1e-5
        differences = (force(x + h * direction) - force(x - h * direction)) / (2 * h)
        assert np.linalg.norm(tangent - differences) < 1e-5 * np.linalg.norm(differences)


def test_a_block_under_a_held_force_creeps_as_kelvin_voigt():
    """The finite-strain push (:mod:`hifumotion.reference.finite_strain_push`) at 1 % strain: ν = 0,
    β2 = 0 (μ = β1), a block under a held force between the floor and a bar wider than it creeps as
    ε(t) = σ/E (1 − exp(−E t / 2μ)) — the small-strain closed form the other truth also meets
    (tests/test_creep_fe.py), within the backward-Euler step's first-order error."""
    pytest.importorskip("tetgen")
    import trimesh

    from hifumotion.reference.creep_fe import CreepingTissue
    from hifumotion.reference.finite_strain_push import FiniteStrainSettings, finite_strain_reference

    box = trimesh.creation.box(extents=(10.0,) * 3)
    box.apply_translation((20.0, 5.0, 20.0))
    e, mu, force = 1e4, 500.0, 0.01
    problem = CreepingTissue(box.vertices, box.faces, e, 0.0, mu, 0.0, 1e-3, (20.0, 10.0, 20.0), (0.0, -1.0, 0.0),
                             20.0, lambda t: force, (), gravity_m_s2=0.0, max_volume_mm3=50.0)
    times = np.array([0.0, 0.05, 0.1, 0.2])
    exact = force / 1e-4 / e * 10.0 * (1 - np.exp(-times * e / (2 * mu)))
    errors = []
    for step in (0.025, 0.0125):
        sol = finite_strain_reference(problem, times, FiniteStrainSettings(step_s=step))
        errors.append(np.abs(sol.advance_mm[1:] - exact[1:]).max() / exact[-1])
        assert np.allclose(sol.force_n[1:], force)
        assert sol.stats["floor_penetration_mm"] < 1e-2 * 10.0 / 2      # ≤ 1 % of the mesh's spacing
        # ν = 0 and a uniform compression: J = λ = 1 − ε, and ε is the largest principal strain
        strain = exact[-1] / 10.0
        assert sol.stats["smallest_jacobian"] == pytest.approx(1.0 - strain, abs=0.1 * strain)
        assert sol.stats["largest_strain"] == pytest.approx(strain, rel=0.1)
    assert errors[1] < 0.03 and errors[1] < 0.7 * errors[0]


def test_a_block_under_a_driven_bar_takes_the_kelvin_voigt_force_of_its_travel():
    """Travel control (issue 41, part 2): the same block with the bar's face driven at a steady
    rate v to 1 % strain (ν = 0, μ = β1): its advance is the travel and the force it takes
    A (E v t + 2 μ v) / h, the elastic and the viscous stress of the small-strain closed form
    (backward Euler is exact on a steady rate; finite strain moves it by O(ε))."""
    pytest.importorskip("tetgen")
    import trimesh

    from hifumotion.reference.creep_fe import CreepingTissue
    from hifumotion.reference.finite_strain_push import FiniteStrainSettings, finite_strain_reference

    box = trimesh.creation.box(extents=(10.0,) * 3)
    box.apply_translation((20.0, 5.0, 20.0))
    e, mu = 1e4, 500.0
    times = np.array([0.0, 0.05, 0.1, 0.2])
    rate = 0.1 / times[-1]                              # mm/s: 0.1 mm, 1 % strain, at the end
    problem = CreepingTissue(box.vertices, box.faces, e, 0.0, mu, 0.0, 1e-3, (20.0, 10.0, 20.0), (0.0, -1.0, 0.0),
                             20.0, lambda t: 0.0, (), gravity_m_s2=0.0, max_volume_mm3=50.0,
                             travel_mm=lambda t: rate * t)
    sol = finite_strain_reference(problem, times, FiniteStrainSettings(step_s=0.025))
    area_m2, height_mm = 1e-4, 10.0
    expected = area_m2 * (e * rate * times / height_mm + 2 * mu * rate / height_mm)
    np.testing.assert_allclose(sol.advance_mm, rate * times, atol=1e-9)
    np.testing.assert_allclose(sol.force_n[1:], expected[1:], rtol=0.02)
    assert sol.stats["smallest_jacobian"] == pytest.approx(0.99, abs=1e-3)


def test_tetra10_cells_put_each_midpoint_between_its_edges_vertices():
    """The P2 mesh handed to FElupe (and written for ParaView): node 4 + k of every element lies
    halfway along VTK's edge k — (0,1), (1,2), (2,0), (0,3), (1,3), (2,3) — of its vertices."""
    pytest.importorskip("tetgen")
    import trimesh

    from hifumotion.reference._p2 import p2_mesh

    sphere = trimesh.creation.icosphere(subdivisions=2)
    sphere.apply_scale(6.0)
    p2 = p2_mesh(sphere.vertices, sphere.faces, 5.0)
    cells, x = p2.tetra10_cells(), p2.points_m
    for k, (i, j) in enumerate(((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3))):
        assert np.allclose(x[cells[:, 4 + k]], 0.5 * (x[cells[:, i]] + x[cells[:, j]]), atol=1e-12)


def test_a_twin_is_physical_only_within_the_contacts_limits_and_the_faces_rim():
    """``facts.physicality``: penetration of floor or bar above 1 % of the spacing, a node held
    more than a spacing beyond the face's rim, or an inverted element each make a twin unphysical."""
    from hifumotion.experiment.fe_truth import physicality

    ok = {"smallest_jacobian": 0.8, "largest_strain": 0.2, "floor_penetration_mm": 1e-4,
          "face_penetration_mm": 0.019, "held_beyond_rim_mm": 1.9}
    p = physicality(ok, 2.0)
    assert p["penetration_within_limit"] and p["held_within_face"] and not p["inverted_elements"]
    assert not physicality({**ok, "face_penetration_mm": 0.021}, 2.0)["penetration_within_limit"]
    assert not physicality({**ok, "held_beyond_rim_mm": 2.1}, 2.0)["held_within_face"]
    assert physicality({**ok, "smallest_jacobian": -0.1}, 2.0)["inverted_elements"]
