"""The fit against the fit on the earlier training frames: a determined value that moves by more
than the earlier fit's errors allow is not determined.

Truths known without the code: ordinary least squares on a straight line in time, whose
standard errors are exact under independent Gaussian noise — so a correctly specified model
must pass the check (nearly always), and a curved motion fitted by a straight line (a model-form
error every frame shares, which no frame's scatter shows) must fail it."""

from __future__ import annotations

import numpy as np
import pytest

from hifumotion.estimation.calibrate import Calibration
from hifumotion.estimation.model import Parameters
from hifumotion.estimation.stability import LIMIT_SIGMA, holdout_shift
from hifumotion.estimation.strategies import SpaceMappingRecord


def _ols(t: np.ndarray, y: np.ndarray) -> tuple[dict, dict]:
    """Slope and intercept of a straight line by least squares, with their exact standard errors."""
    a = np.stack([np.ones_like(t), t], axis=1)
    coef, res, *_ = np.linalg.lstsq(a, y, rcond=None)
    s2 = float(res[0]) / (len(t) - 2)
    std = np.sqrt(np.diag(s2 * np.linalg.inv(a.T @ a)))
    return {"c0": coef[0], "slope": coef[1]}, {"c0": std[0], "slope": std[1]}


def _shift_of(y_of_t, rng, n: int = 40, noise: float = 0.05):
    t = np.linspace(0.0, 1.0, n)
    y = y_of_t(t) + rng.normal(0.0, noise, n)
    early = slice(0, int(0.75 * n))
    theta, _ = _ols(t, y)
    theta_e, std_e = _ols(t[early], y[early])
    return holdout_shift(theta, theta_e, std_e, range(int(0.75 * n)))


def test_a_correct_model_keeps_its_values_when_the_last_frames_are_added():
    rng = np.random.default_rng(3)
    flagged = sum(bool(_shift_of(lambda t: 1.0 + 2.0 * t, rng).moved) for _ in range(500))
    # |θ_earlier − θ_all| has a smaller spread than σ_earlier: beyond 3 σ is rarer than 0.27 % a
    # coordinate; two coordinates, 500 fits
    assert flagged <= 3


def test_a_shared_model_form_error_moves_the_fit_beyond_its_errors():
    rng = np.random.default_rng(4)
    shifts = [_shift_of(lambda t: 1.0 + 2.0 * t + 3.0 * t ** 2, rng) for _ in range(50)]
    assert all("slope" in s.moved for s in shifts)
    assert min(s.shift_sigma["slope"] for s in shifts) > LIMIT_SIGMA


def test_an_earlier_fit_no_data_bound_refutes_nothing():
    s = holdout_shift({"nu": 0.45, "beta2": 0.9}, {"nu": 0.30, "beta2": 0.2}, {"nu": np.inf, "beta2": 0.0},
                      [20, 30, 40])
    assert s.shift_sigma["nu"] == 0.0 and s.moved == ["beta2"]
    with pytest.raises(ValueError):
        holdout_shift({"nu": 0.4}, {"beta2": 0.5}, {"beta2": 0.1}, [20])


def _calibration(nu: float, std_nu: float, frames) -> Calibration:
    k = Parameters(force_n=0.25, youngs_modulus_pa=1.0e4, poisson_ratio=nu, beta1=5.0e5, beta2=0.5)
    std = {"log_E": 0.01, "nu": std_nu, "log_beta1": np.inf, "beta2": np.inf}
    determined = {"log_E": True, "nu": True, "log_beta1": False, "beta2": False}
    return Calibration(k, std, determined, list(frames), None, None, SpaceMappingRecord(), [], [], None, None, None, 0)


def test_the_report_says_a_moved_value_is_not_determined_and_why():
    fit = _calibration(0.448, 0.006, range(20, 101, 10))
    assert fit.report()["poisson_ratio"]["determined"]
    shift = fit.compare_with_earlier(_calibration(0.480, 0.008, range(20, 81, 10)))
    assert shift.moved == ["nu"] and shift.shift_sigma["nu"] == pytest.approx(4.0)
    report = fit.report()
    assert not report["poisson_ratio"]["determined"]
    assert "20–80" in report["poisson_ratio"]["not_determined_because"]
    assert report["force_over_youngs_m2"]["determined"]      # E did not move: still determined


def test_the_report_says_which_value_moved_and_why():
    from types import SimpleNamespace

    from hifumotion.report.build import _parameter_parts

    fit = _calibration(0.448, 0.006, range(20, 101, 10))
    quiet = " ".join(_parameter_parts(SimpleNamespace(calibration=fit, truth_parameters=None)))
    assert "whatever its standard error says" not in quiet
    fit.compare_with_earlier(_calibration(0.480, 0.008, range(20, 81, 10)))
    told = " ".join(_parameter_parts(SimpleNamespace(calibration=fit, truth_parameters=None)))
    assert "whatever its standard error says: ν: it moves 4.0 standard errors" in told


def test_the_step_to_another_models_fit_is_that_models_least_squares_fit():
    """Linear residuals r(θ) = Aθ − b: at the fit to b, the Gauss–Newton step on another model's
    residuals (b′) lands on the least-squares fit to b′ — exactly, the model being linear."""
    from hifumotion.estimation.resolution import parameter_shift

    rng = np.random.default_rng(5)
    a = rng.normal(size=(60, 3))
    b, b2 = rng.normal(size=60), rng.normal(size=60)
    here = np.linalg.lstsq(a, b, rcond=None)[0]
    there = np.linalg.lstsq(a, b2, rcond=None)[0]
    step = parameter_shift(a, (a @ here - b).reshape(6, 10), (a @ here - b2).reshape(6, 10))
    np.testing.assert_allclose(here + step, there, atol=1e-12)
    with pytest.raises(ValueError):
        parameter_shift(a, np.zeros(59), np.zeros(59))


def test_the_models_numerical_error_joins_the_datas_in_quadrature():
    from hifumotion.estimation.resolution import ResolutionCheck

    check = ResolutionCheck((1000, 2000), (2.0, 1.6), np.zeros(3), 0.3, 2,
                            parameter_shift={"nu": -0.008, "log_E": 0.02, "beta2": np.inf})
    std = check.with_numerical_error({"nu": 0.006, "log_E": 0.01, "beta2": np.inf, "log_beta1": 0.3})
    assert std["nu"] == pytest.approx(0.010)                     # 3-4-5
    assert std["log_E"] == pytest.approx(np.hypot(0.01, 0.02))
    assert std["beta2"] == np.inf and std["log_beta1"] == 0.3     # no shift: the data's alone
