"""The report's statements about the online loop, from errors set by hand."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from hifumotion.report.build import online_against_holding
from hifumotion.report.figures import latency_axis_ms


def test_one_stall_is_counted_not_drawn_as_the_histograms_range():
    latency = np.r_[np.full(500, 12.0) + np.linspace(0, 4, 500), 2350.0]
    upper, beyond, largest = latency_axis_ms(latency)
    assert 15.0 <= upper < 100.0          # the frames' own spread, not the stall's
    assert beyond == 1 and largest == 2350.0
    assert latency_axis_ms(np.full(10, 20.0))[1] == 0


def _loop(filter_mm: dict, hold_mm: dict):
    return SimpleNamespace(predicted_mm={k: None for k in filter_mm}, frame_interval_s=0.05,
                           errors_mm=lambda k, truth=None: np.asarray(filter_mm[k]),
                           hold_errors_mm=lambda k, truth=None: np.asarray(hold_mm[k]))


def test_the_report_says_where_holding_still_beats_the_online_filter():
    both = online_against_holding(_loop({4: [0.1, 0.2], 6: [0.5, np.nan]}, {4: [0.3, 0.3], 6: [0.2, 0.2]}), None)
    assert "closer than holding still at 200 ms (0.150 against 0.300 mm)" in both
    assert "holding still is as close or closer at 300 ms (0.500 against 0.200 mm)" in both
    assert "tracked sections" in both
    never = online_against_holding(_loop({4: [0.4]}, {4: [0.3]}), np.zeros((3, 2)))
    assert never.startswith("Against the truth, holding still is as close as the filter or closer at every horizon")


def test_the_true_push_is_drawn_as_a_multiple_of_what_the_calibration_saw():
    """A push announced as a ramp and hold, raised 1.8× unannounced: over the announced shape and
    relative to the last training frame, the true push is 1 until the change and 1.8 after it;
    undefined before the push starts."""
    from hifumotion.report.build import relative_push

    t = np.arange(200) * 0.05
    announced = np.minimum(t / 0.5, 1.0)
    true = 0.45 * announced * np.where(t >= 6.6, 1.8, 1.0)
    ratio = relative_push(true, announced, 100)
    assert np.isnan(ratio[0])
    np.testing.assert_allclose(ratio[1:132], 1.0)
    np.testing.assert_allclose(ratio[132:], 1.8)
