"""The product's choice of predictor on a temporal hold-out of the training frames.

Truths: a disc that moves exactly with the drive (a regression on the drive must win, and the
held-out frames must be the last ones), a disc that stands still (holding still is as good as
anything), and a perfect physics (the physics must win)."""

import numpy as np
import pytest

from hifumotion.errors import InputError
from hifumotion.prediction.choice import holdout_split, rank_on_holdout
from hifumotion.prediction.evaluate import evaluate

DT, PIXEL = 0.05, 0.1


def disc(centre_xy_px, radius_px=14, shape=(80, 200)):
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    return (xx - centre_xy_px[0]) ** 2 + (yy - centre_xy_px[1]) ** 2 <= radius_px ** 2


def sliding(n=200):
    t = np.arange(n) * DT
    travel = np.interp(t, [0.0, 3.0, 6.0, 10.0], [0.0, 1.0, 5.0, 5.0])    # a drive that speeds up, then stops
    x_px = 40 + 1.0 * travel / PIXEL                                        # 1 mm of motion per mm of travel
    return travel, {f: disc((x_px[f], 40)) for f in range(n)}, x_px


def test_the_held_out_frames_are_the_last_quarter():
    fit, held = holdout_split(range(20, 101, 10))
    # the frames between the held-out training frames are observed too
    assert fit == [20, 30, 40, 50, 60, 70, 80] and held == list(range(81, 101))
    with pytest.raises(InputError, match="training_frames"):
        holdout_split([20, 30, 40])


def test_a_target_that_moves_with_the_drive_is_given_to_the_regression():
    travel, tracked, _ = sliding()
    r = rank_on_holdout(tracked, range(20, 101, 5), travel, DT, PIXEL)
    assert r.winner in ("drive_static", "drive_lagged")
    # the drive speeds up inside the held-out frames: holding still and constant velocity miss it
    assert r.centroid_mm["no_motion"] > 5 * r.centroid_mm[r.winner]
    assert r.centroid_mm["kalman"] > 2 * r.centroid_mm[r.winner]
    assert "regression on the drive" in r.sentence()


def test_a_perfect_physics_wins_and_a_still_target_makes_no_winner_of_anything():
    travel, tracked, _ = sliding()
    training = list(range(20, 101, 5))
    _, held = holdout_split(training)
    r = rank_on_holdout(tracked, training, travel, DT, PIXEL, physics={f: tracked[f] for f in held})
    assert r.winner == "physics" and r.centroid_mm["physics"] == 0.0
    still = {f: disc((60, 40)) for f in range(200)}
    r = rank_on_holdout(still, training, travel, DT, PIXEL)
    assert r.centroid_mm["no_motion"] == 0.0
    assert all(r.as_good(m) for m in r.centroid_mm if r.centroid_mm[m] < 0.05)


def test_evaluate_scores_the_choice_beside_the_best_on_the_validation_frames():
    from types import SimpleNamespace

    travel, tracked, x_px = sliding()
    training, validation = list(range(20, 101, 5)), list(range(110, 191, 10))
    # a physics that lags 0.5 mm behind the truth: the regression on the drive is better
    pred = SimpleNamespace(pixel_mm=PIXEL, masks={f: disc((x_px[f] - 5, 40)) for f in range(200)})
    fit, held = holdout_split(training)
    choice = rank_on_holdout(tracked, training, travel, DT, PIXEL, physics={f: pred.masks[f] for f in fit + held})
    stack = np.stack([tracked[f] for f in range(200)])
    ev = evaluate(pred, None, None, stack, stack.astype(float), tracked, training, validation, DT,
                  program=travel, choice=choice)
    c = ev.physics["choice"]
    # every predictor that follows the drive, or the physics' motion from the last seen frame, is
    # exact here; the physics itself lags by 0.5 mm
    exact = ("drive_static", "drive_lagged", "physics_anchored", "physics_corrected")
    assert c["chosen"] in exact
    assert c["validation"]["centroid_mean_mm"] < 0.1 < ev.physics["validation"]["centroid_mean_mm"]
    # whichever of them was chosen is within a tenth of a pixel of the best
    assert c["excess_over_best_mm"] <= 0.1 * PIXEL
    assert ev.physics["ranking"][0]["method"] in exact
    assert "better than" in ev.physics["verdict"]
    # the physics' constant 0.5 mm miss on the training frames is taken out by its correction
    assert ev.baselines["physics_corrected"]["centroid_mean_mm"] < 0.05
    assert ev.baselines["physics_corrected"]["fit"]["coefficients"][0][0] == pytest.approx(0.5, abs=0.05)
    # anchored on the last tracked frame, the lagging physics' motion is the truth's
    assert ev.baselines["physics_anchored"]["centroid_mean_mm"] < 0.05


def test_a_hold_out_that_does_not_move_leaves_the_choice_with_the_physics():
    # the drive is drawn back over the held-out frames while the sample stays: holding still is
    # exact there, and says nothing of what comes when the drive moves it again
    travel = np.interp(np.arange(200) * DT, [0.0, 4.0, 5.5, 9.0], [0.0, 4.0, 2.5, 7.0])
    x_px = 40 + np.interp(np.arange(200), [0, 80, 133, 180], [0, 65, 65, 103])
    tracked = {f: disc((x_px[f], 40)) for f in range(200)}
    training = list(range(20, 101, 5))
    fit, held = holdout_split(training)
    physics = {f: disc((x_px[f] + 1, 40)) for f in fit + held}      # a tenth of a mm off, moving as the truth
    r = rank_on_holdout(tracked, training, travel, DT, PIXEL, physics=physics)
    assert r.order[0] == "no_motion" and r.held_motion_mm < r.resolved_mm
    assert r.winner == "physics" and "cannot rank the predictors" in r.sentence()
    # the same physics where the held-out frames move: the held-out best wins as before
    moving = {f: disc((40 + 0.5 * f, 40)) for f in range(200)}
    r = rank_on_holdout(moving, training, travel, DT, PIXEL, physics={f: moving[f] for f in fit + held})
    assert r.informative and r.winner == r.order[0]
