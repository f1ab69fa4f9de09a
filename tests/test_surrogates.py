"""The drive surrogates: the target's motion regressed on the push's known program.

Truths independent of the code: a first-order lag's closed form under a ramp and a step, the
exact coefficients of a motion built from them, a disc translated by a known amount, and the
batch least-squares solution the recursive one must reach.
"""

import numpy as np
import pytest

from hifumotion.errors import InputError
from hifumotion.observed.setup import PushSchedule
from hifumotion.prediction.surrogates import (OnlineDriveRegression, drive_regression_predict,
                                              fit_drive_regression, lagged_program, online_drive_regression,
                                              shift_mask)

DT = 0.05


def ramp_then_hold(n=200, rate=0.8, stop_s=7.0):
    t = np.arange(n) * DT
    return t, rate * np.minimum(t, stop_s)


def test_the_lag_of_a_ramp_and_of_a_step_is_the_closed_form():
    # τ v' = u − v, v(0) = u(0): a ramp r·t gives r(t − τ(1 − e^{−t/τ})); a step of height 1 at
    # t = 0⁺ after rest at 0 gives 1 − e^{−t/τ} (sampled, the step is a ramp over one frame)
    tau, r = 0.7, 0.8
    t = np.arange(300) * DT
    v = lagged_program(r * t, DT, tau)
    np.testing.assert_allclose(v, r * (t - tau * (1 - np.exp(-t / tau))), atol=1e-12)
    # a held value after the ramp decays to it as e^{−(t − t_stop)/τ}
    t, u = ramp_then_hold()
    v = lagged_program(u, DT, tau)
    after = t >= 7.0
    lag_at_stop = r * tau * (1 - np.exp(-7.0 / tau))
    np.testing.assert_allclose(v[after], u[after] - lag_at_stop * np.exp(-(t[after] - 7.0) / tau), atol=1e-12)


def test_a_motion_made_of_the_program_and_its_lag_is_recovered_exactly():
    t, u = ramp_then_hold()
    tau = 0.9
    v = lagged_program(u, DT, tau)
    truth = np.stack([4.0 + 0.3 * u + 0.5 * v, 12.0 - 0.2 * u + 0.25 * v], axis=1)
    frames = np.arange(20, 101)
    fit = fit_drive_regression(truth[frames], frames, u, DT, lagged=True)
    assert fit.lag_s == pytest.approx(tau, rel=1e-3)
    np.testing.assert_allclose(fit.coefficients, [[4.0, 12.0], [0.3, -0.2], [0.5, 0.25]], atol=1e-3)
    # it predicts the frames it never saw, past the drive's stop at 7 s
    np.testing.assert_allclose(fit.centroids_mm(u, DT)[101:], truth[101:], atol=1e-3)
    # the static regression cannot: the lag keeps moving the target after the drive has stopped
    static = fit_drive_regression(truth[frames], frames, u, DT, lagged=False)
    assert static.lag_s is None
    assert np.abs(static.centroids_mm(u, DT)[150:] - truth[150:]).max() > 0.1


def test_the_static_regression_is_exact_on_a_target_that_moves_with_the_drive():
    t, u = ramp_then_hold()
    truth = np.stack([2.0 + 0.7 * u, 5.0 - 0.1 * u], axis=1)
    frames = np.arange(20, 101)
    fit = fit_drive_regression(truth[frames], frames, u, DT)
    np.testing.assert_allclose(fit.coefficients, [[2.0, 5.0], [0.7, -0.1]], atol=1e-10)
    assert fit.residual_rms_mm < 1e-10


def disc(shape, centre_xy_px, radius_px):
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    return (xx - centre_xy_px[0]) ** 2 + (yy - centre_xy_px[1]) ** 2 <= radius_px ** 2


def test_the_predicted_masks_are_the_last_seen_one_moved_by_the_regression():
    # a disc slides along x with the drive (0.5 mm per mm of travel) at 0.1 mm pixels
    pixel = 0.1
    t, u = ramp_then_hold()
    x_px = 40 + 0.5 * u / pixel
    observed = {f: disc((80, 160), (x_px[f], 40), 15) for f in range(0, 101, 5)}
    masks, fit = drive_regression_predict(observed, [150, 190], u, DT, pixel)
    assert fit.coefficients[1, 0] == pytest.approx(0.5, abs=0.01)
    for f in (150, 190):
        from hifumotion.metrics import centroid

        # the pixel grid rounds each disc's centroid by a fraction of a pixel: the fit carries that
        assert centroid(masks[f], pixel)[0] == pytest.approx(x_px[f] * pixel, abs=0.3 * pixel)


def test_shift_mask_moves_by_subpixel_amounts():
    from hifumotion.metrics import centroid

    m = disc((60, 60), (30, 30), 10)
    moved = shift_mask(m, (0.25, -0.5), 0.1)          # 2.5 px right, 5 px up
    np.testing.assert_allclose(np.subtract(centroid(moved, 0.1), centroid(m, 0.1)), (0.25, -0.5), atol=0.02)
    # below half a pixel: a lobed section's centroid follows the asked shift, not the pixel grid
    yy, xx = np.mgrid[:90, :90]
    lobed = np.hypot(xx - 45.3, yy - 44.6) <= 16 + 3 * np.cos(3 * np.arctan2(yy - 44.6, xx - 45.3))
    for shift_px in (0.15, 0.3, 0.45):
        moved = np.subtract(centroid(shift_mask(lobed, (shift_px, -0.5 * shift_px), 1.0), 1.0), centroid(lobed, 1.0))
        np.testing.assert_allclose(moved, (shift_px, -0.5 * shift_px), atol=0.1)


def test_recursive_least_squares_without_forgetting_is_the_batch_fit():
    rng = np.random.default_rng(3)
    t, u = ramp_then_hold()
    c = np.stack([1.0 + 0.4 * u, -2.0 + 0.3 * u], axis=1) + rng.normal(0, 0.05, (len(u), 2))
    reg = OnlineDriveRegression(u, DT, memory_s=1e12, lagged=False)
    for f in range(121):
        reg.update(f, c[f])
    batch = fit_drive_regression(c[:121], np.arange(121), u, DT)
    # equal but for the weak prior that keeps the first frames' solves defined (10⁻⁶ of the program²)
    np.testing.assert_allclose(reg.members[0].theta, batch.coefficients, atol=1e-5)
    assert not np.allclose(reg.members[0].theta, 0.0)


def test_the_online_surrogate_follows_a_lagged_response_and_is_causal():
    t, u = ramp_then_hold()
    v = lagged_program(u, DT, 0.6)
    c = np.stack([3.0 + 0.2 * u + 0.6 * v, 0.1 * u], axis=1)
    aims = online_drive_regression(c, u, DT, [6], memory_s=4.0)[6]
    err = np.linalg.norm(aims[:-6] - c[6:], axis=1)
    hold = np.linalg.norm(c[:-6] - c[6:], axis=1)
    # after the first seconds it aims far closer than holding still, through the drive's stop
    assert np.mean(err[60:]) < 0.1 * np.mean(hold[60:])
    # causal: a change to the frames after t leaves the aim made at t as it was
    later = c.copy()
    later[101:] += 5.0
    again = online_drive_regression(later, u, DT, [6], memory_s=4.0)[6]
    np.testing.assert_array_equal(again[:101], aims[:101])


def test_the_program_of_each_push_shape():
    travel = PushSchedule(control="travel", shape="piecewise_linear", times_s=[0.0, 7.0, 10.0],
                          travel_mm=[0.0, 6.0, 6.0])
    np.testing.assert_allclose(travel.program([0.0, 3.5, 7.0, 12.0]), [0.0, 3.0, 6.0, 6.0])
    ramp = PushSchedule(shape="ramp_hold", ramp_s=2.0)
    np.testing.assert_allclose(ramp.program([0.0, 1.0, 2.0, 5.0]), [0.0, 0.5, 1.0, 1.0])
    force = PushSchedule(shape="piecewise_linear", times_s=[0.0, 1.0, 3.0], relative_force=[0.0, 1.0, 0.5])
    np.testing.assert_allclose(force.program([0.5, 2.0, 9.0]), [0.5, 0.75, 0.5])


def test_bad_inputs_are_named():
    t, u = ramp_then_hold()
    with pytest.raises(InputError, match="centroids_mm"):
        fit_drive_regression(np.zeros((1, 2)), [3], u, DT)
    with pytest.raises(InputError, match="frames"):
        fit_drive_regression(np.zeros((2, 2)), [3, 500], u, DT)
    with pytest.raises(InputError, match="program"):
        OnlineDriveRegression(np.array([0.0, np.nan, 1.0]), DT, 1.0)
    reg = OnlineDriveRegression(u, DT, 1.0)
    reg.update(4, (0.0, 0.0))
    with pytest.raises(InputError, match="increase"):
        reg.update(4, (0.0, 0.0))
