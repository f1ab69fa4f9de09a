"""The fast path (hifumotion.creep): analytic truths, constraints that hold, and the FE reference."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hifumotion.creep import CreepMaterial, CreepSettings, CreepSolver, ContactPlane, Punch, Surroundings, voxel_mesh
from hifumotion.errors import InputError

MM = 1e-3


def block(n: int, dx: float = 1.0) -> np.ndarray:
    ax = dx * (np.arange(n) + 0.5)
    return np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)


def pressed_block(n, e, nu, force, beta1=0.0, beta2=0.0, friction=0.0, gravity=(0.0, 0.0, 0.0), density=1e-3,
                  schedule=None, times=(0.0, 0.5), settings=None):
    mesh = voxel_mesh(block(n), 1.0)
    side = n * 1.0
    punch = None
    if force is not None:
        punch = Punch((side / 2 * MM, side * MM, side / 2 * MM), (0.0, -1.0, 0.0), 10 * side * MM,
                      schedule or (lambda t: force if t > 0 else 0.0), friction)
    solver = CreepSolver(mesh, CreepMaterial(e, nu, beta1=beta1, beta2=beta2, density_kg_m3=density,
                                             rate_floor_per_s=1e-12),
                         Surroundings(gravity), [ContactPlane((0, 0, 0), (0, 1, 0), friction)], punch, settings)
    return mesh, solver.run(np.asarray(times))


def test_uniaxial_compression_gives_youngs_modulus_and_poisson_ratio():
    # a cube on a frictionless floor under a frictionless punch wider than it: σ = F/A everywhere
    n, e, nu, force = 5, 8e3, 0.3, 0.02
    mesh, r = pressed_block(n, e, nu, force)
    stress = force / (n * MM) ** 2
    assert r.advance_mm[-1] == pytest.approx(stress / e * n, rel=1e-6)
    x = r.nodes_mm[-1]
    left, right = mesh.nodes_mm[:, 0] < 1e-9, mesh.nodes_mm[:, 0] > n - 1e-9
    width = x[right, 0].mean() - x[left, 0].mean()
    assert (width - n) / n == pytest.approx(nu * stress / e, rel=1e-4)
    assert r.bar_force_n[-1] == pytest.approx(force, rel=1e-9)


def test_block_under_its_weight_sinks_by_the_analytic_amount_and_not_into_the_floor():
    # ν = 0: u_top = ρ g H² / (2E), nodally exact for trilinear elements; stuck on a rough floor
    for n, dx in ((4, 1.0), (8, 0.5)):
        mesh = voxel_mesh(block(n, dx), dx)
        rho, g, e = 1000.0, 9.81, 2e3
        solver = CreepSolver(mesh, CreepMaterial(e, 0.0, beta1=0.0, density_kg_m3=rho), Surroundings((0, -g, 0)),
                             [ContactPlane((0, 0, 0), (0, 1, 0), 0.5)], None)
        r = solver.run(np.array([0.0, 0.1]))
        h = n * dx * MM
        top = mesh.nodes_mm[:, 1] > n * dx - 1e-9
        sag = -(r.nodes_mm[0][top, 1] - mesh.nodes_mm[top, 1]).mean() * MM
        assert sag == pytest.approx(rho * g * h ** 2 / (2 * e), rel=1e-6)
        assert r.nodes_mm[:, :, 1].min() >= -1e-9 * dx
        assert r.stats["max_penetration_mm"] <= 0.01 * dx


def test_a_round_bottomed_sample_settles_into_an_equilibrium_that_then_holds():
    # a conformed ellipsoid rests on a few floor nodes: a near-hinge whose soft mode the contact
    # rounds' loose solves do not resolve. Its settled state (frame 0) must be an equilibrium:
    # with nothing applied afterwards, nothing moves (a voxel surface short of the sample's once leaned it back 0.4 mm)
    from hifumotion.creep.scene_run import scene_material, tissue_mesh
    from hifumotion.scene import Scene

    scene = Scene()
    scene.particles.spacing_mm = 2.0
    mesh, _ = tissue_mesh(scene)
    material = dataclasses.replace(scene_material(scene), beta1=0.0)
    water = scene.tank.water_depth_mm * MM     # buoyant: the floor's few nodes carry little
    solver = CreepSolver(mesh, material, Surroundings((0.0, -9.81, 0.0), 1000.0, water),
                         [ContactPlane((0, 0, 0), (0, 1, 0), 3.0)], None)
    r = solver.run(np.array([0.0, 0.5, 1.0]))
    sag = np.abs(r.nodes_mm[0] - mesh.nodes_mm).max()
    assert sag > 0.1                                             # it did settle
    assert np.abs(r.nodes_mm[-1] - r.nodes_mm[0]).max() <= 0.01 * sag
    assert r.nodes_mm[:, :, 1].min() >= -0.01 * scene.particles.spacing_mm


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_conformed_voxels_lie_on_a_lumpy_surface(seed):
    # a boundary voxel whose centre is barely inside a sloped shoulder is mostly outside: put on
    # the surface it flattens. Held to a fifth of a cube's corner Jacobian, 30 % of the boundary
    # nodes of such samples stayed more than ¼ Δx off (a hook for a sliding bar, docs/decisions.md);
    # the distance is to the analytic surface the lattice was filled from
    import trimesh

    from hifumotion.creep.hexahedra import general_blocks
    from hifumotion.creep.conform import conform
    from hifumotion.experiment.blob import Blob

    dx = 2.0
    blob = Blob.random((30.0, 18.0, 24.0), 0.14, 5, 0.2, seed)
    star = blob.star_surface(3)
    lift = np.array([0.0, -np.asarray(star.vertices)[:, 1].min(), 0.0])
    surface = trimesh.Trimesh(np.asarray(star.vertices) + lift, star.faces)
    mesh = conform(voxel_mesh(blob.particles(dx) + lift, dx), surface)
    boundary = np.unique(mesh.surface_faces())
    off_floor = boundary[mesh.nodes_mm[boundary, 1] > 1e-9]
    signed = trimesh.proximity.signed_distance(surface, mesh.nodes_mm[off_floor])   # > 0 inside
    distance = np.abs(signed)
    assert np.mean(distance > 0.25 * dx) <= 0.05
    assert distance.max() <= 0.5 * dx
    # and none stands proud of it: a node the fold guard held back is projected again from where it
    # went (projected once, up to 0.39 Δx stayed outside on these samples, and a bar rested on them)
    assert -signed.min() <= 0.1 * dx
    *_, smallest = general_blocks(mesh.nodes_mm, mesh.elements, np.arange(len(mesh.elements)))
    assert smallest.min() > 0.0                                  # nothing folded


def test_a_voxel_that_conforming_would_flatten_is_moved_half_as_far_not_a_crash():
    # one voxel and a flat square through its middle: each corner's closest point is its
    # projection, top and bottom corners meet and the voxel is flat (det J = 0 at every point:
    # inverting J raised before the fold check could see it, a mesh of slide_stop_s49's true
    # surface at 1.25 × its lattice spacing did); the fold check halves the moves instead
    import trimesh

    from hifumotion.creep.hexahedra import general_blocks
    from hifumotion.creep.conform import conform

    mesh = voxel_mesh(np.array([[0.5, 0.5, 0.5]]), 1.0)
    flat = np.array([[-1.0, 0.5, -1.0], [2.0, 0.5, -1.0], [2.0, 0.5, 2.0], [-1.0, 0.5, 2.0]])
    plane = trimesh.Trimesh(flat, [[0, 1, 2], [0, 2, 3]], process=False)
    squashed = mesh.nodes_mm.copy()
    squashed[:, 1] = 0.5
    *_, flattened = general_blocks(squashed * MM, mesh.elements, np.arange(1))
    assert flattened[0] == 0.0
    once = conform(mesh, plane, floor_mm=None, projections=1)
    *_, smallest = general_blocks(once.nodes_mm * MM, once.elements, np.arange(1))
    assert smallest[0] > 0.0
    np.testing.assert_allclose(np.ptp(once.nodes_mm[:, 1]), 0.5)       # moved half way
    # projected again from there, twice: each time the whole way folds and half of what is left
    # does not (a corner Jacobian of ¼, then ⅛ of the cube's, above the guard's 1/100)
    conformed = conform(mesh, plane, floor_mm=None, projections=3)
    *_, smallest = general_blocks(conformed.nodes_mm * MM, conformed.elements, np.arange(1))
    assert smallest[0] > 0.0
    np.testing.assert_allclose(np.ptp(conformed.nodes_mm[:, 1]), 0.125)


def test_creep_under_a_held_load_follows_the_kelvin_voigt_law():
    # ν = 0, β2 = 0 (μ = β1): σ = E ε + 2μ ε̇ uniaxially, so ε(t) = σ/E (1 − exp(−E t / 2μ))
    n, e, mu, force = 3, 5e3, 2e3, 0.01
    tau = 2 * mu / e
    times = np.array([0.0, 0.5, 1.0, 2.0, 4.0]) * tau
    mesh, r = pressed_block(n, e, 0.0, force, beta1=mu, beta2=0.0, times=times,
                            settings=CreepSettings(tolerance=0.001))
    final = force / (n * MM) ** 2 / e * n
    expected = final * (1 - np.exp(-times / tau))
    assert np.abs(r.advance_mm - expected).max() <= 0.02 * final


def test_a_released_bar_rests_on_the_block_as_it_creeps_back_by_the_kelvin_voigt_law():
    # held, then let go: ε(t) = ε₁ exp(−(t − t₁)/τ) after t₁ (ν = 0: the weight's own strain is
    # settled at frame 0 and adds nothing to the change); the unloaded bar follows the top,
    # touching and taking no force (as the FE reference's bar does)
    n, e, mu, force = 3, 5e3, 2e3, 0.01
    tau = 2 * mu / e
    t1 = 4 * tau
    mesh = voxel_mesh(block(n), 1.0)
    punch = Punch((n / 2 * MM, n * MM, n / 2 * MM), (0.0, -1.0, 0.0), 10 * n * MM,
                  lambda t: force if 0 < t <= t1 else 0.0, 0.0, (t1,))
    # its weight (a hundredth of the push) keeps the block on the floor as it springs back
    solver = CreepSolver(mesh, CreepMaterial(e, 0.0, beta1=mu, beta2=0.0, density_kg_m3=1000.0, rate_floor_per_s=1e-12),
                         Surroundings((0.0, -9.81, 0.0)), [ContactPlane((0, 0, 0), (0, 1, 0), 0.0)], punch,
                         CreepSettings(tolerance=0.001))
    times = t1 + np.array([0.0, 0.5, 1.0, 2.0, 3.0]) * tau
    r = solver.run(np.r_[0.0, times])
    final = force / (n * MM) ** 2 / e * n
    held = final * (1 - np.exp(-t1 / tau))
    expected = held * np.exp(-(times - t1) / tau)
    assert np.abs(r.advance_mm[1:] - expected).max() <= 0.02 * held
    top = mesh.nodes_mm[:, 1] > n - 1e-9
    sink = -(r.nodes_mm[:, top, 1] - r.nodes_mm[0, top, 1]).mean(axis=1)   # since the settled frame 0
    np.testing.assert_allclose(sink[2:], r.advance_mm[2:], atol=1e-6 * n)   # touching, not lifted off
    assert np.all(r.bar_force_n[2:] == 0.0) and r.stats["max_penetration_mm"] <= 0.01


def test_the_bar_takes_its_force_and_nothing_crosses_a_surface():
    from hifumotion.creep.scene_run import simulate_creep
    from hifumotion.scene import Scene

    scene = Scene()
    scene.particles.spacing_mm = 3.0
    scene.tissue.beta1 = 5e4
    scene.tissue.rate_floor_per_s = 0.02
    scene.run.duration_s, scene.run.output_interval_s = 2.0, 0.25
    sim = simulate_creep(scene)
    taken = np.asarray(sim.facts["bar_force_n"])
    schedule = scene.bar.schedule()
    assert np.allclose(taken[1:], [schedule(t) for t in sim.times_s[1:]], rtol=1e-6)
    assert sim.facts["creep_max_penetration_mm"] <= 0.01 * scene.particles.spacing_mm
    descent = sim.tissue_mm[0, :, 1] - sim.tissue_mm[-1, :, 1]
    assert descent.mean() > 0  # pushed down
    assert np.all(np.diff(sim.bar_centre_mm[:, 1]) <= 1e-9)  # a push that only grows never lifts the bar


def test_fast_path_agrees_with_the_finite_element_reference():
    import trimesh

    from hifumotion.creep.scene_run import scene_punch, simulate_creep, tissue_mesh
    from hifumotion.scene import Scene
    from hifumotion.reference import PunchedTissue, punch_reference

    scene = Scene()
    scene.tissue.beta1 = 0.0  # the relaxed limit the reference solves
    # the reference's floor and bar are stuck; a rough floor (μ = 3: nothing here pulls sideways
    # by a third of its push) is their limit. (μ ≫ 1 is out of the fast path's reach: its rounds
    # take the friction at the last round's normal reactions, and at μ = 100 an edge node of
    # the patch chatters on and off the floor — docs/decisions.md)
    scene.physics.friction = 3.0
    scene.particles.spacing_mm = 2.0
    scene.run.duration_s, scene.run.output_interval_s = 1.0, 0.5
    mesh, _ = tissue_mesh(scene)
    sim = simulate_creep(scene, mesh=mesh)
    punch, axis = scene_punch(scene, mesh.centres_mm, 2.0)
    surface = trimesh.creation.icosphere(subdivisions=3)
    surface.apply_scale(np.asarray(scene.tissue.size_mm) / 2)
    surface.apply_translation([25.0, 9.0, 20.0])
    ref = punch_reference(PunchedTissue(surface.vertices, surface.faces, scene.tissue.youngs_modulus_pa,
                                        scene.tissue.poisson_ratio, tuple(np.asarray(punch.tip_m) / MM), tuple(axis),
                                        scene.bar.radius_mm, scene.bar.force_n, max_volume_mm3=8.0))
    assert ref.force_n == pytest.approx(scene.bar.force_n, rel=1e-3)
    u_fast = sim.tissue_mm[-1] - mesh.centres_mm
    u_ref = ref.at(mesh.centres_mm)
    rms = math.sqrt(((u_fast - u_ref) ** 2).sum(1).mean())
    # measured 0.036 of the peak at 2 mm (0.032 at 2.2 mm), with the model's rim rounded at half a
    # spacing (1 mm of the 6 mm bar here). It was once 0.154: the boundary voxels
    # were left a staircase where conforming them would flatten them below ⅕ of a cube, and the
    # settled ellipsoid, resting on two floor nodes, leaned 0.7 mm (its soft mode left by the
    # contact rounds' loose solve) — docs/decisions.md, "The voxels meet the surface"
    assert rms <= 0.05 * np.linalg.norm(u_ref, axis=1).max()


def test_reference_uniaxial_box():
    import trimesh

    from hifumotion.reference import PunchedTissue, punch_reference

    box = trimesh.creation.box(extents=(10, 10, 10))
    box.apply_translation((5, 5, 5))
    box = box.subdivide().subdivide()
    ref = punch_reference(PunchedTissue(box.vertices, box.faces, 1e4, 0.0, (5, 10, 5), (0, -1, 0), 30.0, 0.05,
                                        density_kg_m3=1000.0, max_volume_mm3=4.0))
    assert ref.advance_mm == pytest.approx(0.05 * 10e-3 / (1e4 * 1e-4) / MM, rel=1e-5)


def test_bad_input_is_refused_with_a_named_field():
    with pytest.raises(InputError, match="lattice"):
        voxel_mesh(np.random.default_rng(0).random((20, 3)), 1.0)
    with pytest.raises(InputError, match="share"):
        voxel_mesh(np.zeros((2, 3)), 1.0)
    mesh = voxel_mesh(block(2), 1.0)
    with pytest.raises(InputError, match="Poisson"):
        CreepSolver(mesh, CreepMaterial(1e3, 0.5), Surroundings(), [ContactPlane((0, 0, 0), (0, 1, 0))], None)
    solver = CreepSolver(mesh, CreepMaterial(1e3, 0.3), Surroundings(), [ContactPlane((0, 0, 0), (0, 1, 0))], None)
    with pytest.raises(InputError, match="increasing"):
        solver.run(np.array([1.0, 0.5]))


def test_clamped_beam_sags_as_beam_theory_says():
    # hifumotion validate cantilever's beam (80 × 10 × 6 mm, E = 10 MPa, ν = 0, its weight), clamped
    # by a bonded wall: Euler–Bernoulli 3ρgL⁴/(2Eh²) within the case's 3 %, approaching Timoshenko's
    # shear-corrected value (+ 4EI/(κGAL²) = +1.25 % here) as the spacing halves
    length, height, width, e, rho, g = 0.08, 0.01, 0.006, 1e7, 1000.0, 9.81
    euler = 3 * rho * g * length ** 4 / (2 * e * height ** 2)
    timoshenko = euler * (1 + 4 * (e * height ** 2 / 12) / ((5 / 6) * (e / 2) * height ** 2 * length ** 2))
    errors = []
    for layers in (5, 10):
        dx = height / layers
        axes = [dx * (np.arange(round(s / dx)) + 0.5) for s in (length, height, width)]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) / MM + np.array([0.0, 20.0, 0.0])
        mesh = voxel_mesh(pts, dx / MM)
        solver = CreepSolver(mesh, CreepMaterial(e, 0.0, beta1=0.0, density_kg_m3=rho), Surroundings((0, -g, 0)),
                             [ContactPlane((0, 0, 0), (1, 0, 0), bonded=True)], None)
        r = solver.run(np.array([0.0, 0.1]))
        tip = mesh.nodes_mm[:, 0] > length / MM - 1e-6
        sag = -(r.nodes_mm[0][tip, 1] - mesh.nodes_mm[tip, 1]).mean() * MM
        assert sag == pytest.approx(euler, rel=0.03)
        errors.append(abs(sag - timoshenko))
    assert errors[1] < errors[0]


def _rigid_block_on_elastic_stick(times_s, accel_push, mu, g, eps_m):
    """x(t) (m) of a rigid block from rest, pushed at ``accel_push`` = F/M against friction
    μ M g min(x/ε, 1): harmonic until x = ε (ω² = μ g/ε), then at F/M − μ g."""
    if mu == 0:
        return 0.5 * accel_push * times_s ** 2
    omega = math.sqrt(mu * g / eps_m)
    x_eq = accel_push / omega ** 2
    t1 = math.acos(1 - eps_m / x_eq) / omega
    v1 = accel_push / omega * math.sin(omega * t1)
    late = times_s - t1
    return np.where(times_s < t1, x_eq * (1 - np.cos(omega * times_s)),
                    eps_m + v1 * late + 0.5 * (accel_push - mu * g) * late ** 2)


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_a_block_pushed_along_a_rough_floor_sticks_below_coulombs_limit_and_slides_at_its_rate_above(mu):
    # a stiff cube (E/ρg·side ~ 10⁴) pushed sideways by a frictionless bar at mid-height:
    # below μ M g it sticks — nothing moves beyond the elastic stick's reach ε (and the cube's
    # own compression, 10⁻⁸ m here); above it, it slides as a rigid block whose friction is
    # μ M g min(x/ε, 1) (an analytic motion), to backward Euler's first-order error, held
    # small by a tight step tolerance
    n, rho, g, e = 3, 1000.0, 9.81, 1e6
    side = n * MM
    mass = rho * side ** 3
    mesh = voxel_mesh(block(n), 1.0)
    eps_mm = CreepSettings().stick_mm
    for ratio in ((0.5, 2.0) if mu > 0 else (2.0,)):
        force = ratio * max(mu, 0.5) * mass * g
        punch = Punch((0.0, side / 2, side / 2), (1.0, 0.0, 0.0), 10 * side, lambda t, f=force: f if t > 0 else 0.0, 0.0)
        solver = CreepSolver(mesh, CreepMaterial(e, 0.0, beta1=0.0, density_kg_m3=rho), Surroundings((0.0, -g, 0.0)),
                             [ContactPlane((0, 0, 0), (0, 1, 0), mu)], punch, CreepSettings(tolerance=1e-4))
        times = np.array([0.0, 0.01, 0.02])
        r = solver.run(times)
        if force < mu * mass * g:
            assert np.abs(r.advance_mm).max() <= 1.05 * eps_mm
            bottom = mesh.nodes_mm[:, 1] < 1e-9
            assert np.abs(r.nodes_mm[-1][bottom, 0] - r.nodes_mm[0][bottom, 0]).max() <= eps_mm
        else:
            expected = _rigid_block_on_elastic_stick(times, force / mass, mu, g, eps_mm * MM) / MM
            np.testing.assert_allclose(r.advance_mm[1:], expected[1:], rtol=0.02)
            assert r.bar_force_n[-1] == pytest.approx(force, rel=1e-6)


@pytest.mark.parametrize("angle_deg, floor_mu, face_mu", [(35.0, 0.15, 0.15), (45.0, 0.3, 0.2), (30.0, 0.1, 0.3)])
def test_a_tilted_bar_drives_a_stiff_block_along_a_rough_floor_as_a_rigid_wedge(angle_deg, floor_mu, face_mu):
    # a slide's statics and kinematics in closed form: a stiff cube whose top edge is driven by
    # a bar tilted θ from the vertical, along its axis a = (sin θ, −cos θ). A rigid block on the
    # floor keeps the face's normal gap closed only by sliding: dx = dδ / sin θ. It slides up
    # the face (relative to the bar) along t = (cos θ, sin θ), so the face's friction on it is
    # −μ_b P t, the floor's −μ_f N; the horizontal and vertical balances give
    # P = μ_f W / (sin θ − μ_b cos θ − μ_f (cos θ + μ_b sin θ))
    n, rho, g, e = 4, 1000.0, 9.81, 1e6
    theta = math.radians(angle_deg)
    side = n * MM
    weight = rho * side ** 3 * g
    axis = np.array([math.sin(theta), -math.cos(theta), 0.0])
    along_face = np.array([math.cos(theta), math.sin(theta), 0.0])
    radius = 5 * MM
    top_edge = np.array([0.0, side, side / 2])
    # the face's centre behind the edge, so the edge stays on the flat face as it slides up it
    tip = top_edge - 0.5 * radius * along_face - 0.05 * MM * axis
    travel_m = 1.0 * MM
    punch = Punch(tuple(tip), tuple(axis), radius, lambda t: 0.0, face_mu, (), travel_m=lambda t: travel_m * t)
    mesh = voxel_mesh(block(n), 1.0)
    solver = CreepSolver(mesh, CreepMaterial(e, 0.3, beta1=0.0, density_kg_m3=rho), Surroundings((0.0, -g, 0.0)),
                         [ContactPlane((0, 0, 0), (0, 1, 0), floor_mu)], punch, CreepSettings(tolerance=1e-4))
    r = solver.run(np.linspace(0.0, 1.0, 6))
    x_mm = (r.nodes_mm[:, :, 0] - mesh.nodes_mm[None, :, 0]).mean(1)
    sliding = slice(2, None)          # past the elastic stick's onset
    rate = np.polyfit(r.advance_mm[sliding], x_mm[sliding], 1)[0]
    assert rate == pytest.approx(1.0 / math.sin(theta), rel=1e-3)
    push = floor_mu * weight / (math.sin(theta) - face_mu * math.cos(theta)
                                - floor_mu * (math.cos(theta) + face_mu * math.sin(theta)))
    np.testing.assert_allclose(r.bar_force_n[sliding], push, rtol=1e-3)
    # and nothing tips it: the block's bottom stays on the floor
    assert np.abs(r.nodes_mm[-1][mesh.nodes_mm[:, 1] < 1e-9, 1]).max() < 1e-3


def test_the_blockwise_reduction_is_the_sparse_product():
    """The reduced matrix built node block by node block (creep/eliminate.py) against Tᵀ A T by
    SciPy's sparse products, for free nodes, sliding contacts on a floor and a tilted bar
    (turned frames, the bar's column) and bonded ones (zero columns)."""
    from hifumotion.creep.contact import STICK

    n = 4
    mesh = voxel_mesh(block(n), 1.0)
    axis = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    punch = Punch((2 * MM, 4 * MM, 2 * MM), tuple(axis), 10 * MM, lambda t: 0.1, 0.5)
    planes = [ContactPlane((0, 0, 0), (0, 1, 0), 0.5), ContactPlane((0, 0, 0), (1, 0, 0), 0.5, bonded=True)]
    solver = CreepSolver(mesh, CreepMaterial(1e4, 0.45, beta1=1e3, beta2=0.5), Surroundings(), planes, punch)
    rest = solver.rest_m
    cs = solver.contacts
    zero = np.zeros_like(rest)
    floor = np.flatnonzero(rest[:, 1] < 1e-9)
    wall = np.flatnonzero((rest[:, 0] < 1e-9) & (rest[:, 1] > 1e-9) & (rest[:, 1] < 4 * MM - 1e-9))
    top = np.flatnonzero(rest[:, 1] > 4 * MM - 1e-9)
    cs.touch(floor, np.zeros(len(floor), np.int64), zero)
    cs.touch(wall, np.ones(len(wall), np.int64), zero)
    cs.touch(top, np.full(len(top), cs.punch_index), zero)
    assert np.all(cs.status[wall] == STICK)
    rate = np.random.default_rng(3).uniform(0.0, 2.0, len(mesh.elements))
    a, _ = solver._matrices(0.05, solver.material.viscosity(rate))
    t, _, s_col, constrained = solver._reduction()
    assert s_col >= 0
    got = solver._reduced(a, t).toarray()
    expected = (t.T @ a @ t).toarray()
    free = np.setdiff1d(np.arange(t.shape[1]), constrained)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(got[np.ix_(free, free)], expected[np.ix_(free, free)], atol=1e-12 * scale)
    # a constrained unknown: an identity row and column, scaled to its node's diagonal
    assert np.all(got[constrained][:, free] == 0.0) and np.all(got[free][:, constrained] == 0.0)
    assert np.all(np.diag(got)[constrained] > 0)


def test_the_reduced_shear_rates_are_the_meshs_own():
    # the rates the hyper-reduction reads straight from q̇ (reduced/hyper.py) against the mesh's
    # kernel on the node velocities, for random modes on a block with a displaced (distorted) corner
    from hifumotion.creep.hexahedra import MeshMatrices
    from hifumotion.reduced.hyper import rate_modes, shear_rates

    mesh = voxel_mesh(block(3), 1.0)
    nodes = mesh.nodes_mm * MM
    corner = np.argmin(np.linalg.norm(nodes, axis=1))
    nodes[corner] += 0.1 * MM
    m = MeshMatrices(nodes, mesh.elements, MM)
    assert len(m.distorted) > 0
    rng = np.random.default_rng(4)
    modes = rng.normal(size=(3 * len(nodes), 5))
    qdot = rng.normal(size=5)
    np.testing.assert_allclose(shear_rates(rate_modes(m, modes, np.arange(len(mesh.elements))), qdot),
                               m.rates((modes @ qdot).reshape(-1, 3)), rtol=1e-10)


def _least_distance_problem(seed, rows=160, r=12):
    # contact rows as the reduced model's: many, redundant (pairs nearly alike), in few dimensions
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(rows // 2, r))
    g = np.vstack([g, g + 1e-6 * rng.normal(size=g.shape)])
    h = g @ rng.normal(size=r) - np.abs(rng.normal(size=rows))     # a point meets every row: feasible
    return g, h


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nnls_started_anywhere_reaches_the_optimum_scipys_finds(seed):
    # Lawson & Hanson from a guessed passive set (reduced/nnls.py) against SciPy's cold NNLS on the
    # least-distance problems the reduced contacts make: the same residual, and the optimality
    # conditions (w ≥ 0, gradient ≤ 0 where w = 0 and ≈ 0 where w > 0)
    from scipy.optimize import nnls

    from hifumotion.reduced.nnls import nnls_from

    g, h = _least_distance_problem(seed)
    e = np.vstack([g.T, h[None]])
    f = np.zeros(len(e))
    f[-1] = 1.0
    reference, _ = nnls(e, f, maxiter=5000)
    best = np.linalg.norm(e @ reference - f)
    rng = np.random.default_rng(seed + 10)
    starts = [np.zeros(0, np.int64), np.flatnonzero(reference > 0), rng.choice(len(h), 30, replace=False),
              np.arange(len(h))]
    for start in starts:
        w, converged = nnls_from(e, f, np.asarray(start, np.int64), 3 * len(h))
        assert converged
        assert w.min() >= 0.0
        assert np.linalg.norm(e @ w - f) <= best * (1 + 1e-9) + 1e-12
        gradient = e.T @ (f - e @ w)
        assert gradient[w == 0].max() <= 1e-9
        np.testing.assert_allclose(gradient[w > 0], 0.0, atol=1e-9)


def test_the_contact_solves_response_is_its_derivative():
    # ReducedCreep.solve_response against the contact solve's own finite differences: random
    # stiffness, contact rows that press, right-hand sides moved along random directions by
    # amounts too small to change which rows press
    from hifumotion.reduced.model import ReducedCreep, ReducedSettings

    g, h = _least_distance_problem(3, rows=80, r=10)
    rng = np.random.default_rng(7)
    root = rng.normal(size=(10, 10))
    a = root @ root.T + 10 * np.eye(10)
    rhs = rng.normal(size=10)
    model = ReducedCreep.__new__(ReducedCreep)        # only the contact solve's parts
    model.rows, model.bound, model._bar = g, -0.2 * np.abs(h), None
    model.settings, model.dx_m, model._pressed = ReducedSettings(contact_tolerance=1e-12), 1.0, np.zeros(0, np.int64)
    stats = {"contact_solves": 0}
    q = model._solve(a, rhs, stats, np.zeros(10))
    pressed = len(model._pressed)
    assert 0 < pressed < 10, "the problem should press some rows but not pin every coordinate"
    directions = rng.normal(size=(10, 3))
    response = model.solve_response(directions)
    step = 1e-7
    for k in range(3):
        moved = model._solve(a, rhs + step * directions[:, k], stats, np.zeros(10))
        assert len(model._pressed) == pressed
        np.testing.assert_allclose((moved - q) / step, response[:, k], rtol=1e-4, atol=1e-6)
    # the rows that press do not move; a free direction is a's own response
    np.testing.assert_allclose(g[model._pressed] @ response, 0.0, atol=1e-8)


def test_a_driven_bar_takes_the_force_its_travel_needs_and_the_block_its_poisson_bulge():
    # travel control: the bar's end driven δ into a cube on a frictionless floor (a frictionless
    # face wider than it): uniaxial stress, so the bar takes F = E A δ / h and the cube widens ν δ / h
    n, e, nu, travel_m = 5, 8e3, 0.3, 0.05e-3
    mesh = voxel_mesh(block(n), 1.0)
    punch = Punch((n / 2 * MM, n * MM, n / 2 * MM), (0.0, -1.0, 0.0), 10 * n * MM, lambda t: 0.0, 0.0,
                  travel_m=lambda t: travel_m if t > 0 else 0.0)
    solver = CreepSolver(mesh, CreepMaterial(e, nu, beta1=0.0, beta2=0.0, density_kg_m3=1e-3, rate_floor_per_s=1e-12),
                         Surroundings((0.0, 0.0, 0.0)), [ContactPlane((0, 0, 0), (0, 1, 0), 0.0)], punch)
    r = solver.run(np.array([0.0, 0.5]))
    assert r.advance_mm[-1] == pytest.approx(travel_m / MM, rel=1e-12)
    assert r.bar_force_n[-1] == pytest.approx(e * (n * MM) ** 2 * travel_m / (n * MM), rel=1e-6)
    x = r.nodes_mm[-1]
    left, right = mesh.nodes_mm[:, 0] < 1e-9, mesh.nodes_mm[:, 0] > n - 1e-9
    assert (x[right, 0].mean() - x[left, 0].mean() - n) / n == pytest.approx(nu * travel_m / (n * MM), rel=1e-4)


def test_a_bar_driven_at_a_steady_rate_takes_the_kelvin_voigt_force_in_full_and_reduced():
    # ν = 0, Eq. 16's μ constant: a cube driven at a steady rate v takes F = A (E v t + 2 μ v) / h
    # (the elastic stress and the viscous one, σ_v = 2 μ ε̇, with no lateral strain). The reduced
    # model's modes come from the full run at v; it is run at 2 v, which its snapshots never had.
    n, e, mu = 3, 5e3, 2e3
    tau = 2 * mu / e
    times = np.array([0.0, 0.5, 1.0, 2.0, 4.0]) * tau
    rate = 0.05e-3 / times[-1]                       # m/s: 0.05 mm over the run
    mesh = voxel_mesh(block(n), 1.0)
    material = CreepMaterial(e, 0.0, beta1=mu, beta2=0.0, density_kg_m3=1e-3, rate_floor_per_s=1e-12)
    punch = Punch((n / 2 * MM, n * MM, n / 2 * MM), (0.0, -1.0, 0.0), 10 * n * MM, lambda t: 0.0, 0.0,
                  travel_m=lambda t: rate * t)
    full = CreepSolver(mesh, material, Surroundings((0.0, 0.0, 0.0)), [ContactPlane((0, 0, 0), (0, 1, 0), 0.0)], punch,
                       CreepSettings(tolerance=0.001))
    r = full.run(times)
    area_over_height = (n * MM) ** 2 / (n * MM)
    expected = area_over_height * (e * rate * times + 2 * mu * rate)
    np.testing.assert_allclose(r.bar_force_n[1:], expected[1:], rtol=1e-6)
    np.testing.assert_allclose(r.advance_mm, rate * times / MM, rtol=1e-9, atol=1e-12)
    reduced = _reduced_of(full, [r], tolerance=0.001)
    fast = reduced.run(material, lambda t: 0.0, (), times, travel_m=lambda t: 2 * rate * t)
    np.testing.assert_allclose(fast.advance_mm, 2 * rate * times / MM, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(fast.bar_force_n[1:], 2 * expected[1:], rtol=1e-3)


def _reduced_of(solver, runs, **settings):
    from hifumotion.reduced.model import ReducedCreep, ReducedSettings, pod_basis

    return ReducedCreep(solver, pod_basis(runs), ReducedSettings(**settings))


def test_the_reduced_model_creeps_by_the_kelvin_voigt_law_under_a_force_its_snapshots_never_had():
    # the snapshots at one force, the reduced run at three times it: ε(t) = σ/E (1 − exp(−E t / 2μ))
    n, e, mu, force = 3, 5e3, 2e3, 0.01
    tau = 2 * mu / e
    times = np.array([0.0, 0.5, 1.0, 2.0, 4.0]) * tau
    mesh = voxel_mesh(block(n), 1.0)
    material = CreepMaterial(e, 0.0, beta1=mu, beta2=0.0, density_kg_m3=1e-3, rate_floor_per_s=1e-12)

    def solver_at(f):
        punch = Punch((n / 2 * MM, n * MM, n / 2 * MM), (0.0, -1.0, 0.0), 10 * n * MM, lambda t: f if t > 0 else 0.0)
        return CreepSolver(mesh, material, Surroundings((0.0, 0.0, 0.0)), [ContactPlane((0, 0, 0), (0, 1, 0), 0.0)], punch,
                           CreepSettings(tolerance=0.001))

    full = solver_at(force)
    reduced = _reduced_of(full, [full.run(times)], tolerance=0.001)
    r = reduced.run(material, lambda t: 3 * force if t > 0 else 0.0, (), times)
    final = 3 * force / (n * MM) ** 2 / e * n
    expected = final * (1 - np.exp(-times / tau))
    assert np.abs(r.advance_mm - expected).max() <= 0.02 * final
    assert r.stats["modes"] <= 4


def _rough_floor_block(mu: float):
    """The reduced tests' rough-floor block: a stiff 3-voxel cube (E 1 MPa, 1 mm voxels) on a
    floor of friction ``mu``, pushed sideways at mid-height by a frictionless bar; returns its
    mesh, material, mass (kg), g (m/s²), the elastic stick's reach (mm), the output times (s)
    and ``solver_at(force_n)``, the full model under that push."""
    n, rho, g = 3, 1000.0, 9.81
    side = n * MM
    mesh = voxel_mesh(block(n), 1.0)
    material = CreepMaterial(1e6, 0.0, beta1=0.0, density_kg_m3=rho)

    def solver_at(force):
        punch = Punch((0.0, side / 2, side / 2), (1.0, 0.0, 0.0), 10 * side, lambda t, f=force: f if t > 0 else 0.0, 0.0)
        return CreepSolver(mesh, material, Surroundings((0.0, -g, 0.0)), [ContactPlane((0, 0, 0), (0, 1, 0), mu)], punch,
                           CreepSettings(tolerance=1e-4))

    return (mesh, material, rho * side ** 3, g, CreepSettings().stick_mm, np.array([0.0, 0.005, 0.01, 0.015, 0.02]),
            solver_at)


def test_the_reduced_model_sticks_below_coulombs_limit_and_slides_at_its_rate_above():
    # the rough-floor block of the full model's test, reduced: modes from full runs that stick
    # (half of μ M g) and slide (twice it); the reduced runs at forces neither had must stick
    # within the elastic stick's reach below μ M g (0.4 of it: the stick's swing, twice
    # F ε / μ M g, stays inside ε) and slide as the analytic rigid block above it — and
    # without friction the same modes slide at any force
    mu = 0.5
    mesh, material, mass, g, eps_mm, times, solver = _rough_floor_block(mu)

    def solver_at(ratio):
        return solver(ratio * mu * mass * g)

    snapshots = [solver_at(r).run(times) for r in (0.5, 2.0)]
    bottom = mesh.nodes_mm[:, 1] < 1e-9
    for friction in (True, False):
        reduced = _reduced_of(solver_at(1.0), snapshots, tolerance=1e-4, friction=friction)
        if friction:
            # at rest the floor's normal reactions carry the weight (the force balance), and
            # only the bottom presses
            settled = reduced.settle(reduced.loads(material), 0.0)
            pressing = reduced.friction.nodes[settled.friction.pressing]
            assert settled.friction.limit_n.sum() / mu == pytest.approx(mass * g, rel=0.01)
            assert np.all(mesh.nodes_mm[pressing, 1] < 1e-9)
        for ratio in (0.4, 1.5):
            force = ratio * mu * mass * g
            r = reduced.run(material, lambda t, f=force: f if t > 0 else 0.0, (), times)
            slid_mm = np.abs(r.nodes_mm[-1][bottom, 0] - r.nodes_mm[0][bottom, 0]).max()
            if not friction:
                assert slid_mm > 10 * eps_mm      # nothing holds it
            elif ratio < 1:
                assert np.abs(r.advance_mm).max() <= 1.05 * eps_mm
                assert slid_mm <= eps_mm
            else:
                expected = _rigid_block_on_elastic_stick(times, force / mass, mu, g, eps_mm * MM) / MM
                np.testing.assert_allclose(r.advance_mm[1:], expected[1:], rtol=0.03)
                assert r.stats["friction_rounds"] > 0


def test_the_reduced_model_run_at_another_friction_sticks_and_slides_by_coulombs_law_at_that_friction():
    # the rough-floor block's modes made at μ 0.5 (runs that stick and slide), run at μ 0.25 and
    # 1.0 (the fitted friction of a driven slide reaches the reduced model this way): a push of
    # 0.375 M g slides it at μ 0.25 as the analytic rigid block at μ 0.25 does, and holds it at
    # μ 1.0 and at the μ it was made at, within the elastic stick's swing
    made = 0.5
    mesh, material, mass, g, eps_mm, times, solver_at = _rough_floor_block(made)
    snapshots = [solver_at(r * made * mass * g).run(times) for r in (0.5, 2.0)]
    reduced = _reduced_of(solver_at(0.0), snapshots, tolerance=1e-4)
    force = 0.375 * mass * g
    bottom = mesh.nodes_mm[:, 1] < 1e-9
    for mu in (0.25, 1.0, None):
        r = reduced.run(material, lambda t: force if t > 0 else 0.0, (), times, friction=mu)
        slid_mm = np.abs(r.nodes_mm[-1][bottom, 0] - r.nodes_mm[0][bottom, 0]).max()
        if mu == 0.25:
            expected = _rigid_block_on_elastic_stick(times, force / mass, mu, g, eps_mm * MM) / MM
            np.testing.assert_allclose(r.advance_mm[1:], expected[1:], rtol=0.03)
        else:
            # 0.375 M g is below μ M g at 0.5 (the made μ, None) and at 1.0: it sticks, its
            # elastic stick swinging at most twice F ε / μ M g
            swing = 2 * force / ((mu or made) * mass * g) * eps_mm
            assert slid_mm <= 1.05 * swing
            assert np.abs(r.advance_mm).max() <= 1.05 * swing
    with pytest.raises(InputError, match="friction"):
        reduced.run(material, lambda t: force, (), times, friction=-0.1)


def test_the_balanced_floor_reactions_carry_the_weight_and_the_push():
    # a block on a rough floor pressed from above by the bar: at rest the floor carries M g + F
    # (vertical equilibrium), which the balance gives the friction's limits whatever the rows say
    n, rho, g, mu = 3, 1000.0, 9.81, 0.5
    side = n * MM
    mass = rho * side ** 3
    mesh = voxel_mesh(block(n), 1.0)
    material = CreepMaterial(1e6, 0.0, beta1=0.0, density_kg_m3=rho)
    times = np.array([0.0, 0.005, 0.01])

    def solver_at(force):
        punch = Punch((side / 2, side, side / 2), (0.0, -1.0, 0.0), 10 * side, lambda t, f=force: f if t > 0 else 0.0, 0.0)
        return CreepSolver(mesh, material, Surroundings((0.0, -g, 0.0)), [ContactPlane((0, 0, 0), (0, 1, 0), mu)], punch,
                           CreepSettings(tolerance=1e-4))

    push = 3 * mass * g
    snapshots = [solver_at(f * push).run(times) for f in (0.5, 2.0)]
    reduced = _reduced_of(solver_at(push), snapshots, tolerance=1e-4, friction_balance=True)
    settled = reduced.settle(reduced.loads(material), push)
    floor = reduced.friction.body[settled.friction.pressing] == 0
    carried = settled.friction.limit_n[settled.friction.pressing][floor].sum() / mu
    assert carried == pytest.approx(mass * g + push, rel=1e-9)


@pytest.mark.parametrize("scale", [0.7, 1.4])
def test_the_reduced_model_follows_the_full_one_on_the_floor_at_pushes_its_snapshots_never_had(scale):
    # an ellipsoid pushed onto a rough floor: its curved bottom lands on the floor as it is
    # squashed, so the contact set grows. The modes come from full runs at half and twice
    # the push; the reduced run at a push between must keep to the full run's motion (3 % of
    # it) and off the floor.
    from hifumotion.creep.scene_run import creep_solver, output_times, scene_material, scene_punch, snapshot_run, tissue_mesh
    from hifumotion.scene import Scene

    def scene_at(f):
        return Scene.model_validate({
            "tissue": {"shape": "ellipsoid", "size_mm": [30, 18, 24], "youngs_modulus_pa": 1e4, "poisson_ratio": 0.46,
                       "beta1": 5e5, "beta2": 0.5},
            "bar": {"radius_mm": 5.0, "force_n": 0.5 * f, "ramp_s": 1.0}, "particles": {"spacing_mm": 3.0},
            "run": {"duration_s": 6.0, "output_interval_s": 0.1, "write_vtu": False}})

    mesh, vol = tissue_mesh(scene_at(1.0))
    snapshots = [snapshot_run(scene_at(f), mesh, vol) for f in (0.5, 2.0)]
    scene = scene_at(scale)
    truth = [snapshot_run(scene, mesh, vol)]
    punch, _ = scene_punch(scene, mesh.centres_mm, scene.particles.spacing_mm)
    moved = truth[0].particles_mm - truth[0].particles_mm[:1]
    motion = np.sqrt(np.mean(np.sum(moved ** 2, axis=-1), axis=1))
    assert motion.max() > 0.3     # mm: a push that squashes it
    # every voxel's viscosity summed, and ECSW's sample of them (fewer voxels, the same motion)
    for hyper in (False, True):
        reduced = _reduced_of(creep_solver(scene_at(1.0), mesh)[0], snapshots, hyper_reduction=hyper)
        r = reduced.run(scene_material(scene), punch.force_n, punch.breakpoints_s, output_times(scene))
        error = np.sqrt(np.mean(np.sum((r.particles_mm - r.particles_mm[:1] - moved) ** 2, axis=-1), axis=1))
        assert error.max() <= 0.03 * motion.max()
        assert r.nodes_mm[..., 1].min() >= -1e-3 * scene.particles.spacing_mm     # nothing through the floor
        assert r.stats["contact_solves"] > 0
        assert (r.stats["viscous_voxels"] < len(mesh.elements)) == hyper


@pytest.mark.parametrize("own_mm, expected_mm", [(None, 0.5), (0.1, 0.5), (0.8, 0.8), (20.0, 5.0)])
def test_the_bars_rim_is_rounded_at_its_own_edge_or_half_a_spacing_whichever_is_rounder(own_mm, expected_mm):
    # a voxel mesh cannot see an edge sharper than about half its spacing (1 mm here); a bar
    # machined rounder than that is rounded as it is; no rounding exceeds the bar's radius (5 mm)
    mesh = voxel_mesh(block(3), 1.0)
    punch = Punch((1.5 * MM, 3 * MM, 1.5 * MM), (0.0, -1.0, 0.0), 5 * MM, lambda t: 0.0, 0.0,
                  edge_radius_m=None if own_mm is None else own_mm * MM)
    solver = CreepSolver(mesh, CreepMaterial(1e4, 0.3), Surroundings((0.0, 0.0, 0.0)),
                         [ContactPlane((0, 0, 0), (0, 1, 0), 0.0)], punch)
    assert solver.punch.edge_radius_m == pytest.approx(expected_mm * MM)


def test_nodes_that_stay_on_the_floor_and_the_bars_face_in_every_snapshot_are_held_there_by_the_modes():
    """The tilted bar drives the stiff block (the wedge above) in two full runs: in the reduced
    model's basis the bottom nodes' floor-normal motion is exactly zero and the face nodes'
    axial motion exactly the bar's advance (the full model's pressed contacts), the modes stay
    orthonormal and hold the snapshots as before, and the reduced block driven 3× the
    shorter snapshot's travel slides at the closed form's dx = dδ / sin θ."""
    from hifumotion.reduced.model import ReducedCreep, ReducedSettings, held_on_solids, pod_basis

    n, rho, g, e = 4, 1000.0, 9.81, 1e6
    theta = math.radians(35.0)
    side = n * MM
    axis = np.array([math.sin(theta), -math.cos(theta), 0.0])
    along_face = np.array([math.cos(theta), math.sin(theta), 0.0])
    radius = 8 * MM
    tip = np.array([0.0, side, side / 2]) - 0.5 * radius * along_face - 0.05 * MM * axis
    mesh = voxel_mesh(block(n), 1.0)
    material = CreepMaterial(e, 0.3, beta1=0.0, density_kg_m3=rho)

    def solver(travel_m):
        punch = Punch(tuple(tip), tuple(axis), radius, lambda t: 0.0, 0.1, (), travel_m=lambda t: travel_m * t)
        return CreepSolver(mesh, material, Surroundings((0.0, -g, 0.0)), [ContactPlane((0, 0, 0), (0, 1, 0), 0.2)], punch,
                           CreepSettings(tolerance=1e-4))

    times = np.linspace(0.0, 1.0, 11)
    bottom = mesh.nodes_mm[:, 1] < 1e-9
    rng = np.random.default_rng(4)
    runs = []
    for travel in (0.5, 2.0):
        run = solver(travel * MM).run(times)
        # what a bigger mesh's snapshots carry on the floor: contacts that open and close, noise
        # of a micrometre in the floor's normal (far below its 1 % tolerance)
        nodes = run.nodes_mm.copy()
        nodes[1:, bottom, 1] += rng.uniform(0.0, 1e-3, (len(times) - 1, int(bottom.sum())))
        runs.append(dataclasses.replace(run, nodes_mm=nodes))
    basis = pod_basis(runs)
    full = solver(1.5 * MM)
    held = held_on_solids(basis, full, 1e-2 * full.dx_m)
    v = held.node_modes_m.reshape(len(mesh.nodes_mm), 3, -1)
    assert np.abs(basis.node_modes_m.reshape(v.shape)[bottom, 1]).max() > 1e-4   # the noise is in the modes
    assert np.abs(v[bottom, 1]).max() == 0.0                                     # and held out of them
    stacked = np.vstack([held.node_modes_m, held.advance_modes_m[None]])
    np.testing.assert_allclose(stacked.T @ stacked, np.eye(held.size), atol=1e-12)
    # the face's nodes: those the runs kept on it move along the axis exactly with the bar
    rel = basis.settled_nodes_mm * MM - (np.asarray(tip) + basis.advance_at_rest_mm * MM * axis)
    on_face = np.abs(rel @ axis) <= 1e-2 * full.dx_m
    if on_face.any():
        gap_modes = np.einsum("k,nkr->nr", axis, v[on_face]) - held.advance_modes_m[None]
        assert np.abs(gap_modes).max() < 1e-12
    # the snapshots are held as well as before: every frame's motion, projected on either basis
    for run in runs:
        x = np.hstack([(run.nodes_mm - run.nodes_mm[:1]).reshape(len(times), -1) * MM,
                       (run.advance_mm - run.advance_mm[0])[:, None] * MM]).T
        old = np.vstack([basis.node_modes_m, basis.advance_modes_m[None]])
        assert np.linalg.norm(x - stacked @ (stacked.T @ x)) <= np.linalg.norm(x - old @ (old.T @ x)) + 1e-3 * np.linalg.norm(x)
    reduced = ReducedCreep(full, basis, ReducedSettings(tolerance=1e-4))
    r = reduced.run(material, lambda t: 0.0, (), times, travel_m=lambda t: 1.5 * MM * t)
    x_mm = (r.nodes_mm[:, :, 0] - r.nodes_mm[:1, :, 0]).mean(1)
    rate = np.polyfit(r.advance_mm[3:], x_mm[3:], 1)[0]
    assert rate == pytest.approx(1.0 / math.sin(theta), rel=2e-3)


def test_the_bars_rows_bound_its_rounded_solids_distance_from_below_and_touch_it_where_taken():
    """The bar's rows, linearised at q̄, are tangent planes of a convex solid (a cylinder with a
    rounded rim), whose signed distance is a convex function of q (positions and the bar's
    advance are linear in q): the row's distance d(q̄) + G (q − q̄) equals the true distance at
    q̄ and lies below it everywhere else — so a row never lets a node into the bar."""
    from hifumotion.reduced.bar_rows import ReducedBarRows

    mesh = voxel_mesh(block(4), 1.0)
    axis = np.array([math.sin(0.6), -math.cos(0.6), 0.0])
    punch = Punch((2.5 * MM, 4.2 * MM, 2.0 * MM), tuple(axis), 1.5 * MM, lambda t: 0.0, 0.0, edge_radius_m=0.6 * MM)
    solver = CreepSolver(mesh, CreepMaterial(1e4, 0.3), Surroundings((0.0, 0.0, 0.0)),
                         [ContactPlane((0, 0, 0), (0, 1, 0), 0.0)], punch)
    rng = np.random.default_rng(11)
    n, r = len(mesh.nodes_mm), 5
    modes = rng.normal(scale=0.4 * MM, size=(n, 3, r))
    advance_modes = rng.normal(scale=0.4 * MM, size=r)
    surface = np.unique(mesh.surface_faces())
    bar = ReducedBarRows(solver.contacts, mesh.nodes_mm * MM, modes, advance_modes, 0.1 * MM, surface, 10 * MM)
    assert bar.size == len(surface)
    for _ in range(20):
        at, q = rng.normal(size=r), rng.normal(size=r)
        rows, bound, holds = bar.rows_at(at)
        d_at, _ = bar.distances_m(at)
        d_q, _ = bar.distances_m(q)
        assert holds.all()
        # where taken, the row is the distance; a node outside has its row's gap, rows q̄ − bound, there
        outside = d_at > 0
        np.testing.assert_allclose((rows @ at - bound)[outside], d_at[outside], rtol=0, atol=1e-15)
        linear = d_at + rows @ (q - at)
        assert np.all(linear <= d_q + 1e-12)
    # the nodes span the rim, the side and the face: every kind of tangent plane was tried
    _, normals = bar.distances_m(np.zeros(r))
    kinds = {"face": np.abs(normals @ axis) > 1 - 1e-9, "side": np.abs(normals @ axis) < 1e-9}
    assert all(k.any() for k in kinds.values()) and (~(kinds["face"] | kinds["side"])).any()


@pytest.mark.parametrize("kinematics", ["small_strain", "corotational"])
def test_a_tilted_bar_slides_a_reduced_ellipsoid_on_a_rough_floor_as_the_full_model_does(kinematics):
    """An ellipsoid driven along a rough floor (μ 0.15) by a bar tilted 35°: tissue beside the
    bar's rim comes under its face as it slides. The reduced model with friction (modes from
    drives of half and twice the travel) must slide it as the full implicit model of the same
    kinematics does, within 5 % of the slide, and keep every node out of the bar. (With the face
    a sharp disc whose row appeared under it, that tissue jumped the depth it was behind the face
    at any step size; the rate of that jump threw the sample 766 mm.)"""
    from hifumotion.reduced.model import ReducedSettings
    from hifumotion.creep.scene_run import scene_material, simulate_creep, tissue_mesh
    from hifumotion.reduced.build import reduced_creep
    from hifumotion.scene import Scene

    def scene(travel_mm):
        return Scene.model_validate({
            "tissue": {"shape": "ellipsoid", "size_mm": [24, 14, 20], "youngs_modulus_pa": 9e3, "poisson_ratio": 0.47,
                       "beta1": 1.5e5, "beta2": 0.5},
            "bar": {"radius_mm": 5.0, "control": "travel", "direction": [0.574, -0.819, 0.0],
                    "schedule_times_s": [0.0, 6.0], "schedule_travel_mm": [0.0, travel_mm]},
            "physics": {"friction": 0.15}, "particles": {"spacing_mm": 3.0},
            "run": {"duration_s": 6.0, "output_interval_s": 0.2, "write_vtu": False}})

    base = scene(4.0)
    mesh, vol = tissue_mesh(base)
    creep = CreepSettings(kinematics=kinematics)
    truth = simulate_creep(base, mesh=mesh, tissue_particles=(mesh.centres_mm, vol), settings=creep).tissue_mm
    slid = (truth[-1] - truth[0]).mean(0)
    assert slid[0] > 5.0          # mm: it slides, not only squashes
    model = reduced_creep([scene(2.0), scene(8.0)], mesh, vol, ReducedSettings(friction=True), creep=creep)
    assert (model.corotation is not None) == (kinematics == "corotational")
    travel = base.bar.travel_schedule()
    times = np.arange(31) * 0.2
    r = model.run(scene_material(base), lambda t: 0.0, (6.0,), times, travel_m=lambda t: float(travel(t)) * MM)
    reduced_slid = (r.particles_mm[-1] - r.particles_mm[0]).mean(0)
    assert np.linalg.norm(reduced_slid - slid) <= 0.05 * np.linalg.norm(slid)
    # the bar's advance from its tip: at rest on this material, then as the run reports it
    contacts = model._bar.contacts
    rest_mm = model.basis.advance_at_rest_mm + model.basis.advance_modes_m @ model.settle(
        model.loads(scene_material(base)), 0.0).q / MM
    deepest = min(contacts.bar_distance(r.nodes_mm[f] * MM, (rest_mm + r.advance_mm[f]) * MM)[0].min()
                  for f in range(len(times)))
    assert deepest >= -0.01 * base.particles.spacing_mm * MM      # penetration ≤ 1 % of the spacing


# -- corotational kinematics ------------------------------------------------------------------------

def _elastica_tip(alpha: float) -> tuple[float, float]:
    """The inextensible Euler–Bernoulli cantilever under its own weight (α = qL³/EI), solved here as
    its boundary-value problem θ'' = −α (1 − s) cos θ, θ(0) = 0, θ'(1) = 0: the tip's drop and the
    span's shortening, over L."""
    from scipy.integrate import solve_bvp

    s = np.linspace(0.0, 1.0, 201)
    sol = solve_bvp(lambda s, y: np.vstack([y[1], -alpha * (1 - s) * np.cos(y[0])]),
                    lambda a, b: np.array([a[0], b[1]]), s, np.zeros((2, len(s))), tol=1e-10, max_nodes=100_000)
    assert sol.success
    fine = np.linspace(0.0, 1.0, 20_001)
    theta = sol.sol(fine)[0]
    return float(np.trapezoid(np.sin(theta), fine)), float(1.0 - np.trapezoid(np.cos(theta), fine))


def test_a_rigid_turn_stresses_nothing_corotated_and_a_turned_strain_gives_the_turned_force():
    from scipy.spatial.transform import Rotation

    from hifumotion.creep.corotation import Corotation
    from hifumotion.creep.hexahedra import MeshMatrices

    mesh = voxel_mesh(block(4), 1.0)
    x = mesh.nodes_mm * MM
    e, nu = 5e3, 0.45
    lam, g = e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))
    matrices = MeshMatrices(x, mesh.elements, MM)
    corotation = Corotation(matrices, x, 2 * g, lam + 2 * g / 3)
    k = matrices.matrix(2 * g, lam + 2 * g / 3, 0.0)
    q = Rotation.from_rotvec([0.2, 0.5, -0.3]).as_matrix()     # 35°
    centre = x.mean(axis=0)
    turned = (x - centre) @ q.T + centre - x + np.array([1e-3, 2e-3, 0.0])
    small = np.abs(k @ turned.ravel()).max()
    assert small > 1e-3                                          # the small-strain model stresses a turn
    assert np.abs(corotation.forces(turned)).max() < 1e-12 * small
    assert np.allclose(corotation.rotations(turned), q, atol=1e-12)
    # a 1 % strain: the small-strain force, to the order of the strain; the same strain turned by
    # Q gives that force turned by Q
    strain = 1e-2 * MM * np.random.default_rng(0).standard_normal(x.shape)
    f_small = (k @ strain.ravel()).reshape(-1, 3)
    assert np.linalg.norm(corotation.forces(strain) - f_small) < 0.02 * np.linalg.norm(f_small)
    f_turned = corotation.forces((x - centre + strain) @ q.T + centre - x)
    assert np.linalg.norm(f_turned - f_small @ q.T) < 0.02 * np.linalg.norm(f_small)


def _cantilever_tip(alpha: float, kind: str, length=0.08, height=0.01, width=0.006, rho=1000.0, g=9.81):
    """The clamped beam of the test above made soft enough to bend to α = qL³/EI: its tip's mean
    motion over L (x along the span, y up) with ``kind`` kinematics."""
    q = rho * g * width * height
    e = q * length ** 3 / (alpha * width * height ** 3 / 12)
    dx = height / 5
    axes = [dx * (np.arange(round(s / dx)) + 0.5) for s in (length, height, width)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) / MM + np.array([0.0, 200.0, 0.0])
    mesh = voxel_mesh(pts, dx / MM)
    tip = mesh.nodes_mm[:, 0] > length / MM - 1e-6
    solver = CreepSolver(mesh, CreepMaterial(e, 0.0, beta1=0.0, density_kg_m3=rho), Surroundings((0, -g, 0)),
                         [ContactPlane((0, 0, 0), (1, 0, 0), bonded=True)], None, CreepSettings(kinematics=kind))
    r = solver.run(np.array([0.0, 0.1]))
    return (r.nodes_mm[-1][tip] - mesh.nodes_mm[tip]).mean(axis=0) * MM / length


@pytest.mark.parametrize("kind", ["corotational", "neo_hooke"])
def test_large_deformation_kinematics_and_small_strain_agree_at_one_percent_strain(kind):
    # α = 0.32: the root's bending strain qL²h/(4EI) is 1 %, the tip turned ~3°. The drop agrees to
    # 1 %; what differs is of second order, the span's shortening (2 % of the drop), which the
    # elastica has and the small-strain model cannot
    small, large = (_cantilever_tip(0.32, k) for k in ("small_strain", kind))
    drop, shortening = _elastica_tip(0.32)
    assert -small[1] == pytest.approx(0.32 / 8, rel=0.03)
    assert large[1] == pytest.approx(small[1], rel=0.01)
    assert np.abs(large - small).max() < 0.03 * np.abs(small).max()
    assert -large[0] == pytest.approx(shortening, rel=0.05)


def test_a_cantilever_bent_far_under_its_weight_follows_the_elastica_with_large_deformations_not_small_strain():
    # α = 4 (the tip turns ~40°, the strain stays ~10 %): the small-strain model drops the tip by the
    # linear α/8 and never shortens the span; the corotational and the neo-Hookean ones follow the
    # inextensible elastica, solved here
    alpha = 4.0
    drop, shortening = _elastica_tip(alpha)
    small = _cantilever_tip(alpha, "small_strain")
    for kind in ("corotational", "neo_hooke"):
        large = _cantilever_tip(alpha, kind)
        assert -large[1] == pytest.approx(drop, rel=0.03)
        assert -large[0] == pytest.approx(shortening, rel=0.03)
    assert -small[1] == pytest.approx(alpha / 8, rel=0.03)     # the linear theory's
    assert -small[1] > 1.15 * drop and abs(small[0]) < 1e-3 * shortening


def test_the_reduced_corotational_model_bends_a_cantilever_as_the_elastica_on_a_few_sampled_voxels():
    # modes of the corotational cantilever's deflections at α = 2, 3 and 5, from the unloaded beam;
    # the reduced model settles at α = 4 (the tip turned ~40°) in those modes: the elastica's drop and
    # shortening, solved here, on ECSW's sample of the voxels; the same modes small-strain give the
    # linear α/8 and no shortening
    from hifumotion.creep.integrate import CreepResult
    from hifumotion.reduced.model import ReducedCreep, pod_basis, step_counters
    from hifumotion.creep.settings import ReducedSettings

    length, height, width, rho, g = 0.08, 0.01, 0.006, 1000.0, 9.81
    dx = height / 5
    axes = [dx * (np.arange(round(s / dx)) + 0.5) for s in (length, height, width)]
    mesh = voxel_mesh(np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) / MM, dx / MM)
    tip = mesh.nodes_mm[:, 0] > length / MM - 1e-6

    def material(alpha):
        return CreepMaterial(rho * g * width * height * length ** 3 / (alpha * width * height ** 3 / 12), 0.0,
                             beta1=0.0, density_kg_m3=rho)

    def solver(alpha, kind):
        return CreepSolver(mesh, material(alpha), Surroundings((0, -g, 0)), [ContactPlane((0, 0, 0), (1, 0, 0), bonded=True)],
                           None, CreepSettings(kinematics=kind))

    runs = []
    for alpha in (2.0, 3.0, 5.0):
        bent = solver(alpha, "corotational").run(np.array([0.0, 0.1])).nodes_mm[-1]
        runs.append(CreepResult(np.array([0.0, 1.0]), np.stack([mesh.nodes_mm, bent]), np.zeros((2, 0, 3)),
                                np.zeros(2), np.zeros(2), {}))
    basis = pod_basis(runs)
    drop, shortening = _elastica_tip(4.0)
    tips = {}
    for kind in ("corotational", "small_strain"):
        model = ReducedCreep(solver(4.0, kind), basis, ReducedSettings())
        stats = step_counters(model)
        q = model.settle(model.loads(material(4.0)), 0.0, stats).q
        nodes = basis.settled_nodes_mm + (basis.node_modes_m @ q).reshape(-1, 3) / MM
        tips[kind] = (nodes[tip] - mesh.nodes_mm[tip]).mean(axis=0) * MM / length
        if kind == "corotational":
            assert 0 < stats["elastic_voxels"] < len(mesh.elements) / 10
            assert stats["rotation_rounds"] > 0
    assert -tips["corotational"][1] == pytest.approx(drop, rel=0.03)
    assert -tips["corotational"][0] == pytest.approx(shortening, rel=0.03)
    assert -tips["small_strain"][1] == pytest.approx(4.0 / 8, rel=0.03)
    assert abs(tips["small_strain"][0]) < 1e-2 * shortening


def test_the_reduced_corotational_force_on_every_voxel_is_the_full_force_projected():
    from scipy.spatial.transform import Rotation

    from hifumotion.creep.corotation import Corotation
    from hifumotion.reduced.corotated_force import ReducedCorotation

    mesh, x, matrices = _block_matrices()
    two_g, kappa = 3e3, 2e4
    rng = np.random.default_rng(3)
    turn = Rotation.from_rotvec([0.3, -0.4, 0.2]).as_matrix()
    shapes = [0.05 * MM * rng.standard_normal(x.shape), (x - x.mean(axis=0)) @ turn.T + x.mean(axis=0) - x]
    modes, _ = np.linalg.qr(np.column_stack([s.ravel() for s in shapes]))
    settled = 0.01 * MM * rng.standard_normal(x.size)
    reduced = ReducedCorotation(matrices, x, modes, settled, np.zeros((2, 0)), 0.0, 8)
    full = Corotation(matrices, x, two_g, kappa)
    q = modes.T @ (0.7 * shapes[0] + 0.9 * shapes[1]).ravel()
    at = reduced.at(q, two_g, kappa)
    expected = modes.T @ full.forces((settled + modes @ q).reshape(-1, 3)).ravel()
    assert np.allclose(at.force, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    k_r = full.linearised((settled + modes @ q).reshape(-1, 3))
    import scipy.sparse as sp

    asm = matrices.assembly
    k = sp.csr_matrix((k_r.stiffness_data, asm.indices, asm.indptr), shape=(asm.size, asm.size))
    assert np.allclose(at.matrix, modes.T @ (k @ modes), rtol=1e-10, atol=1e-12 * np.abs(at.matrix).max())
    # the viscosity turned with its voxels: the full model's rates read in each voxel's frame, and its
    # R C_e Rᵀ projected (every voxel rated and sampled, weight 1)
    from hifumotion.reduced.hyper import rate_modes, shear_rates
    from hifumotion.reduced.corotated_force import TurnedViscosity

    every = np.arange(len(mesh.elements))
    upper = np.triu_indices(modes.shape[1])
    rates = rate_modes(matrices, modes, every)
    blocks = np.zeros((len(every), len(upper[0])), np.float32)
    viscosity = TurnedViscosity(matrices, modes, settled, every, every, np.ones(len(every)), upper, rates, blocks)
    viscosity.update(q, 0.0)
    qdot = rng.standard_normal(modes.shape[1]) * 1e-4
    u = (settled + modes @ q).reshape(-1, 3)
    assert np.allclose(shear_rates(viscosity.rate_modes, qdot), full.rates((modes @ qdot).reshape(-1, 3), u),
                       rtol=1e-9, atol=1e-12)
    c = np.zeros((modes.shape[1],) * 2)
    c[upper] = blocks.astype(float).sum(axis=0)
    c.T[upper] = c[upper]
    state = full.linearised(u)
    c_full = sp.csr_matrix((full.viscous_data(np.ones(len(every)), state), asm.indices, asm.indptr),
                           shape=(asm.size, asm.size))
    assert np.allclose(c, modes.T @ (c_full @ modes), rtol=1e-5, atol=1e-5 * np.abs(c).max())
    # the friction's candidates' elastic force along their normals: the full force at their nodes (a
    # node twice, against two solids)
    from hifumotion.reduced.corotated_force import CandidateForces

    nodes = np.array([0, 3, 7, 7, 12])
    normals = np.array([[0, 1, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, -1, 0]], float)
    touching = np.flatnonzero(np.isin(mesh.elements, nodes).any(axis=1))
    candidates = CandidateForces(matrices, x, modes, settled, touching, nodes, normals)
    expected = np.einsum("ck,ck->c", normals, full.forces(u)[nodes])
    assert np.allclose(candidates.normal_n(q, two_g, kappa), expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())


def _block_matrices(n=4):
    from hifumotion.creep.hexahedra import MeshMatrices

    mesh = voxel_mesh(block(n), 1.0)
    x = mesh.nodes_mm * MM
    return mesh, x, MeshMatrices(x, mesh.elements, MM)


def test_the_neo_hookean_force_is_its_energys_gradient_its_tangent_the_small_strain_stiffness_at_rest():
    import scipy.sparse as sp
    from scipy.spatial.transform import Rotation

    from hifumotion.creep.neo_hooke import NeoHooke

    mesh, x, matrices = _block_matrices()
    e, nu = 5e3, 0.45
    lam, g = e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))
    law = NeoHooke(matrices, x, g, lam + 2 * g / 3)
    k = matrices.matrix(2 * g, lam + 2 * g / 3, 0.0)
    rest = law.linearised(np.zeros_like(x))
    assert np.abs(rest.stiffness_data - k.data).max() < 1e-12 * np.abs(k.data).max()
    assert np.abs(rest.forces).max() == 0.0
    rng = np.random.default_rng(1)
    u = 0.05 * MM * rng.standard_normal(x.shape)            # ~5 % random strain
    at = law.linearised(u, project=False)                   # the exact tangent, not the projected one
    h = 1e-9
    for node, axis in ((5, 0), (17, 2), (40, 1)):
        step = np.zeros_like(u)
        step[node, axis] = h
        assert (law.energy(u + step) - law.energy(u - step)) / (2 * h) == pytest.approx(at.forces[node, axis],
                                                                                           rel=1e-6)
    tangent = sp.csr_matrix((at.stiffness_data, matrices.assembly.indices, matrices.assembly.indptr), shape=k.shape)
    d = 1e-6 * MM * rng.standard_normal(x.shape)
    difference = (law.forces(u + d) - law.forces(u - d)).ravel() / 2
    assert np.linalg.norm(difference - tangent @ d.ravel()) < 1e-6 * np.linalg.norm(difference)
    # projected: positive semi-definite, and the same forces
    projected = law.linearised(u)
    assert np.array_equal(projected.forces, at.forces)
    dense = sp.csr_matrix((projected.stiffness_data, matrices.assembly.indices, matrices.assembly.indptr),
                          shape=k.shape).toarray()
    assert np.linalg.eigvalsh(dense).min() > -1e-9 * np.abs(dense).max()
    q = Rotation.from_rotvec([0.2, 0.5, -0.3]).as_matrix()
    centre = x.mean(axis=0)
    turned = (x - centre) @ q.T + centre - x
    assert np.abs(law.forces(turned)).max() < 1e-12 * np.abs(k @ turned.ravel()).max()


def _neo_hookean_uniaxial_stretches(n, e, nu, force):
    """A frictionless floor and punch: a homogeneous uniaxial state whose nominal stress is F/A₀
    along the axis and nothing across it, solved here from W's stress: (axial, lateral)."""
    from scipy.optimize import fsolve

    mu, kappa = e / (2 * (1 + nu)), e / (3 * (1 - 2 * nu))

    def stresses(stretch):
        axial, lateral = stretch
        j, i1 = axial * lateral ** 2, axial ** 2 + 2 * lateral ** 2
        c = mu * j ** (-2 / 3)
        return [c * (axial - i1 / (3 * axial)) + kappa * (j - 1) * j / axial + force / (n * MM) ** 2,
                c * (lateral - i1 / (3 * lateral)) + kappa * (j - 1) * j / lateral]

    return fsolve(stresses, [0.8, 1.05], xtol=1e-14)


def test_a_block_pressed_by_a_quarter_takes_the_neo_hookean_stretches():
    # the analytic uniaxial state (_neo_hookean_uniaxial_stretches); the linear model's 30 % is not it
    n, e, nu, force = 5, 8e3, 0.3, 0.06
    axial, lateral = _neo_hookean_uniaxial_stretches(n, e, nu, force)
    assert 0.75 < axial < 0.8
    mesh, r = pressed_block(n, e, nu, force, settings=CreepSettings(kinematics="neo_hooke"))
    assert r.advance_mm[-1] == pytest.approx((1 - axial) * n, rel=1e-4)
    x, rest = r.nodes_mm[-1], mesh.nodes_mm
    # across, by the distance between opposite edges (the block is free to turn about the axis)
    left = np.flatnonzero((rest[:, 0] < 1e-9) & (rest[:, 2] < 1e-9))
    right = np.flatnonzero((rest[:, 0] > n - 1e-9) & (rest[:, 2] < 1e-9))
    left, right = left[np.argsort(rest[left, 1])], right[np.argsort(rest[right, 1])]
    assert np.linalg.norm(x[right] - x[left], axis=1) / n == pytest.approx(lateral, rel=1e-4)
    _, linear = pressed_block(n, e, nu, force)
    assert linear.advance_mm[-1] > 1.3 * r.advance_mm[-1]


def test_the_reduced_model_refuses_a_neo_hookean_solver_by_name():
    from hifumotion.reduced.model import ReducedCreep

    solver = CreepSolver(voxel_mesh(block(3), 1.0), CreepMaterial(5e3, 0.45), Surroundings((0, -9.81, 0)),
                         [ContactPlane((0, 0, 0), (0, 1, 0))], None, CreepSettings(kinematics="neo_hooke"))
    with pytest.raises(InputError, match="kinematics"):
        ReducedCreep(solver, None)


def test_another_pardiso_call_in_the_process_leaves_a_pressed_blocks_contacts_as_they_are():
    """A PARDISO solve through pypardiso's own wrapper (as the finite-element references make)
    moves the fast path's single-precision factor's solutions in their 7th digit; the pressed
    neo-Hookean block must still reach its analytic stretch — no contact released by a pull
    smaller than the round's solve resolves."""
    import pypardiso
    import scipy.sparse as sp

    a = sp.random(50, 50, density=0.2, random_state=0)
    a = (a + a.T) + 10 * sp.eye(50)
    pypardiso.PyPardisoSolver(mtype=2).solve(sp.triu(a).tocsr(), np.ones(50))
    n, e, nu, force = 5, 8e3, 0.3, 0.06
    axial, _ = _neo_hookean_uniaxial_stretches(n, e, nu, force)
    _, r = pressed_block(n, e, nu, force, settings=CreepSettings(kinematics="neo_hooke", precision="mixed"))
    assert r.advance_mm[-1] == pytest.approx((1 - axial) * n, rel=1e-4)
