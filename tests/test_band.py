"""The aim's band: the least determined direction of a covariance, against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from hifumotion.errors import InputError
from hifumotion.estimation.fit import RELEVANCE
from hifumotion.estimation.space import SearchSpace
from hifumotion.prediction.band import covariance_from_calibration, least_determined_step

NAMES = ["log_E", "nu", "log_beta1", "beta2"]
SPACE = SearchSpace()
REL = np.array([RELEVANCE[n] for n in NAMES])


def _cov(std, corr=None):
    return {"coordinates": NAMES, "std": list(std), "matrix": (np.eye(4) if corr is None else corr).tolist()}


def test_uncorrelated_errors_step_along_the_one_largest_for_its_relevance():
    # ν's error is 3 of its relevance scales, the others' 1 or 2: the step is ν's standard error
    std = REL * np.array([2.0, 3.0, 1.0, 0.5])
    step = least_determined_step(_cov(std), SPACE.lower, SPACE.upper)
    assert abs(step[1]) == pytest.approx(std[1], rel=1e-12)
    assert np.allclose(np.delete(step, 1), 0.0, atol=1e-12)


def test_a_correlated_pair_steps_along_its_diagonal_by_the_closed_form():
    # β1 and β2 each 3 relevance scales, correlated ρ: in relevance units the pair's covariance is
    # 9·[[1, ρ], [ρ, 1]], whose largest eigenvalue 9(1 + ρ) has the eigenvector (1, 1)/√2
    rho = 0.5
    std = REL * np.array([1.0, 1.0, 3.0, 3.0])
    corr = np.eye(4)
    corr[2, 3] = corr[3, 2] = rho
    step = least_determined_step(_cov(std, corr), SPACE.lower, SPACE.upper)
    expected = np.sqrt(9 * (1 + rho) / 2) * REL[2:]
    assert np.abs(step[2:]) == pytest.approx(expected, rel=1e-12)
    assert np.sign(step[2]) == np.sign(step[3]) and np.allclose(step[:2], 0.0, atol=1e-12)
    # anti-correlated: the same length along the other diagonal
    corr[2, 3] = corr[3, 2] = -rho
    step = least_determined_step(_cov(std, corr), SPACE.lower, SPACE.upper)
    assert np.abs(step[2:]) == pytest.approx(expected, rel=1e-12) and np.sign(step[2]) != np.sign(step[3])


def test_an_error_no_data_bound_counts_as_half_its_search_range():
    std = [0.01, None, 0.01, 0.01]
    step = least_determined_step(_cov(std), SPACE.lower, SPACE.upper)
    assert abs(step[1]) == pytest.approx(0.5 * (SPACE.upper[1] - SPACE.lower[1]), rel=1e-12)


def test_a_calibration_without_the_covariance_is_refused_naming_it():
    with pytest.raises(InputError, match="correlation"):
        least_determined_step({"coordinates": NAMES, "matrix": np.eye(4).tolist()}, SPACE.lower, SPACE.upper)
    with pytest.raises(InputError, match="correlation"):
        least_determined_step(_cov([0.1] * 4, np.eye(3)), SPACE.lower, SPACE.upper)


def test_older_calibrations_give_the_coordinates_errors_from_the_parameters():
    meta = {"parameters": {"youngs_modulus_pa": {"value": 4000.0, "std": 2000.0},
                           "poisson_ratio": {"value": 0.45, "std": 0.03},
                           "beta1_pa_s_pow": {"value": 4e5, "std": None},
                           "beta2": {"value": 0.6, "std": 0.1}},
            "fit": {"correlation": {"coordinates": NAMES, "matrix": np.eye(4).tolist()}}}
    cov = covariance_from_calibration(meta)
    assert cov["std"] == [pytest.approx(0.5), 0.03, None, 0.1]


@pytest.mark.parametrize("bad", [
    {"coordinates": NAMES, "std": ["a", 1, 1, 1], "matrix": np.eye(4).tolist()},
    {"coordinates": NAMES, "std": [0.1] * 4, "matrix": [["x"] * 4] * 4},
    {"coordinates": ["log_E", "nu", "log_beta1", "colour"], "std": [0.1] * 4, "matrix": np.eye(4).tolist()},
    {"coordinates": "log_E", "std": 3, "matrix": 1},
])
def test_a_hand_edited_covariance_is_one_error_naming_it(bad):
    with pytest.raises(InputError, match="correlation"):
        least_determined_step(bad, SPACE.lower, SPACE.upper)


def test_a_hand_edited_calibration_gives_no_covariance_rather_than_a_crash():
    for meta in ({"fit": "none"}, {"fit": {"correlation": [1, 2]}}, []):
        cov = covariance_from_calibration(meta)
        assert cov == {} or cov.get("coordinates") is None
        with pytest.raises(InputError, match="correlation"):
            least_determined_step(cov, SPACE.lower, SPACE.upper)
    # parameters without their errors: every coordinate unbounded, so the step is half the widest
    # search range in relevance units (ln β1's: 10² … 10⁸)
    cov = covariance_from_calibration({"parameters": 3, "fit": {"correlation": {
        "coordinates": NAMES, "matrix": np.eye(4).tolist()}}})
    assert cov["std"] == [None] * 4
    step = least_determined_step(cov, SPACE.lower, SPACE.upper)
    assert abs(step[2]) == pytest.approx(0.5 * (SPACE.upper[2] - SPACE.lower[2]), rel=1e-12)
