"""Parameter estimation and prediction: the objective, the estimators, the predicted sections, the CLI."""

import io
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import disc
from hifumotion.errors import InputError
from hifumotion.estimation.evaluator import Evaluator
from hifumotion.estimation.fit import degeneracy, least_squares_fit, uncertainty
from hifumotion.estimation.iterative import iterative_estimate
from hifumotion.estimation.model import Parameters
from hifumotion.estimation.objective import TrainingData, frame_sums_mm, residuals_mm
from hifumotion.estimation.protocol import default_frames, parse_frames
from hifumotion.estimation.space import SearchSpace
from hifumotion.scene import Plane
from hifumotion.particles.section import displacement_at, material_displacement, plane_displacement
from hifumotion.prediction.physics import ReferenceShape, predicted_mask

PLANE = Plane((0.0, 0.0, 5.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (120, 140), 0.2)


def test_paper_protocol_frames():
    # Section 3.2: ground truth every 10th step from the 20th; 1st–9th train, 10th–18th validate
    train, valid = default_frames(200)
    assert train == list(range(20, 101, 10))
    assert valid == list(range(110, 191, 10))
    train, valid = default_frames(40)
    assert train == list(range(4, 21, 2)) and valid == list(range(22, 39, 2))
    assert parse_frames("20:101:10", 200, "x") == train_200() and parse_frames("5,3", 10, "x") == [3, 5]
    with pytest.raises(InputError, match="--training"):
        parse_frames("0,300", 200, "--training")
    with pytest.raises(InputError):
        default_frames(10)


def train_200():
    return list(range(20, 101, 10))


def test_residual_is_the_signed_distance_to_the_observed_contour():
    # a disc of radius 30 px; model points on circles of 30 + d px: residual −d px (outside), in mm
    cx, cy, r = 70.0, 60.0, 30.0
    masks = np.stack([disc(PLANE.shape, cx, cy, r)] * 3)
    data = TrainingData.from_masks(masks, [1, 2], PLANE)
    angles = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    points = np.zeros((3, 32, 3))
    for f, d in ((1, 4.0), (2, -6.0)):
        rad = r + d
        points[f, :, 0] = (cx + rad * np.cos(angles)) * PLANE.pixel_mm
        points[f, :, 1] = (cy + rad * np.sin(angles)) * PLANE.pixel_mm
        points[f, :, 2] = 5.0
    res = residuals_mm(points, data)
    assert res.shape == (2, 32)
    assert np.allclose(res[0], -4.0 * 0.2, atol=0.1)   # outside by 4 px
    assert np.allclose(res[1], 6.0 * 0.2, atol=0.1)    # inside by 6 px
    assert np.allclose(frame_sums_mm(res), [32 * 0.8, 32 * 1.2], rtol=0.08)
    with pytest.raises(InputError, match="training frames"):
        TrainingData.from_masks(masks, [5], PLANE)


def test_displacement_is_exact_for_an_affine_motion():
    g = np.stack(np.meshgrid(*[np.arange(0, 10.0, 1.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    a = np.array([[0.02, 0.01, 0.0], [-0.01, 0.03, 0.0], [0.0, 0.0, -0.02]])
    moved = g + g @ a.T + np.array([0.3, -0.2, 0.1])
    q = np.array([[4.3, 5.1, 4.9], [2.5, 3.5, 6.2]])
    u, covered = displacement_at(q, moved, g, 1.0)
    assert covered.all()
    # Shepard weights reproduce constants exactly; a linear field to the weights' centring error
    expected = q @ a.T + np.array([0.3, -0.2, 0.1])
    assert np.allclose(u, expected, atol=0.02)


def test_material_points_follow_an_affine_motion_exactly_at_a_surface():
    """Linear moving least squares: exact for an affine motion, also at a corner of the cloud
    where the neighbours lie on one side (Shepard's weights are off there by their centring)."""
    g = np.stack(np.meshgrid(*[np.arange(0, 10.0, 1.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    a = np.array([[0.02, 0.01, 0.0], [-0.01, 0.03, 0.05], [0.0, 0.0, -0.02]])
    shift = np.array([0.3, -0.2, 0.1])
    moved = g + g @ a.T + shift
    q = np.array([[4.3, 5.1, 4.9], [0.2, 9.0, 4.4], [9.0, 9.0, 9.0], [0.0, 0.3, 0.0]])
    u, covered = material_displacement(q, moved, g, 1.0)
    assert covered.all()
    np.testing.assert_allclose(u, q @ a.T + shift, atol=1e-9)
    frames = np.stack([g, moved, g + 2.0 * (moved - g)])          # (F, N, 3) at once
    uf, _ = material_displacement(q, frames, g, 1.0)
    np.testing.assert_allclose(uf[2], 2.0 * (q @ a.T + shift), atol=1e-9)
    far, covered_far = material_displacement(np.array([[30.0, 0.0, 0.0]]), moved, g, 1.0)
    assert not covered_far[0] and np.all(far == 0.0)


def test_material_points_under_an_indent_deeper_than_the_support_follow_it():
    """A top surface pushed 3 mm down by a smooth dent (3 spacings, beyond the 2-spacing support):
    the points on it follow the dent's known displacement, not the material now near where
    they were."""
    g = np.stack(np.meshgrid(np.arange(0, 21.0), np.arange(0, 11.0), np.arange(0, 11.0), indexing="ij"),
                 -1).reshape(-1, 3)

    def dent(x):   # mm: down by 3 at the top centre, fading with depth and across (σ 5 mm)
        r2 = (x[:, 0] - 10.0) ** 2 + (x[:, 2] - 5.0) ** 2
        return np.stack([0 * r2, -3.0 * np.exp(-r2 / 50.0) * (x[:, 1] / 10.0) ** 2, 0 * r2], 1)

    moved = g + dent(g)
    top = np.stack([np.linspace(6.0, 14.0, 9), np.full(9, 10.0), np.full(9, 5.0)], 1)
    u, covered = material_displacement(top, moved, g, 1.0)
    assert covered.all()
    # the dent's curvature over the support (≤ 0.12 /mm) is the interpolation's only error: ½ u'' h² ≲ 0.1 mm
    np.testing.assert_allclose(u, dent(top), atol=0.1)


def test_the_default_objective_fits_the_displacement_only_where_speckle_tracking_observed_it():
    from types import SimpleNamespace

    from hifumotion.estimation.calibrate import CalibrationSettings, objective_for

    assert CalibrationSettings().objective == "auto"
    tracked, segmented = SimpleNamespace(motion=object()), SimpleNamespace(motion=None)
    assert objective_for("auto", tracked) == "contour+displacement"
    assert objective_for("auto", segmented) == "contour"          # given or re-segmented contours
    assert objective_for("contour", tracked) == "contour"          # what the user asked for stands
    assert objective_for("contour+displacement", segmented) == "contour+displacement"   # and is refused later


def test_predicted_section_follows_a_rigid_shift():
    mask0 = disc(PLANE.shape, 70, 60, 25)
    ref = ReferenceShape(mask0, PLANE)
    g = np.stack(np.meshgrid(np.arange(8, 20, 1.0), np.arange(6, 18, 1.0), np.arange(2, 9, 1.0),
                             indexing="ij"), -1).reshape(-1, 3)
    shift = np.array([1.0, -0.6, 0.0])   # mm: 5 px right, 3 px down
    pred = predicted_mask(g + shift, g, 1.0, ref)
    expected = disc(PLANE.shape, 75, 57, 25)
    from hifumotion.metrics import centroid, dice

    assert dice(pred, expected) > 0.99
    assert np.allclose(centroid(pred, 0.2) - centroid(mask0, 0.2), shift[:2], atol=0.03)


def test_the_online_aim_is_the_tracked_centroid_carried_by_the_models_motion():
    """A model translating rigidly at a known velocity, a tracked section offset from it by a
    fraction of a pixel: the aim k frames ahead is the tracked centroid plus k frames of motion
    (the closed form, to the grid's quantisation), and the CSV writes that aim."""
    from types import SimpleNamespace

    from hifumotion.metrics import centroid
    from hifumotion.prediction.pipeline import online_csv, online_predictions

    mask0 = disc(PLANE.shape, 70, 60, 25)
    ref = ReferenceShape(mask0, PLANE)
    g = np.stack(np.meshgrid(np.arange(4, 28, 1.0), np.arange(3, 22, 1.0), np.arange(2, 9, 1.0),
                             indexing="ij"), -1).reshape(-1, 3)
    v = np.array([0.13, -0.07, 0.0])            # mm a frame
    run = SimpleNamespace(kept={f: g + f * v for f in range(12)}, rest_mm=g)
    pred = SimpleNamespace(run=run, pixel_mm=PLANE.pixel_mm)
    # the tracked sections: the disc moved with the tissue, 1.7 px right and 0.3 px up of the model's
    tracked = np.stack([disc(PLANE.shape, 70 + 1.7 + f * v[0] / 0.2, 60 - 0.3 + f * v[1] / 0.2, 25)
                        for f in range(12)])
    out = online_predictions(pred, SimpleNamespace(spacing_mm=1.0), ref, tracked, [3, 5], [0, 2, 4, 6])
    for k in (3, 5):
        assert sorted(out.aims_mm[k]) == [t + k for t in (0, 2, 4, 6)]
        for t in (0, 2, 4, 6):
            expected = centroid(tracked[t], 0.2) + k * v[:2]
            # the model's rasterised sections carry its motion to the grid's quantisation (a
            # quarter of a pixel on each axis for this disc), and so does the moved mask
            np.testing.assert_allclose(out.aims_mm[k][t + k], expected, atol=0.3 * 0.2)
            assert np.linalg.norm(centroid(out.masks[k][t + k], 0.2) - expected) < 0.5 * 0.2
            assert out.masks[k][t + k].shape == PLANE.shape
    rows = np.genfromtxt(io.StringIO(online_csv(out, tracked, 0.2, 0.05)), delimiter=",", names=True)
    first = rows[(rows["horizon_frames"] == 3) & (rows["frame"] == 3)][0]
    np.testing.assert_allclose([first["predicted_x_mm"], first["predicted_y_mm"]], out.aims_mm[3][3], atol=1e-4)


def test_predicted_mask_is_the_interpolation_at_every_pixel_under_a_large_motion():
    """predicted_mask splats the particles' displacement onto the pixels: it must be the Shepard
    interpolation a tree search gives at every pixel, and so the mask, for a motion of 2 mm with
    a turn and an out-of-plane part and a reference continued out of the plane by a sphere."""
    mask0 = disc(PLANE.shape, 70, 60, 25)
    zz, yy, xx = np.mgrid[0:12, 0:26, 0:30] * 1.0               # 1 mm voxels from the tank origin
    sphere = 5.0 - np.sqrt((xx - 14.0) ** 2 + (yy - 12.0) ** 2 + (zz - 5.0) ** 2)
    ref = ReferenceShape(mask0, PLANE, sphere, 1.0, (0.0, 0.0, 0.0))
    g = np.stack(np.meshgrid(np.arange(6, 23, 1.0), np.arange(4, 20, 1.0), np.arange(1, 10, 1.0),
                             indexing="ij"), -1).reshape(-1, 3)
    turn = np.deg2rad(12.0)
    rot = np.array([[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0], [0.0, 0.0, 1.0]])
    centre = np.array([14.0, 12.0, 5.0])
    moved = (g - centre) @ rot.T + centre + np.array([1.5, -1.0, 0.8]) + 0.3 * np.sin(g / 3.0)
    pts = PLANE.points_mm().reshape(-1, 3)
    u, covered = displacement_at(pts, moved, g, 1.0, neighbours=64)    # a tree search per pixel
    splat, splat_covered = plane_displacement(moved, g, 1.0, PLANE)     # each particle splatted
    assert np.array_equal(splat_covered.ravel(), covered)
    np.testing.assert_allclose(splat.reshape(-1, 3), u, atol=1e-9)
    everywhere = np.zeros(len(pts), bool)
    everywhere[covered] = ref.inside(pts[covered] - u[covered])
    pred = predicted_mask(moved, g, 1.0, ref, stride_px=1)
    assert everywhere.sum() > 1000
    assert np.array_equal(pred, everywhere.reshape(PLANE.shape))


def test_predicted_section_of_a_uniform_strain_is_the_mapped_disc_at_every_stride():
    """Particles strained uniformly (8 % compression in y, 4 % extension and a shear in x):
    the predicted section is the frame-0 disc mapped by the same affine map, known in
    closed form, whether the displacement is interpolated at every pixel (the default) or on
    the coarse grid; the two differ by a few boundary pixels at most."""
    from hifumotion.metrics import dice

    mask0 = disc(PLANE.shape, 70, 60, 25)
    ref = ReferenceShape(mask0, PLANE)
    g = np.stack(np.meshgrid(np.arange(6, 23, 1.0), np.arange(4, 20, 1.0), np.arange(2, 9, 1.0),
                             indexing="ij"), -1).reshape(-1, 3)
    a = np.array([[1.04, 0.03, 0.0], [0.0, 0.92, 0.0], [0.0, 0.0, 1.0]])
    centre = np.array([14.0, 12.0, 5.0])                       # the disc's centre (mm): col 70, row 60
    moved = (g - centre) @ a.T + centre
    rows, cols = np.mgrid[0:PLANE.shape[0], 0:PLANE.shape[1]]
    xy = np.stack([cols * 0.2, rows * 0.2], -1) - centre[:2]   # mm from the centre
    back = xy @ np.linalg.inv(a[:2, :2]).T                     # the material point of each pixel
    expected = (back ** 2).sum(-1) <= (25 * 0.2) ** 2
    fine = predicted_mask(moved, g, 1.0, ref, stride_px=1)
    coarse = predicted_mask(moved, g, 1.0, ref, stride_px=2)
    assert dice(fine, expected) > 0.99 and dice(coarse, expected) > 0.99
    assert (fine != coarse).sum() <= 10


class AnalyticEvaluator(Evaluator):
    """An evaluator whose 'runs' are a known function of the parameters, in process (no Dask).

    r = Σ_c pattern_c × (θ_c − θ*_c) + curvature, with no dependence on β2: the truth is θ*,
    β2 is not determined."""

    def __init__(self, truth: Parameters, frames=(1, 2, 3)):
        space = SearchSpace()
        masks = np.stack([disc(PLANE.shape, 70, 60, 25)] * (max(frames) + 1))
        data = TrainingData.from_masks(masks, frames, PLANE)

        class Spec:
            points_mm = np.zeros((16, 3))

        super().__init__(Spec(), data, space)
        self.truth = space.theta(truth)
        rng = np.random.default_rng(0)
        self.patterns = rng.normal(0, 1, (3, len(frames), 16))
        self._client = "analytic"

    def _submit(self, ks, n):
        out = []
        for k in ks:
            d = self.space.theta(k) - self.truth
            # F, E, β1 scaled together leave the push unchanged: the residual sees ln(E/F), ln(β1/F)
            d[0] -= np.log(k.force_n / self.space.force_n)
            d[2] -= np.log(k.force_n / self.space.force_n)
            r = sum(p * v for p, v in zip(self.patterns, (d[0], d[1] * 10, d[2] * 0.3)))
            r = r + 0.1 * d[0] ** 2
            out.append({"residuals_mm": r[:n], "seconds": 0.0, "steps": 0})
            self.runs += 1
        return out


def test_least_squares_recovers_known_parameters_and_flags_the_undetermined():
    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5)
    ev = AnalyticEvaluator(truth)
    start = ev.space.theta(Parameters(0.25, 20000.0, 0.47, 1e4, 0.7))
    fit = least_squares_fit(ev, start, max_evaluations=20)
    k = ev.space.parameters(fit.theta)
    assert k.youngs_modulus_pa == pytest.approx(9000.0, rel=0.01)
    assert k.poisson_ratio == pytest.approx(0.43, abs=0.002)
    assert k.beta1 == pytest.approx(2e5, rel=0.05)
    unc = uncertainty(ev, fit.theta)
    assert unc.determined["log_E"] and unc.determined["nu"]
    assert not unc.determined["beta2"]          # the residuals never depend on it
    # scaling F, E, β1 together costs nothing: the push cannot tell them apart
    costs = {d["factor"]: d["cost_mm"] for d in degeneracy(ev, fit.theta)}
    assert costs[2.0] == pytest.approx(costs[1.0], abs=1e-6) and costs[0.5] == pytest.approx(costs[1.0], abs=1e-6)


def test_the_errors_scale_with_the_scatter_of_the_residuals_they_are_given():
    """Gauss–Newton's errors are s × √diag((JᵀJ)⁻¹): at the truth of an exact model the scatter is
    the half-pixel floor; given another model's residuals there (a full model's beside a reduced
    one's Jacobian), the errors scale by their scatter over that floor, and the Jacobian's part
    is the same."""
    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5)
    ev = AnalyticEvaluator(truth)
    at = ev.space.theta(truth)
    own = uncertainty(ev, at)
    assert own.sigma_mm == pytest.approx(0.5 * ev.data.pixel_mm)
    other = np.random.default_rng(3).normal(0, 1, ev.one(at).shape)
    m, p = other.size, len(at)
    s = float(np.sqrt(other.ravel() @ other.ravel() / (m - p)))
    assert s > 0.5 * ev.data.pixel_mm
    given = uncertainty(ev, at, other)
    assert given.sigma_mm == pytest.approx(s)
    seen = np.isfinite(own.std_independent)
    assert np.allclose(given.std_independent[seen], own.std_independent[seen] * s / own.sigma_mm)
    assert np.array_equal(np.isfinite(given.std_independent), seen)
    # the reported error is never below the independent-point one
    assert np.all(given.std[seen] >= given.std_independent[seen] * (1 - 1e-12))


def _frames_sharing_errors(seed: int, frames: int = 9, points: int = 150, p: int = 3):
    """A linear model ``r = J δθ + e`` whose error ``e`` is mostly one draw per frame, spread over
    the frame's points along a pattern the Jacobian can see (a section drawn too wide: every
    point moves together), plus a little independent noise per point."""
    rng = np.random.default_rng(seed)
    j = rng.normal(0, 1, (frames * points, p)) + np.repeat(rng.normal(0, 1, (frames, 1, p)), points, 1).reshape(-1, p)
    per_frame = j.reshape(frames, points, p)
    pattern = np.einsum("twp,tp->tw", per_frame, rng.normal(0, 1, (frames, p))) / np.sqrt(p)
    pattern += 0.5 * rng.normal(0, 1, (frames, points))
    return j, pattern, rng


def test_the_frames_jackknife_matches_the_scatter_of_repeated_fits_where_points_share_errors():
    """Monte Carlo truth: 600 fits of a linear model on nine frames whose points share each
    frame's error. Their scatter is the true standard error; the delete-one-frame jackknife
    finds it (within 20 %), while the independent-point covariance, which counts 150 points a
    frame as 150 measurements, is several times too small."""
    from hifumotion.estimation.fit import frame_jackknife_covariance

    j, pattern, rng = _frames_sharing_errors(0)
    frames, points = pattern.shape
    _, _, vt = np.linalg.svd(j, full_matrices=False)
    solve = np.linalg.inv(j.T @ j) @ j.T
    fits, jack, independent = [], [], []
    for _ in range(600):
        e = (rng.normal(0, 1, frames)[:, None] * pattern + 0.3 * rng.normal(0, 1, (frames, points))).ravel()
        theta = solve @ e
        r = (e - j @ theta).reshape(frames, points)
        fits.append(theta)
        jack.append(np.diag(frame_jackknife_covariance(j, r, vt)))
        independent.append(np.diag(r.ravel() @ r.ravel() / (r.size - 3) * np.linalg.inv(j.T @ j)))
    truth = np.std(fits, axis=0)
    assert np.all(np.abs(np.sqrt(np.mean(jack, axis=0)) / truth - 1) < 0.2)
    assert np.all(np.sqrt(np.mean(independent, axis=0)) / truth < 0.3)
    # and the jackknife's 3σ covers the truth (0) in nearly every fit
    assert np.mean(np.abs(np.array(fits)) < 3 * np.sqrt(np.array(jack))) > 0.95


def test_a_direction_one_frame_alone_sees_has_no_measured_scatter():
    from hifumotion.estimation.fit import frame_jackknife_covariance

    rng = np.random.default_rng(4)
    j = rng.normal(0, 1, (3 * 20, 2))
    j[20:, 1] = 0.0                      # only frame 0 sees the second coordinate
    r = rng.normal(0, 1, (3, 20))
    cov = frame_jackknife_covariance(j, r, np.eye(2))
    assert np.isfinite(cov[0, 0]) and cov[1, 1] == np.inf


class FrictionEvaluator(AnalyticEvaluator):
    """The analytic evaluator on a space that fits the friction too: ln μ_f has its own pattern."""

    def __init__(self, truth: Parameters, frames=(1, 2, 3)):
        from hifumotion.estimation.space import FRICTION_BOUNDS

        super().__init__(truth, frames)
        self.space = SearchSpace(friction=FRICTION_BOUNDS)
        self.truth = self.space.theta(truth)
        self.patterns = np.concatenate([self.patterns, np.random.default_rng(1).normal(0, 1, (1,) + self.patterns.shape[1:])])

    def _submit(self, ks, n):
        out = []
        for k in ks:
            d = self.space.theta(k) - self.truth
            r = sum(p * v for p, v in zip(self.patterns, (d[0], d[1] * 10, d[2] * 0.3, d[4])))
            out.append({"residuals_mm": r[:n], "seconds": 0.0, "steps": 0})
            self.runs += 1
        return out


def test_the_friction_as_a_fifth_coordinate_is_recovered_and_its_design_spans_it():
    from hifumotion.estimation.space import FRICTION_BOUNDS

    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5, friction=0.12)
    ev = FrictionEvaluator(truth)
    assert ev.space.names[-1] == "log_mu" and len(ev.space.steps) == 5
    design = ev.space.initial_design()
    assert len(design) == 12
    mus = sorted({float(np.exp(t[4])) for t in design})
    assert len(mus) == 2 and FRICTION_BOUNDS[0] < mus[0] < mus[1] < FRICTION_BOUNDS[1]
    start = ev.space.theta(Parameters(0.25, 20000.0, 0.47, 1e4, 0.7, friction=0.4))
    fit = least_squares_fit(ev, start, max_evaluations=20)
    k = ev.space.parameters(fit.theta)
    assert k.friction == pytest.approx(0.12, rel=0.01)
    assert k.youngs_modulus_pa == pytest.approx(9000.0, rel=0.01)
    assert uncertainty(ev, fit.theta).determined["log_mu"]
    # a space without the coordinate leaves the friction to the model's setting
    assert SearchSpace().parameters(SearchSpace().theta(truth)).friction is None


def test_a_reduced_models_friction_trust_region_is_cut_by_the_space():
    from hifumotion.estimation.space import FRICTION_BOUNDS

    space = SearchSpace(friction=FRICTION_BOUNDS)
    k = Parameters(0.25, 9000.0, 0.45, 2e5, 0.5, friction=0.1)
    near = space.friction_within(space.theta(k), 1.25)
    assert near.friction == pytest.approx((0.08, 0.125))
    assert (near.youngs_pa, near.poisson, near.beta1, near.beta2) == (space.youngs_pa, space.poisson, space.beta1, space.beta2)
    assert space.friction_within(space.theta(k.replaced(friction=0.9)), 1.25).friction == pytest.approx((0.72, 1.0))
    assert SearchSpace().friction_within(SearchSpace().theta(k), 1.25) == SearchSpace()


def test_the_fits_coordinates_are_addressed_by_name():
    """Each coordinate's place in θ is its place in the space's names; setting one by name
    changes that one only, and a coordinate the space does not fit is refused by name."""
    from hifumotion.estimation.space import FRICTION_BOUNDS, FRICTION_NAME

    space = SearchSpace(friction=FRICTION_BOUNDS)
    k = Parameters(0.25, 9000.0, 0.45, 2e5, 0.5, friction=0.1)
    theta = space.theta(k)
    assert theta[space.index("nu")] == 0.45 and theta[space.index(FRICTION_NAME)] == pytest.approx(np.log(0.1))
    moved = space.with_value(theta, FRICTION_NAME, np.log(0.3))
    assert space.parameters(moved).friction == pytest.approx(0.3)
    assert space.parameters(moved).replaced(friction=0.1).as_dict() == pytest.approx(space.parameters(theta).as_dict())
    assert np.array_equal(theta, space.theta(k))      # the original is left as it was
    with pytest.raises(KeyError, match="log_mu"):
        SearchSpace().index(FRICTION_NAME)


class ReducedFrictionEvaluator(FrictionEvaluator):
    """A reduced model of the friction evaluator, made around a centre: its friction term is the
    truth's within a factor 1.3 of the μ_f it was made at, and beyond it fades into a false one
    that holds a stick at μ_f 0.9 for a slide (the reduced model that slides on at any μ_f,
    docs/decisions.md, "The reduced search fits the friction within its trust region")."""

    ACCURATE, FALSE_MU = np.log(1.3), 0.9

    def __init__(self, truth: Parameters, centre_mu: float):
        super().__init__(truth)
        self.centre = np.log(centre_mu)
        self.made = 0

    def reduce_around(self, theta, upto=None, new_runs=True) -> float:
        self.centre = float(theta[4])
        self.model_tag = f"reduced@{self.centre:.9g}"
        self.made += 1
        return 0.0

    def full_runs(self, thetas, upto=None):
        """The full model: the friction evaluator's exact residuals."""
        self.full = getattr(self, "full", 0) + len(thetas)
        return [r["residuals_mm"] for r in FrictionEvaluator._submit(self, [self.space.parameters(t) for t in thetas],
                                                                    len(self.data.frames))]

    def _submit(self, ks, n):
        out = []
        for k in ks:
            theta = self.space.theta(k)
            d = theta - self.truth
            beyond = max(abs(theta[4] - self.centre) - self.ACCURATE, 0.0)
            g = np.exp(-(beyond / 0.1) ** 2)
            friction = g * d[4] + (1 - g) * (theta[4] - np.log(self.FALSE_MU))
            r = sum(p * v for p, v in zip(self.patterns, (d[0], d[1] * 10, d[2] * 0.3, friction)))
            out.append({"residuals_mm": r[:n], "seconds": 0.0, "steps": 0})
            self.runs += 1
        return out


def test_the_reduced_search_keeps_the_friction_where_its_model_holds_and_remakes_it_there():
    """A reduced model made at μ_f 0.3 for a truth at 0.12 holds only near 0.3 (and beyond it
    prefers a false 0.9): searched within its trust region and made again where each search stops
    at that region's edge, the fit reaches the truth; searched free and unchecked, it is misled;
    searched free but checked by the full model, the check sees the false fit and the model made
    again there leads on to the truth."""
    from hifumotion.estimation.settings import CalibrationSettings
    from hifumotion.estimation.strategies import ReducedTrustRegion, TrustRegionRecord

    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5, friction=0.12)
    start = np.array([np.log(9000.0), 0.43, np.log(2e5), 0.5, np.log(0.3)])
    for trust, checked, reaches_truth in ((1.25, True, True), (1.25, False, True), (100.0, False, False),
                                          (100.0, True, True)):
        ev = ReducedFrictionEvaluator(truth, centre_mu=0.3)
        s = CalibrationSettings(max_evaluations=20, reduced_friction_trust=trust, reduced_rounds=8,
                                full_model_check=checked)
        record, made = TrustRegionRecord(centres=[start]), []
        _, _, theta, rounds = ReducedTrustRegion._pass(ev, s, start, record, made)
        centres, checks = record.centres, [r.check for r in rounds if r.check is not None]
        mu = float(np.exp(theta[4]))
        assert ev.space.friction is not None       # the whole space is back after the search
        assert len(checks) == (ev.made + 1 if checked else 0) == getattr(ev, "full", 0)
        if reaches_truth:
            assert mu == pytest.approx(0.12, rel=0.1)       # (the estimator's ftol: 0.129)
        else:
            assert abs(mu / 0.12 - 1) > 0.3 and ev.made == 0      # misled beyond the model's reach
        if trust < 2:
            # each model made again where the last search stopped, μ_f a factor ≤ 1.25 from the last
            assert ev.made == len(made) == len(centres) - 1 >= 3
            steps = np.abs(np.diff([c[4] for c in centres]))
            assert np.all(steps <= np.log(1.25) + 1e-6)
        if checked:
            # the last check is the fit's: the full model and the reduced one agree there
            assert checks[-1].agrees and np.array_equal(checks[-1].theta, theta)
            assert checks[-1].cost_full_mm == pytest.approx(checks[-1].cost_reduced_mm, rel=1e-9)
        if checked and trust > 2:
            # free, the first fit was misled, as unchecked; the check found it out
            assert not checks[0].agrees and abs(np.exp(checks[0].theta[4]) / 0.12 - 1) > 0.3


def test_a_reduced_fit_the_full_model_fits_worse_than_the_start_is_not_kept():
    """Started at the truth on a reduced model that is false there (made at μ_f 0.3, searched
    free, one round): the search walks to the false friction; the full model fits that fit worse
    than the start, so the start is what the search returns — and the design's starts are the best
    of each friction level."""
    from hifumotion.estimation.settings import CalibrationSettings
    from hifumotion.estimation.strategies import ReducedTrustRegion, TrustRegionRecord, _design_starts, run_checks

    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5, friction=0.12)
    ev = ReducedFrictionEvaluator(truth, centre_mu=0.3)
    # uncorrected: corrected by the full model's miss at the start, the search would not leave it
    # (test_the_full_models_miss_at_the_centre_corrects_the_reduced_search)
    s = CalibrationSettings(max_evaluations=20, reduced_friction_trust=100.0, reduced_rounds=0,
                            reduced_correction=False)
    at_truth = ev.space.theta(truth)
    start, = run_checks(ev, [at_truth], s.reduced_agreement)
    assert start.cost_full_mm == pytest.approx(0.0, abs=1e-9) and not start.agrees
    fit, _, theta, rounds = ReducedTrustRegion._pass(ev, s, at_truth, TrustRegionRecord(centres=[at_truth]), [], start)
    checks = [r.check for r in rounds if r.check is not None]
    assert len(checks) == 1 and checks[0].cost_full_mm > 1.0       # the fit the search found
    assert np.array_equal(theta, at_truth) and fit.method == "design"
    design = [(5.0, [1.0, 0.45, 2.0, 0.5, -2.5]), (3.0, [2.0, 0.45, 2.0, 0.5, -1.4]),
              (4.0, [3.0, 0.45, 2.0, 0.5, -2.5]), (1.0, [4.0, 0.45, 2.0, 0.5, -1.4])]
    starts = _design_starts(design, ev.space)
    assert [list(x) for x in starts] == [design[3][1], design[2][1]]
    assert [list(x) for x in _design_starts([(c, d[:4]) for c, d in design], SearchSpace())] == [design[3][1][:4]]


class BiasedReducedEvaluator(FrictionEvaluator):
    """A reduced model that misses the full one by a fixed residual pattern, as a reduced model
    misses even its own snapshot's run where the sample sticks and slips (docs/decisions.md,
    "The reduced model misses its own snapshot"); the full model is the friction evaluator's exact residuals."""

    def __init__(self, truth: Parameters):
        super().__init__(truth)
        rng = np.random.default_rng(7)
        self.bias = 0.3 * rng.normal(0, 1, self.patterns.shape[1:])
        self.made = 0

    def reduce_around(self, theta, upto=None, new_runs=True) -> float:
        self.made += 1
        self.model_tag = f"reduced#{self.made}"
        return 0.0

    def full_runs(self, thetas, upto=None):
        return [r["residuals_mm"] for r in FrictionEvaluator._submit(self, [self.space.parameters(t) for t in thetas],
                                                                    len(self.data.frames))]

    def _submit(self, ks, n):
        out = FrictionEvaluator._submit(self, ks, n)
        for r in out:
            r["residuals_mm"] = r["residuals_mm"] + self.bias[:n]
        return out


def test_the_full_models_miss_at_the_centre_corrects_the_reduced_search():
    """A reduced model off the full one by a fixed pattern: searched as it is from a checked start,
    its fit is the bias's optimum, which the full model fits worse, and it does not agree there;
    searched with the full model's miss at the start added (zero-order consistency, Alexandrov et
    al. 1998), the first search reaches the truth, where the corrected model and the full one agree."""
    from hifumotion.estimation.settings import CalibrationSettings
    from hifumotion.estimation.strategies import ReducedTrustRegion, TrustRegionRecord, run_checks

    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5, friction=0.12)
    theta0 = np.array([np.log(14000.0), 0.45, np.log(1e5), 0.5, np.log(0.15)])
    found = {}
    for corrected in (False, True):
        ev = BiasedReducedEvaluator(truth)
        s = CalibrationSettings(max_evaluations=20, reduced_friction_trust=100.0, reduced_rounds=0,
                                reduced_correction=corrected)
        start, = run_checks(ev, [theta0], s.reduced_agreement)
        _, _, theta, rounds = ReducedTrustRegion._pass(ev, s, theta0, TrustRegionRecord(centres=[theta0]), [], start)
        found[corrected] = (theta, rounds[0].check)
    (plain, plain_check), (fit, check) = found[False], found[True]
    k = FrictionEvaluator(truth).space.parameters(fit)
    assert k.youngs_modulus_pa == pytest.approx(9000.0, rel=0.01) and k.friction == pytest.approx(0.12, rel=0.01)
    assert check.agrees and check.cost_full_mm == pytest.approx(check.cost_reduced_mm, rel=0.05)
    # uncorrected, the bias's optimum: off the truth, and the full model fits it worse
    assert not plain_check.agrees and plain_check.cost_full_mm > 10 * check.cost_full_mm
    assert abs(np.exp(plain[0]) / 9000.0 - 1) > 0.01 or abs(np.exp(plain[4]) / 0.12 - 1) > 0.01


def test_a_search_that_stays_at_its_checked_start_ends_the_rounds_without_another_full_run():
    """Started at the full model's optimum (its cost 0 there), the corrected reduced model is the
    full one at its centre, so the search does not leave it: the rounds end there, with no second
    full run at the same point and no model made again from the same runs (which would search the
    same model again, round after round)."""
    from hifumotion.estimation.settings import CalibrationSettings
    from hifumotion.estimation.strategies import ReducedTrustRegion, TrustRegionRecord, run_checks

    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5, friction=0.12)
    ev = BiasedReducedEvaluator(truth)
    at_truth = ev.space.theta(truth)
    s = CalibrationSettings(max_evaluations=20, reduced_friction_trust=100.0, reduced_rounds=3)
    start, = run_checks(ev, [at_truth], s.reduced_agreement)
    assert start.cost_full_mm == pytest.approx(0.0, abs=1e-9)
    fit, _, theta, rounds = ReducedTrustRegion._pass(ev, s, at_truth, TrustRegionRecord(centres=[at_truth]), [], start)
    assert np.array_equal(theta, at_truth) and fit.method == "design"
    assert [r.check for r in rounds] == [None] and ev.made == 0


def test_the_resolution_check_compares_displacements_from_each_runs_own_frame_0():
    """Two runs of the same points: one the other moved rigidly by a shift that grows frame by frame
    (and starts offset, which is no motion): the difference is that growth, per frame; a shape
    mismatch is refused."""
    from hifumotion.estimation.resolution import ResolutionCheck, displacement_difference_mm

    rng = np.random.default_rng(3)
    a = rng.normal(0, 5, (4, 10, 3)).cumsum(axis=0)
    growth = np.array([0.0, 0.1, 0.25, 0.5])
    b = a + np.array([1.0, -2.0, 0.5]) + growth[:, None, None] * np.array([0.6, 0.8, 0.0])
    np.testing.assert_allclose(displacement_difference_mm(a, b), growth, atol=1e-12)
    # one point of ten off by 1 mm at the last frame: RMS √(1/10)
    c = a.copy()
    c[3, 0] += [1.0, 0.0, 0.0]
    np.testing.assert_allclose(displacement_difference_mm(a, c), [0, 0, 0, np.sqrt(0.1)], atol=1e-12)
    with pytest.raises(ValueError):
        displacement_difference_mm(a, a[:, :5])
    check = ResolutionCheck((1000, 2000), (2.0, 1.6), growth, 0.3, 3)
    assert check.largest_mm == 0.5 and not check.resolved
    assert ResolutionCheck((1000, 2000), (2.0, 1.6), growth * 0.5, 0.3, 3).resolved


@pytest.mark.parametrize("second_off_mm, resolved", [(0.0, True), (0.5, False)])
def test_a_finer_lattice_that_disagrees_is_checked_by_the_next_one(monkeypatch, second_off_mm, resolved):
    """Runs whose truth is set here: the model's own lattice and the one with 4× its particles move
    the points alike (or the 4× one by ``second_off_mm``), the 2× lattice 1 mm apart from both.
    The 2× lattice is overruled and the check, its verdict and its parameter shift are the 4×
    one's; without ``confirm`` the 2× lattice stands."""
    from types import SimpleNamespace

    import hifumotion.estimation.resolution as resolution

    frames, points = 4, 6
    base = np.zeros((frames, points, 3))
    growth = np.linspace(0.0, 1.0, frames)[:, None, None] * np.array([1.0, 0.0, 0.0])
    motion = {1000: base, 2000: base + growth, 4000: base + second_off_mm * growth}

    def spec_with(n):
        return SimpleNamespace(tissue_mm=np.zeros((n, 3)), spacing_mm=2.0 * (1000 / n) ** (1 / 3),
                               settings=SimpleNamespace(tissue_particles=n))

    monkeypatch.setattr(resolution, "replace", lambda settings, tissue_particles: tissue_particles)
    monkeypatch.setattr(resolution, "model_spec", lambda observation, n: spec_with(n))
    monkeypatch.setattr(resolution, "run_model", lambda spec, k, last, full: SimpleNamespace(
        points_mm=motion[len(spec.tissue_mm)], bar_centre_mm=None))
    monkeypatch.setattr(resolution, "residuals_mm", lambda p, data, upto, bar: p[..., 0].ravel())
    observation = SimpleNamespace(pixel_mm=0.3)
    jacobian = np.ones((frames * points, 1))
    check = resolution.resolution_check(spec_with(1000), None, observation, frames - 1, data=object(),
                                        jacobian=jacobian, names=("a",))
    assert check.particles == (1000, 4000) and check.overruled == {"particles": 2000, "largest_mm": 1.0}
    assert check.resolved == resolved and check.largest_mm == pytest.approx(second_off_mm)
    # the 4× lattice's shift: −mean of its residuals' difference, the mean x-offset over frames and points
    assert check.parameter_shift["a"] == pytest.approx(-second_off_mm * np.mean(np.linspace(0.0, 1.0, frames)))
    alone = resolution.resolution_check(spec_with(1000), None, observation, frames - 1, confirm=False)
    assert alone.particles == (1000, 2000) and alone.overruled is None and not alone.resolved


def test_a_driven_bars_first_reduced_model_is_made_at_its_own_travel_at_both_friction_levels():
    """With a fitted friction and the full model's check, the first reduced model of a driven bar
    comes from full runs at the design's centre at each of the design's friction levels (the
    program's own travel: no snapshot scenes), made around the first; a force-held push keeps the
    spec's snapshot scenes (F/E × 0.5 and × 2) around the centre."""
    from hifumotion.estimation.settings import CalibrationSettings
    from hifumotion.estimation.strategies import ReducedTrustRegion

    class Recorder(FrictionEvaluator):
        def __init__(self, truth):
            super().__init__(truth)
            self.calls = []

        def full_runs(self, thetas, upto=None):
            self.calls.append(("full", [np.array(t) for t in thetas]))
            return [np.zeros((len(self.data.frames), 16)) for _ in thetas]

        def reduce_around(self, theta, upto=None, new_runs=True):
            self.calls.append(("reduce", np.array(theta), new_runs))
            return 0.0

    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5, friction=0.12)
    ev = Recorder(truth)
    design = ev.space.initial_design()
    centre = np.mean(design, axis=0)
    ReducedTrustRegion._first_model(ev, CalibrationSettings(), centre, driven=True)
    (kind, at), (again, around, new_runs) = ev.calls
    levels = sorted({float(d[4]) for d in design})
    assert kind == "full" and again == "reduce" and not new_runs and len(levels) == 2
    assert [float(a[4]) for a in at] == levels and all(np.array_equal(a[:4], centre[:4]) for a in at)
    assert np.array_equal(around, at[0])
    for driven, checked in ((False, True), (True, False)):
        ev.calls = []
        ReducedTrustRegion._first_model(ev, CalibrationSettings(full_model_check=checked), centre, driven=driven)
        assert len(ev.calls) == 1 and ev.calls[0][0] == "reduce" and ev.calls[0][2]
        assert np.array_equal(ev.calls[0][1], centre)


def test_a_fitted_friction_reaches_the_models_scene():
    from hifumotion.estimation.model import ModelSpec, scene_for
    from hifumotion.scene import Scene

    spec = ModelSpec(Scene(), np.zeros((1, 3)), np.ones(1), np.zeros((1, 3)), 0.05)
    assert scene_for(spec, Parameters(friction=0.07), 10).physics.friction == 0.07
    assert scene_for(spec, Parameters(), 10).physics.friction == Scene().physics.friction


def test_table1_meets_its_thresholds():
    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5)
    ev = AnalyticEvaluator(truth, frames=(1, 2, 3, 4))
    start = ev.space.theta(Parameters(0.25, 15000.0, 0.45, 5e4, 0.5))
    result = iterative_estimate(ev, start, threshold_mm_per_point=0.05, max_runs=400)
    assert result.events[0]["rule"].startswith("step 1")
    assert result.events[0]["S_mm"][0] <= result.threshold_mm / 2 + 1e-9     # S_1 ≤ T/2
    assert result.accepted and np.all(result.frame_sums_mm <= result.threshold_mm)
    assert result.threshold_mm == pytest.approx(0.05 * 16)


def test_search_log_resumes(tmp_path):
    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5)
    ev = AnalyticEvaluator(truth)
    ev.log_path = tmp_path / "log.jsonl"
    thetas = [ev.space.theta(truth) + d for d in (0.0, 0.1, -0.1)]
    first = ev.residuals(thetas)
    again = AnalyticEvaluator(truth)
    again.log_path = tmp_path / "log.jsonl"
    again._read_log()
    again.runs = 0
    second = again.residuals(thetas)
    assert again.runs == 0 and again.resumed == 3
    assert all(np.allclose(a, b, atol=1e-5) for a, b in zip(first, second))


@pytest.mark.slow
def test_prepare_segments_reconstructs_and_tracks_the_twin(small_twin):
    from hifumotion.estimation.prepare import prepare
    from hifumotion.observed import load_observed
    from hifumotion.metrics import dice
    from hifumotion.scoring import read_frame_masks

    folder, result = small_twin
    obs = prepare(load_observed(folder / "observed"))
    truth_sweep = result.sweep_masks
    both = obs.sweep.present & truth_sweep.reshape(len(truth_sweep), -1).any(1)
    scores = [dice(a, b) for a, b in zip(obs.sweep.masks[both], truth_sweep[both])]
    assert np.median(scores) > 0.9
    blob_volume = json.loads((folder / "truth" / "parameters.json").read_text())["facts"]["blob_volume_mm3"]
    assert 0.8 < obs.reconstruction.volume_mm3 / blob_volume < 1.3
    truth = read_frame_masks(folder / "truth")
    assert dice(obs.frame_masks[0], truth[0]) > 0.93
    # the tracked frames follow the true ones (the material, carried by the speckle)
    assert min(dice(obs.frame_masks[f], truth[f]) for f in truth) > 0.9
    # nothing below the pool's floor (tank y < 0) is segmented as tissue at rest; later the
    # tracked material goes no deeper than the true section does (the twin's penalty contact)
    floor_row = int(np.ceil(-obs.offset_mm[1] / obs.pixel_mm))
    assert not obs.frame_masks[0, :floor_row].any() and not obs.sweep.masks[:, :floor_row].any()
    lowest_true = min(int(np.nonzero(m.any(1))[0].min()) for m in truth.values())
    lowest_tracked = min(int(np.nonzero(m.any(1))[0].min()) for m in obs.frame_masks)
    assert lowest_tracked >= lowest_true - 1


@pytest.mark.slow
def test_calibrate_predict_score_end_to_end(small_twin, tmp_path):
    folder, _ = small_twin
    cal, pred = tmp_path / "cal", tmp_path / "pred"
    cli = [sys.executable, "-m", "hifumotion"]
    out = subprocess.run(cli + ["calibrate", str(folder / "observed"), "-o", str(cal), "--particles", "300",
                                "--search-particles", "150", "--workers", "2", "--max-evaluations", "2",
                                "--set", "resolution_check=true", "--set", "bloom_continuation=true"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr + out.stdout
    params = json.loads((cal / "parameters.json").read_text())
    # the fit on twice the particles, said on the console as parameters.json has it
    rc = params["fit"]["resolution_check"]
    assert rc["particles"][1] > 1.8 * rc["particles"][0] and len(rc["difference_mm"]) == max(default_frames(40)[0]) + 1
    assert f"the fit's points A move {rc['largest_mm']:.2f} mm" in " ".join((out.stderr + out.stdout).split())
    for name in ("youngs_modulus_pa", "poisson_ratio", "beta1_pa_s_pow", "beta2", "external_force_n"):
        assert "value" in params["parameters"][name] and "determined" in params["parameters"][name]
    assert params["fit"]["runs"] > 5 and (cal / "search_log.jsonl").is_file()
    # each standard error is the larger of the independent-point one and the frames' jackknife,
    # with the resolution check's numerical error added in quadrature (the check is on here)
    errors = params["fit"]["correlation"]
    for name, reported, independent, frames in zip(errors["coordinates"], errors["std"],
                                                   errors["std_independent_points"], errors["std_frames_jackknife"]):
        if reported is not None:
            data = max(independent, frames)
            assert rc["std_data"][name] == pytest.approx(data, rel=1e-9)
            assert reported == pytest.approx(np.hypot(data, rc["parameter_shift"][name]), rel=1e-9)
    # the observation as it was made: frame 0's target continued into the bar's bloom, as asked
    assert params["observation"]["bloom_continuation"] is True
    assert params["observation"]["bloom_continued_by"] in ("reconstruction", "image")
    assert (cal / "model" / "scene.toml").is_file() and (cal / "observation" / "tissue.vtp").is_file()
    # the model kept is the one that fits the training frames better, saved with its own parameters
    mapping, model = params["fit"]["strategy"], params["model"]
    kept_search = mapping["cost_search_model_mm"] < mapping["cost_final_model_mm"]
    assert mapping["model_kept"] == ("search" if kept_search else "final")
    assert (model["tissue_particles"] == model["search_tissue_particles"]) == kept_search
    theta = mapping["theta_search" if kept_search else "theta_final"]
    assert params["parameters"]["youngs_modulus_pa"]["value"] == pytest.approx(np.exp(theta[0]), rel=1e-9)
    assert params["parameters"]["poisson_ratio"]["value"] == pytest.approx(theta[1], rel=1e-9)
    out = subprocess.run(cli + ["predict", str(cal), "-o", str(pred), "--online", "2,4"], capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr + out.stdout
    train, valid = default_frames(40)
    assert all((pred / "frames" / f"frame_{f:04d}.png").is_file() for f in train + valid)
    online = np.genfromtxt(pred / "online.csv", delimiter=",", names=True)
    assert set(online["horizon_frames"]) == {2, 4} and np.all(online["error_mm"] >= 0)
    aim = np.genfromtxt(pred / "aim.csv", delimiter=",", names=True)
    assert len(aim) == max(valid) + 1 and abs(aim["shift_mm"][0]) < 1e-9
    # the band: the model run again with the fit moved along its least determined direction
    band = json.loads((pred / "prediction.json").read_text())["band"]
    assert band["coordinates"] == params["fit"]["correlation"]["coordinates"]
    minus, plus = band["parameters_minus"], band["parameters_plus"]
    e = np.log(params["parameters"]["youngs_modulus_pa"]["value"])
    lo, hi = np.log(SearchSpace().youngs_pa)          # each end held inside the search bounds
    assert minus["youngs_modulus_pa"] == pytest.approx(np.exp(np.clip(e - band["step"][0], lo, hi)), rel=1e-6)
    assert plus["youngs_modulus_pa"] == pytest.approx(np.exp(np.clip(e + band["step"][0], lo, hi)), rel=1e-6)
    far = np.maximum(np.hypot(aim["aim_minus_x_mm"] - aim["aim_x_mm"], aim["aim_minus_y_mm"] - aim["aim_y_mm"]),
                     np.hypot(aim["aim_plus_x_mm"] - aim["aim_x_mm"], aim["aim_plus_y_mm"] - aim["aim_y_mm"]))
    assert np.allclose(aim["band_mm"], far, atol=2e-4) and abs(aim["band_mm"][0]) < 1e-9
    out = subprocess.run(cli + ["score", str(pred), str(folder / "truth")], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    summary = json.loads((pred / "score" / "scores.json").read_text())["summary"]
    assert (pred / "score" / "overlays.png").is_file()      # Fig. 4
    # a floor, not the target: the predicted sections overlap the truth
    assert summary["validation"]["dsc"]["mean"] > 0.7
    # the peers that know the same inputs beside it, from what the calibration recorded
    from hifumotion.metrics import dice
    from hifumotion.scoring import read_frame_masks

    out = subprocess.run(cli + ["score", str(pred), str(folder / "truth"), "--calibration", str(cal),
                                "-o", str(tmp_path / "score_peers")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "of every predictor:" in " ".join((out.stdout + out.stderr).split())
    peers = json.loads((tmp_path / "score_peers" / "scores.json").read_text())["peers"]
    assert set(peers["peers"]) == {"no_motion", "kalman", "drive_static", "drive_lagged"}
    # holding still is the last training frame's tracked mask, scored here independently
    tracked_last = read_frame_masks(cal / "observation")[max(train)]
    truth_masks = read_frame_masks(folder / "truth")
    hold = np.mean([dice(tracked_last, truth_masks[f]) for f in valid])
    assert peers["peers"]["no_motion"]["dsc_mean"] == pytest.approx(hold, abs=1e-9)
    assert peers["ranking"][0]["centroid_mean_mm"] == min(r["centroid_mean_mm"] for r in peers["ranking"])
    # a calibration folder edited by hand: each mistake one line naming the file, no traceback, no output
    for field, value in (("frames", "forty"), ("training_frames", "abc"), ("frame_interval_s", 0.0),
                         ("frames", 10 ** 9)):
        bad = tmp_path / f"bad_{field}_{value}"
        shutil.copytree(cal, bad)
        meta = json.loads((bad / "parameters.json").read_text())
        meta[field] = value
        (bad / "parameters.json").write_text(json.dumps(meta))
        out = subprocess.run(cli + ["predict", str(bad), "-o", str(tmp_path / "never")], capture_output=True,
                             text=True, timeout=120)
        lines = [ln for ln in (out.stdout + out.stderr).splitlines() if ln.strip()]
        assert out.returncode == 2 and len(lines) == 1 and "parameters.json" in lines[0], out.stderr
        assert field in lines[0] and not (tmp_path / "never").exists()
    # a hand-edited covariance costs the band, said in one line, not the prediction
    bad = tmp_path / "bad_correlation"
    shutil.copytree(cal, bad)
    meta = json.loads((bad / "parameters.json").read_text())
    meta["fit"]["correlation"] = "edited"
    (bad / "parameters.json").write_text(json.dumps(meta))
    out = subprocess.run(cli + ["predict", str(bad), "-o", str(tmp_path / "no_band")], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    assert [ln for ln in out.stderr.splitlines() if "no band" in ln and "fit.correlation" in ln]
    assert "band_mm" not in (tmp_path / "no_band" / "aim.csv").read_text().splitlines()[0]
    bad = tmp_path / "bad_reference"
    shutil.copytree(cal, bad)
    ref = bad / "observation" / "reference.npz"
    ref.write_bytes(ref.read_bytes()[:100])             # truncated
    out = subprocess.run(cli + ["predict", str(bad), "-o", str(tmp_path / "never")], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2 and "reference.npz" in out.stderr and "Traceback" not in out.stderr, out.stderr
    # existing output is never overwritten without --overwrite
    again = subprocess.run(cli + ["predict", str(cal), "-o", str(pred)], capture_output=True, text=True)
    assert again.returncode == 2 and "overwrite" in (again.stdout + again.stderr)
    # the online loop: the cine replayed frame by frame, a row per frame and horizon, a latency each
    live = tmp_path / "online"
    out = subprocess.run(cli + ["online", str(cal), str(folder / "observed"), "-o", str(live), "--horizons", "1,2"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr + out.stdout
    rows = np.genfromtxt(live / "online.csv", delimiter=",", names=True)
    assert len(rows) == 2 * 39 and set(rows["horizon_frames"]) == {1, 2} and np.all(rows["latency_ms"] > 0)
    report = json.loads((live / "online.json").read_text())
    assert report["frames"] == 39 and set(report["horizons"]) == {"1", "2"}
    # the online surrogate beside the filter: its aims in the file, its error in the summary and on the console
    assert np.isfinite(rows["surrogate_x_mm"]).all()
    assert all(h["surrogate_error_vs_tracked_mean_mm"] >= 0 for h in report["horizons"].values())
    assert "the drive surrogate" in " ".join((out.stdout + out.stderr).split())
    assert (live / "online.png").is_file() and (live / "run_info.json").is_file()
    bad = subprocess.run(cli + ["online", str(cal), str(folder / "observed"), "-o", str(tmp_path / "x"),
                                "--horizons", "0"], capture_output=True, text=True)
    assert bad.returncode == 2 and "--horizons" in bad.stderr + bad.stdout and "Traceback" not in bad.stderr
    # another experiment's cine (the same image size) is refused, and nothing is written
    other = tmp_path / "other"
    shutil.copytree(folder / "observed", other)
    frame0 = sorted((other / "frames").glob("*.png"))[0]
    shutil.copyfile(sorted((other / "frames").glob("*.png"))[1], frame0)
    (other / "frames.nii.gz").unlink()           # else the folder itself is refused: its NIfTI disagrees
    wrong = subprocess.run(cli + ["online", str(cal), str(other), "-o", str(tmp_path / "y")], capture_output=True,
                           text=True)
    assert wrong.returncode == 2 and "frame 0" in wrong.stderr + wrong.stdout and not (tmp_path / "y").exists()
    # --watch: a scanner writes the frames one by one (each in two halves, as a slow writer
    # would), the loop takes each as soon as it is whole and prints its aims at once; what it
    # computes is what the recorded replay computed, frame for frame
    scanner = tmp_path / "scanner"
    scanner.mkdir()
    for name in ("setup.json", "initial_contour.csv"):
        shutil.copyfile(folder / "observed" / name, scanner / name)
    (scanner / "frames").mkdir()
    recorded = sorted((folder / "observed" / "frames").glob("frame_*.png"))

    def write_frames():
        import time

        for path in recorded:
            data = path.read_bytes()
            target = scanner / "frames" / path.name
            with open(target, "wb") as fh:
                fh.write(data[: len(data) // 2])
                fh.flush()
                time.sleep(0.01)
                fh.write(data[len(data) // 2:])
            time.sleep(0.02)

    import threading

    writer = threading.Thread(target=write_frames)
    watched = tmp_path / "watched"
    proc = subprocess.Popen(cli + ["online", str(cal), str(scanner), "-o", str(watched), "--horizons", "1,2",
                                   "--watch", "--timeout", "3", "--stream"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    writer.start()
    stdout, stderr = proc.communicate(timeout=600)
    writer.join()
    assert proc.returncode == 0, stderr
    lines = [json.loads(line) for line in stdout.splitlines()]
    assert [line["frame"] for line in lines] == list(range(1, 40)) and set(lines[0]["aim_mm"]) == {"1", "2"}
    replay = np.genfromtxt(live / "online.csv", delimiter=",", names=True)
    watch_rows = np.genfromtxt(watched / "online.csv", delimiter=",", names=True)
    for column in ("predicted_x_mm", "predicted_y_mm", "tracked_x_mm", "push_scale"):
        assert np.array_equal(replay[column], watch_rows[column], equal_nan=True), column


def test_the_displacement_objective_is_the_weighted_difference_of_the_points_motion():
    """Points A that move as the speckle says leave no displacement residual; a point moved
    0.2 mm too far in x leaves 0.2 × its quality; an occluded point (quality 0) leaves none."""
    from hifumotion.estimation.objective import TrainingData, residuals_mm
    from hifumotion.scene import Plane
    from hifumotion.speckle import DisplacementSeries

    plane = Plane((0.0, 0.0, 5.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (40, 40), 0.5)
    masks = np.zeros((3, 40, 40), bool)
    masks[:, 10:30, 10:30] = True
    data = TrainingData.from_masks(masks, [1, 2], plane)
    field = np.zeros((3, 40, 40, 2), np.float32)
    field[1] = (0.3, -0.1)                                  # the observed displacement, mm
    field[2] = (0.6, -0.2)
    quality = np.ones((3, 40, 40), np.float32)
    quality[:, :, 25:] = 0.0                                # the right side unseen
    series = DisplacementSeries(field, quality, (0.5, 0.5))
    rest = np.array([[7.5, 7.5, 5.0], [10.0, 12.0, 5.0], [14.0, 8.0, 5.0]])   # mm; the last one unseen (x px 28)
    data = data.with_displacement(series, rest)
    points = np.stack([rest, rest + (0.3, -0.1, 0.0), rest + (0.6, -0.2, 0.0)])
    points[2, 0, 0] += 0.2                                  # point 0 at frame 2: 0.2 mm too far in x
    points[2, 2, 0] += 0.5                                  # the unseen point: no residual whatever it does
    r = residuals_mm(points, data)
    assert r.shape == (2, 9)
    disp = r[:, 3:].reshape(2, 3, 2)
    assert np.allclose(disp[0], 0.0, atol=1e-6)
    assert disp[1, 0] == pytest.approx([0.2, 0.0], abs=1e-6)
    assert np.allclose(disp[1, 1:], 0.0, atol=1e-6)


def test_the_bar_residuals_are_the_in_plane_difference_of_the_bar_travels_times_root_m():
    """The bar's residual is its model travel minus the tracked one, in the plane's axes,
    weighted by √M: a bar moved 1.0 mm down (and 0.3 mm out of the plane, which the image
    cannot see) against a tracked 0.6 mm down leaves 0.4 mm × √3 on the y column, 0 on x."""
    plane = Plane((0.0, 0.0, 5.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (40, 40), 0.5)
    masks = np.zeros((3, 40, 40), bool)
    masks[:, 10:30, 10:30] = True
    data = TrainingData.from_masks(masks, [1, 2], plane)
    rest = np.array([[6.0, 10.0, 5.0], [10.0, 6.0, 5.0], [14.0, 10.0, 5.0]])
    points = np.stack([rest, rest, rest])
    shift = np.array([[0.0, 0.0], [0.0, -0.3], [0.0, -0.6]])          # tracked (x, y) mm per frame
    bar = np.array([[5.0, 20.0, 5.0], [5.0, 19.5, 5.0], [5.0, 19.0, 5.3]])   # the model's bar centre
    with_bar = data.with_bar(shift, len(rest))
    r = residuals_mm(points, with_bar, bar_mm=bar)
    assert r.shape == (2, 5) and with_bar.width(3) == 5
    assert r[:, :3] == pytest.approx(residuals_mm(points, data), abs=1e-12)   # the contour part unchanged
    assert r[0, 3:] == pytest.approx([0.0, -0.2 * np.sqrt(3)], abs=1e-12)
    assert r[1, 3:] == pytest.approx([0.0, -0.4 * np.sqrt(3)], abs=1e-12)
    with pytest.raises(InputError, match="bar"):
        residuals_mm(points, with_bar)
    with pytest.raises(InputError, match="bar"):
        data.with_bar(shift[:2], len(rest))


def test_contour_residuals_are_weighted_by_the_tracking_quality_at_each_point():
    """A point's signed distance to the observed square is known by geometry (the mask's
    0.5 iso-line lies half a pixel outside its outer pixels' centres). With the quality
    weights it counts by the speckle's quality at the point: fully where the speckle
    matches, a quarter where it matches a quarter, nothing where the image shows none."""
    from hifumotion.speckle import DisplacementSeries

    plane = Plane((0.0, 0.0, 5.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (40, 40), 0.5)
    masks = np.zeros((3, 40, 40), bool)
    masks[:, 10:30, 10:30] = True                            # edges at x, y = 4.75 and 14.75 mm
    data = TrainingData.from_masks(masks, [1, 2], plane)
    quality = np.ones((3, 40, 40), np.float32)
    quality[:, :, 25:] = 0.0                                 # the right side (x ≥ 12.5 mm) unseen
    quality[2, :18, :] = np.minimum(quality[2, :18, :], 0.25)   # frame 2's top rows (y < 9 mm) half-seen
    series = DisplacementSeries(np.zeros((3, 40, 40, 2), np.float32), quality, (0.5, 0.5))
    # 1.25 mm inside the left edge, 1.25 mm inside the top edge, 0.75 mm inside the right edge
    rest = np.array([[6.0, 10.0, 5.0], [10.0, 6.0, 5.0], [14.0, 10.0, 5.0]])
    points = np.stack([rest, rest, rest])
    plain = residuals_mm(points, data)
    assert plain == pytest.approx(np.tile([1.25, 1.25, 0.75], (2, 1)), abs=1e-9)
    weighted = residuals_mm(points, data.with_contour_weights(series, rest))
    assert weighted[0] == pytest.approx(plain[0] * [1.0, 1.0, 0.0], abs=1e-6)
    assert weighted[1] == pytest.approx(plain[1] * [1.0, 0.25, 0.0], abs=1e-6)
    unseen = DisplacementSeries(np.zeros((3, 40, 40, 2), np.float32), np.zeros((3, 40, 40), np.float32), (0.5, 0.5))
    with pytest.raises(InputError, match="quality"):
        data.with_contour_weights(unseen, rest)


@pytest.mark.slow
@pytest.mark.parametrize("final_particles", [300, 150])
def test_a_saved_calibration_runs_the_model_that_was_fitted(small_twin, tmp_path, final_particles):
    """``hifumotion predict CAL/`` must predict with the calibrated model itself: the same
    conforming voxel mesh, so the same motion as the calibration held in memory. The search
    runs on the search model's reduced model (its snapshots on the cluster), and a setting of
    the fast path given in the run's configuration reaches the model that was fitted and saved.
    With the final model at the search model's resolution (the calibration in seconds), the
    search model is the one saved."""
    from hifumotion.estimation.store import load_calibration
    from hifumotion.metrics import dice
    from hifumotion.observed import load_observed
    from hifumotion.prediction.pipeline import predict_calibrated
    from hifumotion.config import validate_config
    from hifumotion.workflow.pipeline import EstimationConfig, observe_and_calibrate

    folder, _ = small_twin
    observed = load_observed(folder / "observed")
    train, valid = default_frames(len(observed.frames))
    settings = validate_config(EstimationConfig, {
        "search_particles": 150, "max_evaluations": 1, "workers": 1, "search_integrator": "reduced",
        "resolution_check": final_particles == 150,
        "model": {"tissue_particles": final_particles, "creep": {"stick_mm": 0.02}}})
    observation, cal = observe_and_calibrate(observed, tmp_path / "cal", settings, train)
    if final_particles == 150:
        # the fit run again on twice the particles, frames 0 … the last training frame, both runs
        # from their own frame 0; in parameters.json as it was measured
        rc = cal.resolution
        assert rc["particles"][0] == len(cal.spec.tissue_mm) and rc["particles"][1] >= 300
        assert rc["spacing_mm"][1] < rc["spacing_mm"][0]
        assert len(rc["difference_mm"]) == max(train) + 1 and rc["difference_mm"][0] == 0.0
        assert rc["resolved"] == (rc["largest_mm"] <= rc["pixel_mm"]) and rc["pixel_mm"] == observed.pixel_mm
        written = json.loads((tmp_path / "cal" / "parameters.json").read_text())["fit"]["resolution_check"]
        assert written["largest_mm"] == pytest.approx(rc["largest_mm"])
        # and how far the finer model would move each coordinate of the fit: its numerical error,
        # in quadrature with the data's in the reported standard error
        assert set(rc["parameter_shift"]) == set(cal.std) == set(rc["std_data"])
        for c, shift in rc["parameter_shift"].items():
            assert cal.std[c] == pytest.approx(np.hypot(rc["std_data"][c], shift))
    else:
        assert cal.resolution is None
    spec, k, reference, _ = load_calibration(tmp_path / "cal")
    assert len(spec.tissue_mm) == len(cal.spec.tissue_mm)
    assert (len(cal.spec.tissue_mm) == len(cal.search_spec.tissue_mm)) == (final_particles == 150)
    assert cal.spec.settings.creep.stick_mm == spec.settings.creep.stick_mm == 0.02
    assert cal.search_spec.settings.integrator == "reduced" and cal.search_spec.settings.creep.stick_mm == 0.02
    # the reduced search: the search model's around the design's centre (two snapshot runs) and
    # its best start (from those and the full run there), again where a check disagrees, then,
    # if the final model is finer, the final model's own around the first optimum (two runs)
    record = cal.record.as_dict()
    assert record["name"] == "reduced_trust_region"
    centres, reductions = record["reduced_model_centres"], cal.timings_s["reductions"]
    assert len(centres) == len(reductions) >= (3 if final_particles == 300 else 2)
    assert cal.timings_s["reduced_model_s"] > 0
    assert reductions[0]["snapshots"] == 2 and reductions[1]["snapshots"] == 3
    if final_particles == 300:
        second = [r for r in reductions if r["snapshots"] == 2]
        assert len(second) == 2 and reductions.index(second[1]) > 1
    # the fit's check: the full model run at the fit, among every check the search made (a search
    # that did not leave its checked start, as a budget of one run makes it, adds none of its own)
    check = record["full_model_check"]
    assert check["cost_full_model_mm"] > 0 and check["cost_reduced_model_mm"] > 0
    made = check["rounds"] + (record["start_checks"] if final_particles == 150 else [])
    assert check["cost_full_model_mm"] == min(c["cost_full_model_mm"] for c in made)
    assert k.as_dict() == pytest.approx(cal.parameters.as_dict(), rel=1e-9)
    # the same mesh: the loaded model's voxels conform to the reconstructed surface as the fitted one's
    assert spec.voxels().nodes_mm.shape == cal.spec.voxels().nodes_mm.shape
    assert np.abs(spec.voxels().nodes_mm - cal.spec.voxels().nodes_mm).max() < 1e-4
    frames = [max(valid)]
    memory = predict_calibrated(cal.spec, cal.parameters, observation.reference_shape(), frames)
    saved = predict_calibrated(spec, k, reference, frames)
    motion = np.sqrt(np.mean(np.sum((memory.run.points_mm - memory.run.points_mm[:1]) ** 2, axis=-1)))
    assert motion > 0
    assert np.abs(saved.run.points_mm - memory.run.points_mm).max() < 1e-3 * motion
    assert dice(saved.masks[frames[0]], memory.masks[frames[0]]) > 0.999


def test_model_settings_pick_one_of_the_forward_models_and_keep_their_own_settings_through_json():
    from dataclasses import asdict

    from hifumotion.estimation.model import FORWARD_MODELS, ModelSettings

    assert set(FORWARD_MODELS) == {"implicit", "explicit", "reduced"}
    s = ModelSettings(integrator="reduced", creep={"tolerance": 0.01}, reduced={"max_modes": 12})
    again = ModelSettings(**json.loads(json.dumps(asdict(s))))   # as parameters.json holds them
    assert again == s and again.creep.tolerance == 0.01 and again.reduced.max_modes == 12
    with pytest.raises(InputError, match="integrator"):
        ModelSettings(integrator="implict")
    with pytest.raises(InputError, match="tolerence"):
        ModelSettings(creep={"tolerence": 0.01})
    with pytest.raises(InputError, match="reduced_span"):
        ModelSettings(reduced_span=(2.0, 0.5))


def test_a_fit_stopped_at_its_budget_or_refuted_by_its_check_reports_nothing_as_determined():
    """The standard errors of a search that stopped at its evaluation budget, or of a reduced
    model the full model's check refuted, do not say how well the data fix a parameter: no value
    is reported as determined, and the reason is given."""
    from hifumotion.estimation.calibrate import Calibration
    from hifumotion.estimation.fit import FitResult
    from hifumotion.estimation.model import Parameters
    from hifumotion.estimation.strategies import Check, SpaceMappingRecord, TrustRegionRecord

    names = ("log_E", "nu", "log_beta1", "beta2")
    search = FitResult(np.zeros(4), np.zeros((2, 3)), "least_squares", 8, 40, [], "`ftol` termination", True)
    cal = Calibration(Parameters(), {n: 0.01 for n in names}, {n: True for n in names}, [20], search, None,
                      SpaceMappingRecord(), [], [], None, None, None, 40)
    assert cal.caveats() == [] and cal.report()["poisson_ratio"]["determined"]
    search.converged, search.message = False, "The maximum number of function evaluations is exceeded."
    assert "budget" in cal.caveats()[0]
    assert not any(entry["determined"] for entry in cal.report().values())
    search.converged = True
    # a check whose full model's cost is 3× the reduced model's, which disagree
    cal.record = TrustRegionRecord(fit_check=Check(np.zeros(4), np.full((2, 5), 1.0), np.full((2, 5), 3.0), False))
    assert "3.00×" in cal.caveats()[0] and not cal.report()["beta2"]["determined"]


def test_a_coordinate_fitted_on_its_search_bound_is_not_determined():
    """At a bound the minimum is the bound's, not the data's: however small its local error, ν
    fitted at 0.495 (the bound) is not reported as determined; the same ν inside is."""
    truth = Parameters(0.25, 9000.0, 0.43, 2e5, 0.5)
    ev = AnalyticEvaluator(truth)
    inside = ev.space.theta(truth)
    assert uncertainty(ev, inside).determined["nu"] and not uncertainty(ev, inside).at_bound["nu"]
    on_bound = inside.copy()
    on_bound[1] = ev.space.upper[1]
    unc = uncertainty(ev, on_bound)
    assert unc.at_bound["nu"] and not unc.determined["nu"]
    assert unc.std[1] < 0.05                    # small by the errors alone: the bound is what decides
    assert not any(unc.at_bound[n] for n in ("log_E", "log_beta1", "beta2"))   # only ν is on a bound



@pytest.mark.slow
def test_a_saved_calibration_carries_the_online_models_runs(small_twin, tmp_path, monkeypatch):
    """The calibration runs the online loop's reduced model's two full runs over the whole series
    and saves them: loaded (or held in memory, as ``hifumotion run`` holds it), the model's reduced
    model is made from them, with no full run, and they are the runs the spec's own snapshot
    scenes give when run afresh here."""
    import hifumotion.reduced.build as build
    from hifumotion.config import validate_config
    from hifumotion.creep.scene_run import snapshot_run
    from hifumotion.estimation.store import load_calibration, read_reduced_snapshots
    from hifumotion.observed import load_observed
    from hifumotion.workflow.pipeline import EstimationConfig, observe_and_calibrate

    folder, _ = small_twin
    observed = load_observed(folder / "observed")
    n = len(observed.frames)
    train, _ = default_frames(n)
    settings = validate_config(EstimationConfig, {"search_particles": 150, "max_evaluations": 1, "workers": 1,
                                                  "search_integrator": "reduced", "particles": 150})
    _, cal = observe_and_calibrate(observed, tmp_path / "cal", settings, train)
    saved = cal.online_snapshots
    assert saved is not None and saved.last_frame == n - 1 and len(saved.runs) == 2
    assert all(len(r.times_s) == n for r in saved.runs)          # frames 0 … n − 1, the whole series
    written = json.loads((tmp_path / "cal" / "parameters.json").read_text())
    assert written["online_model"]["last_frame"] == n - 1 and written["online_model"]["runs"] == 2
    assert "online_model_s" in written["timings_s"]

    spec, k, _, _ = load_calibration(tmp_path / "cal")
    # the runs afresh, in this process: the spec's snapshot scenes around the fit, to the last frame
    fresh = [snapshot_run(scene, spec.voxels(), spec.tissue_volume_mm3, spec.settings.creep)
             for scene in spec.snapshot_scenes(k, n - 1)]
    read = read_reduced_snapshots(tmp_path / "cal" / "model" / "reduced_snapshots.npz")
    for a, b in zip(read.runs, fresh):
        assert np.allclose(a.times_s, b.times_s)
        assert np.abs(a.nodes_mm - b.nodes_mm).max() < 1e-6 * max(1.0, np.abs(b.nodes_mm - b.nodes_mm[:1]).max())
        assert np.abs(a.advance_mm - b.advance_mm).max() < 1e-6
    # loaded, the reduced model comes from the saved runs: no full run is made for it
    monkeypatch.setattr(build, "snapshot_run", lambda *a, **kw: pytest.fail("a full run was made"))
    model = spec.reduced(k, n - 1)
    assert cal.spec.reduced(cal.parameters, n - 1).basis.size == model.basis.size   # and so is the one in memory
    reference = build.reduced_from_runs(spec.snapshot_scenes(k, n - 1)[0], spec.voxels(), fresh,
                                        spec.settings.reduced, spec.settings.creep)
    assert model.basis.size == reference.basis.size
    assert np.allclose(model.basis.singular_values, reference.basis.singular_values, rtol=1e-6)
    # asked for other parameters, or beyond the runs' last frame, it is not theirs: it makes its own
    with pytest.raises(pytest.fail.Exception, match="a full run was made"):
        spec.reduced(k.replaced(youngs_modulus_pa=2 * k.youngs_modulus_pa), n - 1)


def test_saved_online_runs_that_are_not_whole_are_refused_by_name(tmp_path):
    from hifumotion.creep.integrate import CreepResult
    from hifumotion.estimation.model import ReducedSnapshots
    from hifumotion.estimation.store import read_reduced_snapshots, write_reduced_snapshots

    t = np.linspace(0.0, 1.0, 5)
    nodes = np.random.default_rng(0).random((5, 7, 3))
    run = CreepResult(t, nodes, np.zeros((5, 0, 3)), t * 0.1, t * 0.0, {"advance_at_rest_mm": 0.01, "steps": 3})
    path = tmp_path / "reduced_snapshots.npz"
    write_reduced_snapshots(path, ReducedSnapshots(Parameters(), 4, (run, run)))
    back = read_reduced_snapshots(path)          # a round trip keeps every number
    assert back.made_at == Parameters() and back.last_frame == 4 and len(back.runs) == 2
    assert np.array_equal(back.runs[1].nodes_mm, nodes) and back.runs[0].stats["steps"] == 3
    path.write_bytes(path.read_bytes()[:200])     # truncated
    with pytest.raises(InputError, match="unreadable reduced model's runs") as err:
        read_reduced_snapshots(path)
    assert str(path) in str(err.value) or err.value.args[-1] == path
    bad = CreepResult(t, nodes[:4], np.zeros((5, 0, 3)), t, t, {})      # a frame short
    write_reduced_snapshots(path, ReducedSnapshots(Parameters(), 4, (bad,)))
    with pytest.raises(InputError, match="one finite motion per frame"):
        read_reduced_snapshots(path)
    write_reduced_snapshots(path, ReducedSnapshots(Parameters(), 4, ()))          # no run at all
    with pytest.raises(InputError, match="malformed reduced model's runs"):
        read_reduced_snapshots(path)
    path.unlink()
    os.mkfifo(path)                               # refused at once, not waited on
    with pytest.raises(InputError, match="not a regular file"):
        read_reduced_snapshots(path)
