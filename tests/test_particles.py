"""The particle framework against independent truths: kernel integrals, brute-force
neighbours, exact MLS gradients, rigid-motion invariance, analytic pressure fields,
conservation laws and the validation cases' analytic references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hifumotion.particles import (CouplingParameters, SimulationDiverged, Solver, SolverSettings,
                                  TissueParameters, build_system, lattice)
from hifumotion.particles.elastic import rest_neighbourhoods
from hifumotion.particles.kernels import (kernel, kernel_derivative, kernel_gradient,
                                          viscosity_kernel_laplacian)
from hifumotion.particles.neighbours import CellGrid


# -- kernels -----------------------------------------------------------------
def test_cubic_kernel_integrates_to_one_and_vanishes_beyond_support():
    h = 1.0
    dx = 0.02
    axis = np.arange(-h, h + dx / 2, dx)
    g = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    total = kernel(np.linalg.norm(g, axis=1), h).sum() * dx ** 3
    assert total == pytest.approx(1.0, abs=2e-3)
    assert np.all(kernel(np.array([1.0, 1.5, 3.0]), h) == 0)
    assert np.all(viscosity_kernel_laplacian(np.array([1.0, 2.0]), h) == 0)
    assert np.all(viscosity_kernel_laplacian(np.linspace(0, 0.99, 20), h) > 0)


def test_kernel_gradient_matches_finite_differences():
    h = 0.004
    r = np.linspace(0.0001, 0.0039, 40)
    eps = 1e-9
    fd = (kernel(r + eps, h) - kernel(r - eps, h)) / (2 * eps)
    assert np.allclose(kernel_derivative(r, h), fd, rtol=1e-5, atol=1e-3 * np.abs(fd).max())
    v = np.array([[0.001, -0.002, 0.0005]])
    grad = kernel_gradient(v, h)[0]
    assert np.allclose(grad / np.linalg.norm(grad), -v[0] / np.linalg.norm(v[0]))  # points inwards (dW/dr < 0)


# -- neighbours ----------------------------------------------------------------
def test_cell_list_finds_exactly_the_brute_force_neighbours_and_grows_its_table():
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 0.02, (1500, 3))
    h = 0.002
    grid = CellGrid(x.min(0), x.max(0), h, width=4)  # too narrow on purpose: must grow
    table = grid.query(x, 100, 900)
    tree = cKDTree(x)
    for row, i in enumerate(range(100, 900)):
        found = set(table.indices[row, : table.counts[row]].tolist())
        expected = set(tree.query_ball_point(x[i], h * (1 - 1e-12))) - {i}
        assert found == expected
    assert grid.width > 4


# -- elastic -------------------------------------------------------------------
def _slab(n=(10, 5, 4), dx=0.002):
    return lattice([0, 0, 0], [n[0] * dx, n[1] * dx, n[2] * dx], dx), dx


def _gradients(rest, pts_now, order, near=None):
    r = rest_neighbourhoods(rest, 2.5 * 0.002, 1e-4, order, near_m=near)
    i = np.repeat(np.arange(len(rest)), np.diff(r.start))
    u = pts_now - rest
    g = np.zeros((len(rest), 3, 3))
    np.add.at(g, i, (u[r.neighbours] - u[i])[:, :, None] * r.gradient[:, None, :])
    return g


def test_linear_mls_is_exact_for_affine_fields_everywhere():
    rest, _ = _slab()
    a = np.array([[0.01, 0.02, -0.01], [0.0, -0.03, 0.005], [0.02, 0.0, 0.01]])
    g = _gradients(rest, rest + rest @ a.T, order=1)
    assert np.allclose(g, a, atol=1e-10)


@pytest.mark.parametrize("near", [None, 0.004])
def test_quadratic_mls_is_exact_for_bending_even_at_the_surface(near):
    rest, _ = _slab((12, 7, 7))
    y0 = rest[:, 1].mean()
    kappa = 2.0
    u = np.stack([-kappa * rest[:, 0] * (rest[:, 1] - y0), 0.5 * kappa * rest[:, 0] ** 2, 0 * rest[:, 0]], 1)
    g = _gradients(rest, rest + u, order=2, near=near)  # near: linear fits inside, fewer pairs
    assert np.allclose(g[:, 0, 0], -kappa * (rest[:, 1] - y0), atol=1e-9)
    assert np.allclose(g[:, 0, 1] + g[:, 1, 0], 0.0, atol=1e-9)  # no spurious shear
    linear = _gradients(rest, rest + u, order=1)
    surface = np.isclose(rest[:, 1], rest[:, 1].max())
    assert np.abs(linear[surface, 0, 0] + kappa * (rest[surface, 1] - y0)).max() > 1e-4  # the flaw it fixes


@pytest.mark.parametrize("corotated", [False, True])
def test_rigid_rotation_gives_no_elastic_force(corotated):
    rest, dx = _slab((6, 5, 4))
    system = build_system(spacing_m=dx, tissue_positions_m=rest, gravity_m_s2=(0, 0, 0),
                          tissue=TissueParameters(corotated=corotated, beta1=0.0))
    angle = 0.7
    rot = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
    system.x[:] = (rest - rest.mean(0)) @ rot.T + rest.mean(0) + 0.01
    force = Solver(system).compute_forces()
    scale = system.tissue.youngs_modulus_pa * dx ** 2
    assert np.abs(force).max() < 1e-9 * scale
    stretched = build_system(spacing_m=dx, tissue_positions_m=rest, gravity_m_s2=(0, 0, 0),
                             tissue=TissueParameters(corotated=corotated, beta1=0.0))
    stretched.x[:, 0] *= 1.01
    assert np.abs(Solver(stretched).compute_forces()).max() > 1e-4 * scale  # and a stretch does push


def test_elastic_and_coupling_forces_sum_to_zero():
    rng = np.random.default_rng(3)
    rest, dx = _slab((6, 6, 6))
    water = lattice([-0.004, -0.004, -0.004], [0.016, 0.016, 0.016], dx) + dx / 2
    water = water[cKDTree(rest).query(water)[0] > 0.9 * dx]
    system = build_system(spacing_m=dx, fluid_positions_m=water, tissue_positions_m=rest,
                          gravity_m_s2=(0, 0, 0), coupling=CouplingParameters(fluid_coefficient=None),
                          tissue=TissueParameters(volume_stiffness_pa=2e4, beta1=1.0), water_depth_m=0.02)
    n = system.n_moving
    system.x[:n] += rng.normal(0, 2e-4, (n, 3))
    system.v[:n] = rng.normal(0, 0.05, (n, 3))
    force = Solver(system).compute_forces()
    assert np.abs(force.sum(0)).max() < 1e-12 * np.abs(force).sum()


# -- fluid -----------------------------------------------------------------------
def test_pressure_force_of_a_linear_pressure_field_is_its_gradient():
    from hifumotion.particles import fluid

    dx = 0.002
    x = lattice([0, 0, 0], [0.02, 0.02, 0.02], dx)
    system = build_system(spacing_m=dx, fluid_positions_m=x, gravity_m_s2=(0, 0, 0))
    table = CellGrid(x.min(0), x.max(0), system.support_m).query(system.x, 0, len(x))
    gradient = 9800.0
    pressure = gradient * (0.02 - x[:, 1])
    force = np.zeros_like(x)
    fluid.pair_forces(system.x, system.v, system.mass, system.rest_volume.copy(), system.phase, pressure,
                      0, table.indices, table.counts, system.support_m, dx, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-4, 1.0,
                      force)
    inner = np.all((x > 0.006) & (x < 0.014), axis=1)
    per_volume = force[inner] / dx ** 3
    assert np.allclose(per_volume[:, 1] / gradient, 1.0, atol=0.03)  # −∇p points up
    assert np.abs(per_volume[:, [0, 2]]).max() < 1e-9 * gradient


# -- solver ----------------------------------------------------------------------
def test_blow_up_is_reported_with_step_particles_and_limit():
    rest, dx = _slab((5, 5, 5))
    system = build_system(spacing_m=dx, tissue_positions_m=rest, gravity_m_s2=(0, 0, 0),
                          tissue=TissueParameters(youngs_modulus_pa=1e6, beta1=0.0))
    system.x[10] += 0.3 * dx
    solver = Solver(system, SolverSettings(cfl=1.0))
    solver.settings = SolverSettings(cfl=1.0)
    solver.dt = 50 * solver.dt  # far beyond the stability limit
    with pytest.raises(SimulationDiverged, match=r"step \d+ .*particle"):
        for _ in range(200):
            solver.dt = max(solver.dt, 1e-4)
            solver.step()


# -- validation cases (analytic references) ------------------------------------
def test_validation_poisson_ratio():
    from hifumotion.particles.validation import run_case

    r = run_case("poisson")
    assert r.passed, r
    assert r.details["youngs_modulus_from_force_pa"] == pytest.approx(1e5, rel=0.05)


def test_validation_free_rotation_keeps_angular_momentum():
    from hifumotion.particles.validation import run_case

    r = run_case("rotation")
    assert r.passed and r.rel_error < 1e-6
    assert r.details["relative_energy_drift"] < 1e-3
    assert r.details["turns"] > 0.1


def test_validation_momentum_conserved_and_impulse_balanced():
    from hifumotion.particles.validation import run_case

    r = run_case("momentum")
    assert r.passed, r
    assert r.measured > 0  # the bar's force did change the momentum


def test_validation_hydrostatic_pressure():
    from hifumotion.particles.validation import run_case

    r = run_case("hydrostatic")
    assert r.passed, r.details


# -- sections, scenes, output, command line -------------------------------------------
def test_section_of_a_particle_sphere_is_a_disc_of_its_radius():
    from hifumotion.scene import Plane
    from hifumotion.particles.section import section

    dx = 1.0
    pts = lattice([-10, -10, -10], [10, 10, 10], dx)
    pts = pts[np.linalg.norm(pts, axis=1) <= 8.0]
    radius = (3 * len(pts) * dx ** 3 / (4 * math.pi)) ** (1 / 3)  # sphere of the same volume
    plane = Plane(origin_mm=(-15.0, -15.0, 0.0), u=(1.0, 0.0, 0.0), v=(0.0, 1.0, 0.0),
                  shape=(150, 150), pixel_mm=0.2)
    sec = section(pts + np.array([0, 0, 0.5]), np.full(len(pts), dx ** 3), dx, plane)
    assert sec.area_mm2 == pytest.approx(math.pi * radius ** 2, rel=0.05)
    centre = sec.contour_mm.mean(0) - 15.0
    assert np.abs(centre).max() < 0.1
    empty = section(pts + 100.0, np.full(len(pts), 1.0), dx, plane)
    assert not empty.mask.any() and len(empty.contour_px) == 0


def _tiny_scene():
    from hifumotion.scene import Scene

    scene = Scene()
    scene.particles.spacing_mm = 2.5
    scene.tank.size_mm = (40.0, 25.0, 30.0)
    scene.tank.water_depth_mm = 14.0
    scene.tissue.size_mm = (16.0, 10.0, 14.0)
    scene.bar.radius_mm = 3.0
    scene.bar.length_mm = 8.0
    scene.bar.force_n = 0.004
    scene.bar.ramp_s = 0.02
    scene.run.duration_s = 0.06
    scene.run.output_interval_s = 0.03
    scene.run.settle_s = 0.02
    return scene


def test_simulated_push_moves_the_bar_along_its_axis_and_writes_paraview_files(tmp_path):
    import meshio

    from hifumotion.particles.simulate import simulate

    result = simulate(_tiny_scene(), tmp_path)
    assert len(result.times_s) == 3 and result.times_s[-1] == pytest.approx(0.06)
    bar = result.bar_centre_mm
    assert bar[-1, 1] < bar[0, 1] - 0.01  # pushed down
    assert np.abs(bar[:, [0, 2]] - bar[0, [0, 2]]).max() < 1e-9  # and only along its axis
    frame = meshio.read(tmp_path / "frames" / "frame_0002.vtu")
    assert {"type", "velocity_mm_s", "pressure_pa", "strain", "displacement_mm"} <= set(frame.point_data)
    assert len(frame.points) == result.system.n_moving
    pvd = (tmp_path / "frames.pvd").read_text()
    assert pvd.count("<DataSet") == 3 and "frame_0002.vtu" in pvd
    rows = (tmp_path / "bar_pose.csv").read_text().strip().splitlines()
    assert len(rows) == 4 and rows[0].startswith("frame,time_s,body")
    # the water stays in the tank and the tissue stays on the floor
    x = result.system.x[: result.system.n_moving] * 1000
    assert x[:, 1].min() > -1.0
    tissue_bottom = result.tissue_mm[-1][:, 1].min()
    assert -1.25 < tissue_bottom < 2.5  # above the floor's wall particles (at −Δx/2), resting on them


def test_scene_file_errors_name_the_field(tmp_path):
    from hifumotion.errors import InputError
    from hifumotion.scene import load_scene

    bad = tmp_path / "scene.toml"
    bad.write_text("[tissue]\npoisson_ratio = 0.7\n")
    with pytest.raises(InputError, match="tissue.poisson_ratio"):
        load_scene(bad)
    bad.write_text('[tissue]\nshape = "particles"\nparticles_csv = "nope.csv"\n')
    from hifumotion.particles.scene_system import build_scene

    with pytest.raises(InputError, match="nope.csv"):
        build_scene(load_scene(bad))


def test_command_line_simulate_and_validate(tmp_path):
    import json
    import subprocess
    import sys

    def run(*args):
        return subprocess.run([sys.executable, "-m", "hifumotion", *args], capture_output=True, text=True,
                              timeout=300, cwd=tmp_path)

    printed = run("simulate", "--print-scene")
    assert printed.returncode == 0 and "youngs_modulus_pa = 13000.0" in printed.stdout
    scene = tmp_path / "scene.toml"
    text = printed.stdout
    for key, value in [("spacing_mm = 1.5", "spacing_mm = 2.5"), ("duration_s = 1.0", "duration_s = 0.03"),
                       ("settle_s = 0.2", "settle_s = 0.01"), ("size_mm = [50.0, 40.0, 40.0]", "size_mm = [40.0, 25.0, 30.0]"),
                       ("size_mm = [30.0, 18.0, 24.0]", "size_mm = [16.0, 10.0, 14.0]"), ("radius_mm = 6.0", "radius_mm = 3.0"),
                       ("water_depth_mm = 24.0", "water_depth_mm = 10.0"), ("output_interval_s = 0.05", "output_interval_s = 0.03")]:
        assert key in text
        text = text.replace(key, value)
    scene.write_text(text)
    done = run("-q", "simulate", str(scene), "-o", "out")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out" / "frames.pvd").exists() and (tmp_path / "out" / "run_info.json").exists()
    again = run("simulate", str(scene), "-o", "out")
    assert again.returncode == 2 and "--overwrite" in again.stderr
    # the fast path through the same table of forward models: its own frames, named on the console
    coarse = tmp_path / "coarse.toml"
    coarse.write_text(printed.stdout.replace("spacing_mm = 1.5", "spacing_mm = 2.5").replace("duration_s = 1.0", "duration_s = 0.1"))
    fast = run("simulate", str(coarse), "--integrator", "implicit", "-o", "fast")
    assert fast.returncode == 0, fast.stderr
    assert (tmp_path / "fast" / "creep.pvd").exists() and "creep.pvd" in " ".join((fast.stdout + fast.stderr).split())
    checked = run("validate", "rotation", "--json")
    assert checked.returncode == 0
    result = json.loads(checked.stdout)
    assert result["passed"] and {"parameters", "measured", "reference", "rel_error"} <= set(result)
    wrong = run("validate", "nonsense")
    assert wrong.returncode == 2 and "choose from" in wrong.stderr


def test_scene_tissue_from_reconstructed_particles_rests_on_the_floor(tmp_path):
    from hifumotion.scene import Scene
    from hifumotion.particles.scene_system import build_scene

    pts = lattice([-6, -4, -5], [6, 4, 5], 2.0)
    pts = pts[(((pts) / [6, 4, 5]) ** 2).sum(1) <= 1] + [100.0, 50.0, -20.0]  # any frame the user had
    rows = "\n".join(f"{x},{y},{z},7.5,0" for x, y, z in pts)
    csv = tmp_path / "particles.csv"
    csv.write_text("x_mm,y_mm,z_mm,volume_mm3,surface\n" + rows + "\n")
    scene = Scene()
    scene.tissue.particles_csv = csv
    scene.tissue.shape = "particles"
    scene.particles.spacing_mm = 2.0
    scene.tank.water_depth_mm = 0.0
    system, facts = build_scene(scene)
    assert facts["counts"]["tissue"] == len(pts)
    assert facts["tissue_volume_mm3"] == pytest.approx(7.5 * len(pts))
    tissue = system.x[system.tissue_slice] * 1000
    assert tissue[:, 1].min() == pytest.approx(1.0)  # half a spacing above the floor
    size = scene.tank.size_mm
    assert np.allclose(tissue[:, [0, 2]].mean(0), [size[0] / 2, size[2] / 2], atol=1.0)  # centred in the tank


def test_validation_buoyancy_light_floats_at_archimedes_draft_dense_sinks():
    from hifumotion.particles.validation import run_case

    r = run_case("buoyancy")
    assert r.passed, r.details
    assert r.details["draft_error_in_spacings"] < 1.0
    assert r.details["dense_bottom_above_floor_m"] < r.parameters["spacing_m"]


def test_validation_plate_period():
    from hifumotion.particles.validation import run_case

    r = run_case("plate")
    assert r.passed, r  # within 10 % of the thin-plate period
    assert len(r.details["zero_crossings_s"]) >= 2


def test_validation_cantilever_deflection_is_measured_against_beam_theory():
    """Measured: 11–14 % more deflection than Euler–Bernoulli at 5 particles through the
    thickness, shrinking with resolution (8.8 % at 8); the 5 % target needs ≈ 12 particles
    through the thickness (docs/decisions.md). The test pins the measured band so a
    regression — or an improvement that should update the documentation — shows."""
    from hifumotion.particles.validation import run_case

    r = run_case("cantilever")
    assert r.measured > r.reference  # a particle beam is softer, never stiffer, here
    assert r.rel_error < 0.18, r
    history = r.details["deflection_history_m"]
    assert abs(history[-1] - history[-2]) < 1e-3 * history[-1]  # relaxed to equilibrium


def test_validation_hertz_contact_is_measured():
    """Measured: the contact force Hertz gives for the measured indentation is ~30 % below
    the applied one at R = 6 spacings (contact radius ≈ 1.5 spacings); the 10 % target needs
    R ≳ 20 spacings. Pinned as a band, like the cantilever."""
    from hifumotion.particles.validation import run_case

    r = run_case("hertz")
    assert 0.3 * r.parameters["radius_m"] * 0.08 < r.details["indentation_m"] < 1.2 * 0.08 * r.parameters["radius_m"]
    assert r.rel_error < 0.45, r


@pytest.mark.parametrize("how, message", [("nan", r"\[17\].*not a number"),
                                          ("away", r"\[17,.*left the domain")])
def test_nan_or_escaped_particle_stops_the_run_naming_it(how, message):
    rest, dx = _slab((5, 5, 5))
    system = build_system(spacing_m=dx, tissue_positions_m=rest, gravity_m_s2=(0, 0, 0),
                          tissue=TissueParameters(beta1=0.0))
    solver = Solver(system)
    system.v[17] = (np.nan, 0.0, 0.0) if how == "nan" else (1.0, 0.0, 0.0)
    if how == "away":
        system.x[17] += 1.0  # a metre outside the box (its neighbours are flung out too)
    with pytest.raises(SimulationDiverged, match=rf"step 1 .*particle\(s\) {message}"):
        solver.step()


def test_mass_scaling_leaves_the_resting_state_unchanged():
    """Inertia ×25, weight unchanged: a block sagging on its clamped base must come to
    the same equilibrium (gravity and elasticity only), with a 5× longer step."""
    rest, dx = _slab((6, 6, 6))
    base = rest[:, 1] < dx
    finals, steps = [], []
    for scale in (1.0, 25.0):
        system = build_system(spacing_m=dx, tissue_positions_m=rest, tissue_fixed=base,
                              tissue=TissueParameters(youngs_modulus_pa=2e3, beta1=0.0))
        c = system.tissue.p_wave_speed(1050.0)
        omega = 2 * math.pi * c / (4 * 6 * dx)
        solver = Solver(system, SolverSettings(mass_scaling=scale, damping_per_s=omega / math.sqrt(scale),
                                               max_step_s=1.0))
        steps.append(solver.dt)
        solver.run(25 * math.sqrt(scale) / omega)
        finals.append(system.x.copy())
    sag = np.abs(finals[0] - rest).max()
    assert sag > 1e-5  # it did sag
    assert np.abs(finals[1] - finals[0]).max() < 1e-3 * sag + 1e-9
    assert steps[1] / steps[0] == pytest.approx(5.0, rel=0.02)


def test_mapped_section_follows_an_affine_motion_exactly():
    # a particle ball of radius 6 mm, stretched 10 % along x, squeezed 5 % along y and
    # shifted: its section through the centre is the analytic ellipse (a Shepard average
    # of an affine field is that field)
    from hifumotion.metrics import dice
    from hifumotion.scene import Plane
    from hifumotion.particles.section import mapped_section

    dx, radius = 0.8, 6.0
    rest = lattice([-8, -8, -8], [8, 8, 8], dx)
    rest = rest[np.linalg.norm(rest, axis=1) <= radius + dx]          # covers the ball
    a = np.diag([1.10, 0.95, 1.0])
    shift = np.array([1.3, -0.7, 0.0])
    moved = rest @ a.T + shift
    plane = Plane((-10.0, -10.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (200, 200), 0.1)
    sec = mapped_section(moved, rest, dx, plane, lambda p: np.linalg.norm(p, axis=1) <= radius)
    q = plane.points_mm()
    expected = (((q[..., 0] - shift[0]) / 1.10) ** 2 + ((q[..., 1] - shift[1]) / 0.95) ** 2) <= radius ** 2
    assert dice(sec.mask, expected) > 0.995
    assert sec.area_mm2 == pytest.approx(math.pi * radius ** 2 * 1.10 * 0.95, rel=0.01)
