"""The incremental :class:`SafetyStage`: one chunk is exactly ``apply_safety``; any chunking stays safe."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_safety_properties import TOL, _spans, assert_safe, cases

from robogest.errors import InputError, SafetyError
from robogest.safety import SafetyStage, apply_safety, rest_reach_time_s


def _chunked(case: dict, cuts: list[int]) -> np.ndarray:
    q, silent = case["q"], case["silent"]
    stage = SafetyStage(case["limits"], case["fps"], case["config"], case["q0"])
    edges = [0, *sorted(c % (q.shape[0] + 1) for c in cuts), q.shape[0]]
    parts = [stage.extend(q[a:b], silent[a:b]) for a, b in itertools.pairwise(edges)]
    return np.vstack([*parts, stage.finish()])


@settings(deadline=None, max_examples=120, suppress_health_check=[HealthCheck.too_slow])
@given(cases(), st.lists(st.integers(0, 10_000), max_size=6))
def test_any_chunking_is_safe_and_rests_in_long_silences(case, cuts):
    q, limits, fps, silent, config = case["q"], case["limits"], case["fps"], case["silent"], case["config"]
    out = _chunked(case, cuts)
    n_t = q.shape[0]
    q0 = limits.rest_q_rad if case["q0"] is None else case["q0"]
    assert out.shape[0] >= max(n_t, 1)
    assert_safe(out, limits, fps, q0, config.margin_rad)
    assert np.all(np.abs(out[-1] - limits.rest_q_rad) <= TOL)
    for a, b in _spans(silent, fps, config.rest_after_s):
        reach = rest_reach_time_s(out[a], limits, fps)
        for k in range(a, b):
            if k >= a + reach * fps - 1e-9 and (b == n_t or k / fps + 1e-9 < b / fps - config.rest_leave_s):
                assert np.all(np.abs(out[k] - limits.rest_q_rad) <= TOL), f"frame {k} of span {a}:{b} not at rest"
                assert np.all(np.abs(out[k] - out[k - 1]) <= TOL), f"frame {k} of span {a}:{b} moving"


@settings(deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_one_chunk_is_bit_identical_to_apply_safety(case):
    res = apply_safety(case["q"], case["limits"], case["fps"], case["silent"], case["q0"], case["config"])
    stage = SafetyStage(case["limits"], case["fps"], case["config"], case["q0"])
    out = np.vstack([stage.extend(case["q"], case["silent"], last=True), stage.finish()])
    np.testing.assert_array_equal(out, res.q_rad)


def test_smoothing_and_undecided_silence_are_held_back_until_decided():
    from robogest.safety import JointLimits, SafetyConfig

    lim = JointLimits([-1.0], [1.0], [2.0], [20.0], [0.0])
    stage = SafetyStage(lim, 10.0, SafetyConfig(smooth_kernel=5, rest_after_s=1.0))
    assert stage.extend(np.full((5, 1), 0.5)).shape == (3, 1)  # two frames wait for the smoothing's look-ahead
    silent = np.ones(6, bool)
    assert stage.extend(np.full((6, 1), 0.5), silent).shape == (2, 1)  # a silent run not yet known to be long
    assert stage.extend(np.full((6, 1), 0.5), np.ones(6, bool)).shape[0] > 0  # long now: rest up to its leave time
    assert np.all(stage.rest_target)


def test_a_chunk_with_nan_names_its_frame_and_nothing_after_the_last_chunk():
    from robogest.safety import JointLimits

    lim = JointLimits([-1.0, -1.0], [1.0, 1.0], [2.0, 2.0], [20.0, 20.0], [0.0, 0.0], names=("a", "b"))
    stage = SafetyStage(lim, 10.0)
    stage.extend(np.zeros((4, 2)))
    bad = np.zeros((3, 2))
    bad[1, 1] = np.nan
    with pytest.raises(SafetyError, match=r"frames 5 \(t=0.500 s\); joints .*b"):
        stage.extend(bad)
    stage.extend(np.zeros((2, 2)), last=True)
    with pytest.raises(InputError, match="after the last chunk"):
        stage.extend(np.zeros((1, 2)))
