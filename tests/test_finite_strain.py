"""The finite-strain tissue law against closed-form solutions at 30 % strain.

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
    """Travel control: the same block with the bar's face driven at a steady
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


def test_a_twin_is_physical_only_within_the_contacts_limits():
    """``facts.physicality``: penetration of floor or bar above 1 % of the spacing, or an
    inverted element, each make a twin unphysical."""
    from hifumotion.experiment.fe_truth import physicality

    ok = {"smallest_jacobian": 0.8, "largest_strain": 0.2, "floor_penetration_mm": 1e-4, "face_penetration_mm": 0.019}
    p = physicality(ok, 2.0)
    assert p["penetration_within_limit"] and not p["inverted_elements"]
    assert not physicality({**ok, "face_penetration_mm": 0.021}, 2.0)["penetration_within_limit"]
    assert not physicality({**ok, "floor_penetration_mm": 0.021}, 2.0)["penetration_within_limit"]
    assert physicality({**ok, "smallest_jacobian": -0.1}, 2.0)["inverted_elements"]


def _distance_to_rounded_bar(x, axis, radius, edge):
    """The signed distance to the rounded bar as a Minkowski sum — the semi-infinite core
    cylinder {along ≤ −r, d ≤ R − r} grown by a ball of r — for points outside the core: the
    distance to the core (the product of a half-line and a disc, so its nearest point clips
    each factor) less r."""
    along = x @ axis
    radial = x - np.outer(along, axis)
    d = np.linalg.norm(radial, axis=1)
    clipped_along = np.minimum(along, -edge)
    clipped_d = np.minimum(d, radius - edge)
    nearest = np.outer(clipped_along, axis) + radial * (clipped_d / np.maximum(d, 1e-300))[:, None]
    return np.linalg.norm(x - nearest, axis=1) - edge


def test_the_bar_solid_s_gap_is_the_distance_to_a_rounded_cylinder_and_its_normal_and_curvature_its_derivatives():
    """``bar_gap`` (the finite-strain truth's bar) against the Minkowski-sum distance of
    ``_distance_to_rounded_bar`` at points around face, rim and side, and its normal and
    curvature against central differences of its own gap and normal."""
    from hifumotion.reference.finite_strain_push import bar_gap

    rng = np.random.default_rng(3)
    axis = np.array([0.4, -0.9, 0.2])
    axis /= np.linalg.norm(axis)
    radius, edge = 5.0, 0.8
    x = rng.uniform(-8.0, 8.0, (4000, 3))
    along = x @ axis
    d = np.linalg.norm(x - np.outer(along, axis), axis=1)
    outside_core = ~((along <= -edge) & (d <= radius - edge))
    x = x[outside_core & (np.abs(d - (radius - edge)) > 1e-3) & (np.abs(along + edge) > 1e-3)]
    gap, normal, curvature = bar_gap(x, axis, radius, edge)
    np.testing.assert_allclose(gap, _distance_to_rounded_bar(x, axis, radius, edge), atol=1e-9)
    assert (gap < 0).any() and (gap > 0).any()
    h = 1e-6
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        gp, np_, _ = bar_gap(x + step, axis, radius, edge)
        gm, nm, _ = bar_gap(x - step, axis, radius, edge)
        np.testing.assert_allclose((gp - gm) / (2 * h), normal[:, k], atol=1e-5)
        np.testing.assert_allclose((np_ - nm) / (2 * h), curvature[:, :, k], atol=1e-4)


def test_the_bar_comes_to_rest_on_the_first_point_its_rounded_end_meets():
    """``_advance_to_touch``: how far the bar advances along its axis before it touches a point
    (bisection on the Minkowski-sum distance), and never for a point beside it."""
    from hifumotion.reference.finite_strain_push import _advance_to_touch

    rng = np.random.default_rng(4)
    axis = np.array([0.0, -1.0, 0.0])
    radius, edge = 4.0, 1.0
    x = np.column_stack([rng.uniform(-6, 6, 300), rng.uniform(-9, -0.5, 300), rng.uniform(-6, 6, 300)])
    advance = _advance_to_touch(x, axis, radius, edge)
    d = np.hypot(x[:, 0], x[:, 2])
    assert np.all(np.isinf(advance[d > radius])) and np.all(np.isfinite(advance[d <= radius]))
    for point, s in zip(x[d <= radius], advance[d <= radius]):
        lo, hi = -1.0, 20.0            # the bar's end moved lo, hi along its axis: apart, then inside
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if _distance_to_rounded_bar((point - mid * axis)[None], axis, radius, edge)[0] > 0:
                lo = mid
            else:
                hi = mid
        assert s == pytest.approx(lo, abs=1e-9)


def test_a_block_let_go_by_a_driven_bar_recovers_as_kelvin_voigt():
    """Push and release: the block of the driven-bar test pressed to 1 % strain,
    then the bar drawn back at 20 mm/s — far faster than the tissue recovers (E/2μ × 0.1 mm =
    1 mm/s) — so the face lets go and the block recovers freely, ε' = −(E/2μ) ε: backward Euler
    divides its compression by 1 + E Δt/2μ each step, and the bar takes no force and ends where
    its schedule puts it. (Weightless, the expanding block also pushes itself off the floor, so
    the compression is its top's sink less its bottom's.) Newton once failed at
    the first step that drew the bar back."""
    pytest.importorskip("tetgen")
    import trimesh

    from hifumotion.reference.creep_fe import CreepingTissue
    from hifumotion.reference.finite_strain_push import FiniteStrainSettings, finite_strain_reference

    box = trimesh.creation.box(extents=(10.0,) * 3)
    box.apply_translation((20.0, 5.0, 20.0))
    e, mu, dt = 1e4, 500.0, 0.025
    kinks = (0.0, 0.1, 0.105)
    travel = lambda t: float(np.interp(t, kinks, [0.0, 0.1, 0.0]))  # noqa: E731
    problem = CreepingTissue(box.vertices, box.faces, e, 0.0, mu, 0.0, 1e-3, (20.0, 10.0, 20.0), (0.0, -1.0, 0.0),
                             20.0, lambda t: 0.0, kinks, gravity_m_s2=0.0, max_volume_mm3=50.0, travel_mm=travel)
    times = np.array([0.0, 0.05, 0.1, 0.125, 0.15, 0.175, 0.2])
    sol = finite_strain_reference(problem, times, FiniteStrainSettings(step_s=dt))
    height = sol.p2.points_m[:, 1]
    top, bottom = np.isclose(height, 10e-3), np.isclose(height, 0.0)
    rise_mm = sol.displacement_m[:, sol.p2.dof_xyz[:, 1]] * 1e3
    compression_mm = rise_mm[:, bottom].mean(axis=1) - rise_mm[:, top].mean(axis=1)
    assert compression_mm[2] == pytest.approx(0.1, rel=0.01)          # pressed to the bar's travel
    decay = 1.0 / (1.0 + e * dt / (2 * mu))                           # per step of 0.025 s
    np.testing.assert_allclose(compression_mm[4:] / compression_mm[3:-1], decay, rtol=0.01)
    np.testing.assert_allclose(sol.force_n[3:], 0.0, atol=1e-12)
    np.testing.assert_allclose(sol.advance_mm, [travel(t) for t in times], atol=1e-9)


def test_a_lumpy_sample_is_driven_in_and_let_go_through_its_contacts_opening_and_closing():
    """``drive_release`` on a seeded sample, coarse: the bar's face meets one node first and
    more as it goes in, and lets go of them as it is drawn back faster than the tissue
    recovers. Newton used to fail at the first such switch (the line search judged the bar's
    prescribed increment by a linearisation blind to the contacts it closed or opened). The
    checks are physical: the bar's advance is its schedule; its force is ≥ 0, rises while it
    goes in and is nil once it has let go; the sample recovers towards rest after the release;
    no element inverts and no node sinks into the bar or the floor by more than 1 % of the mesh's
    spacing."""
    pytest.importorskip("tetgen")
    from hifumotion.experiment.blob import Blob
    from hifumotion.experiment.config import twin_config
    from hifumotion.experiment.fe_truth import fe_problem
    from hifumotion.reference.finite_strain_push import FiniteStrainSettings, finite_strain_reference

    cfg = twin_config("drive_release", {
        "seed": 5, "blob": {"size_mm": [24.0, 16.0, 20.0], "lobes": 4, "irregularity": 0.15},
        "tissue": {"youngs_modulus_pa": 10000.0, "poisson_ratio": 0.45, "beta1": 1e5, "beta2": 0.5},
        "bar": {"radius_mm": 5.0}, "physics": {"friction": 0.2},
        "protocol": {"peak_travel_mm": 2.0, "ramp_s": 0.6, "hold_s": 0.3},
        "truth": {"max_volume_mm3": 30.0, "surface_subdivisions": 2}})
    blob = Blob.random(cfg.blob.size_mm, cfg.blob.irregularity, cfg.blob.lobes, cfg.blob.bottom_cut, cfg.seed)
    problem, _ = fe_problem(cfg, blob, np.array([cfg.tank.size_mm[0] / 2, 0.0, cfg.tank.size_mm[2] / 2]))
    times = np.arange(0.0, 2.0, 0.1)
    sol = finite_strain_reference(problem, times, FiniteStrainSettings(step_s=0.05))
    np.testing.assert_allclose(sol.advance_mm, [problem.travel_mm(t) for t in times], atol=1e-9)
    pressing, let_go = (times > 0) & (times <= 0.6), times >= 1.5
    assert np.all(sol.force_n >= 0) and np.all(sol.force_n[pressing] > 0)
    assert np.all(np.diff(sol.force_n[pressing]) > 0)
    assert np.all(sol.force_n[let_go] == 0)
    moved = np.linalg.norm(sol.displacement_m - sol.displacement_m[0], axis=1)
    assert np.all(np.diff(moved[let_go]) < 0)
    spacing_mm = (6 * np.sqrt(2) * 30.0) ** (1 / 3)          # a regular tetrahedron's edge at the mesh's largest volume
    assert sol.stats["smallest_jacobian"] > 0
    assert max(sol.stats["floor_penetration_mm"], sol.stats["face_penetration_mm"]) < 0.01 * spacing_mm
