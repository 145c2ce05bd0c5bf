"""Unit tests of each safety stage, with hand-checked numbers."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.errors import ConfigError, InputError, SafetyError
from robogest.safety import (
    JointLimits,
    SafetyConfig,
    apply_safety,
    clamp_positions,
    clamp_velocity,
    gaussian_kernel,
    limit_acceleration,
    long_silent_spans,
    rest_reach_time_s,
    silent_rest_targets,
    smooth,
    track,
)
from robogest.safety.fit import fit_within_limits
from robogest.safety.stages import _brake_step, check_limits


def limits1(q_min=-20.0, q_max=20.0, v=10.0, a=1.0, rest=0.0, n=1) -> JointLimits:
    f = lambda x: np.full(n, float(x))  # noqa: E731
    return JointLimits(f(q_min), f(q_max), f(v), f(a), f(rest))


# --- JointLimits / SafetyConfig validation -----------------------------------------------------------------


def test_joint_limits_reject_bad_values_and_name_the_joint():
    with pytest.raises(InputError, match=r"q_min_rad must be below q_max_rad.*'elbow' \(#1\)"):
        JointLimits([0, 1], [1, 1], [1, 1], [1, 1], [0, 1], names=("shoulder", "elbow"))
    with pytest.raises(InputError, match=r"v_max_rad_s must be > 0.*#0"):
        JointLimits([0], [1], [0], [1], [0.5])
    with pytest.raises(InputError, match=r"a_max_rad_s2 must be > 0"):
        JointLimits([0], [1], [1], [-1], [0.5])
    with pytest.raises(InputError, match=r"rest_q_rad must lie within"):
        JointLimits([0], [1], [1], [1], [1.5])
    with pytest.raises(InputError, match=r"not finite"):
        JointLimits([0], [np.inf], [1], [1], [0.5])
    with pytest.raises(InputError, match=r"do not have the 2 joints"):
        JointLimits([0, 0], [1, 1], [1], [1, 1], [0, 0])
    with pytest.raises(InputError, match=r"names has 1 names for 2 joints"):
        JointLimits([0, 0], [1, 1], [1, 1], [1, 1], [0, 0], names=("a",))


def test_joint_limits_are_read_only_copies():
    src = np.array([0.0])
    lim = JointLimits(src, [1.0], [1.0], [1.0], [0.5])
    src[0] = 5.0
    assert lim.q_min_rad[0] == 0.0
    with pytest.raises(ValueError):
        lim.q_min_rad[0] = 3.0


@pytest.mark.parametrize(
    "kw",
    [
        {"smooth_kernel": 4},
        {"smooth_kernel": 0},
        {"smooth_kernel": 2.0},
        {"margin_rad": -0.1},
        {"smooth_sigma": 0.0},
        {"rest_after_s": 0},
        {"rest_leave_s": -1},
        {"margin_rad": float("nan")},
    ],
)
def test_safety_config_rejects_bad_values(kw):
    with pytest.raises(ConfigError, match=next(iter(kw))):
        SafetyConfig(**kw)


# --- position clamp --------------------------------------------------------------------------------------


def test_clamp_positions_with_margin_and_narrow_range():
    lim = JointLimits([-1.0, 0.0], [1.0, 0.03], [1, 1], [1, 1], [0.0, 0.01])
    q = np.array([[5.0, 5.0], [-5.0, -5.0], [0.5, 0.015]])
    out = clamp_positions(q, lim, 0.02)
    # joint 0: band [-0.98, 0.98]; joint 1: range 0.03 < 2·0.02, so the midpoint 0.015
    np.testing.assert_allclose(out, [[0.98, 0.015], [-0.98, 0.015], [0.5, 0.015]])
    assert q[0, 0] == 5.0  # pure


# --- smoothing -------------------------------------------------------------------------------------------


def test_gaussian_kernel_default_sigma_and_weights():
    # OpenCV rule: sigma(5) = 0.3·(2 − 1) + 0.8 = 1.1 frames
    w = gaussian_kernel(5)
    e1, e2 = np.exp(-0.5 / 1.1**2), np.exp(-2.0 / 1.1**2)
    np.testing.assert_allclose(w, np.array([e2, e1, 1, e1, e2]) / (1 + 2 * e1 + 2 * e2))
    # kernel 3, sigma 1: [e^-½, 1, e^-½] / (1 + 2e^-½) = [0.27407, 0.45186, 0.27407]
    np.testing.assert_allclose(gaussian_kernel(3, 1.0), [0.274068619, 0.451862762, 0.274068619], rtol=1e-8)


def test_smooth_constant_is_constant_and_kernel_one_is_identity():
    q = np.full((7, 2), 0.7)
    np.testing.assert_allclose(smooth(q, 5), q, atol=1e-15)
    r = np.random.default_rng(1).normal(size=(9, 3))
    assert np.array_equal(smooth(r, 1), r)


def test_smooth_impulse_gives_kernel_and_edges_are_not_pulled_to_zero():
    q = np.zeros((9, 1))
    q[4] = 1.0
    np.testing.assert_allclose(smooth(q, 3, 1.0)[3:6, 0], [0.274068619, 0.451862762, 0.274068619], rtol=1e-8)
    ramp = np.arange(6.0)[:, None] + 10.0
    s = smooth(ramp, 3, 1.0)
    np.testing.assert_allclose(s[1:-1], ramp[1:-1])  # a symmetric kernel keeps a line inside
    np.testing.assert_allclose(s[0, 0], 10.0 + 0.274068619)  # edge padded with 10, not 0


# --- velocity clamp --------------------------------------------------------------------------------------


def test_clamp_velocity_ramp_steeper_than_limit():
    q = 0.1 * np.arange(6.0)[:, None]  # 0.1 rad/frame = 5 rad/s at 50 fps
    out = clamp_velocity(q, np.array([2.5]), 1 / 50)  # 0.05 rad/frame
    np.testing.assert_allclose(out[:, 0], [0, 0.05, 0.10, 0.15, 0.20, 0.25])
    slow = 0.01 * np.arange(6.0)[:, None]
    assert np.array_equal(clamp_velocity(slow, np.array([2.5]), 1 / 50), slow)


# --- discrete braking and tracking -----------------------------------------------------------------------


@pytest.mark.parametrize(("d", "s"), [(3.0, 2.0), (1.0, 1.0), (0.5, 0.5), (0.0, 0.0), (6.0, 3.0), (4.5, 2.5)])
def test_brake_step_hand_values(d, s):
    # A = 1: from step 2 one stops with steps 1, 0 → covers 2 + 1 = 3; from 2.5: 2.5 + 1.5 + 0.5 = 4.5
    assert _brake_step(np.array([d]), np.array([1.0]))[0] == pytest.approx(s, abs=1e-12)


def test_brake_step_inverts_stopping_distance():
    a = 0.37
    s = np.linspace(0, 20, 2001)
    dist = np.array([sum(max(x - i * a, 0.0) for i in range(200)) for x in s])
    np.testing.assert_allclose(_brake_step(dist, np.full_like(dist, a)), s, atol=1e-9)


def test_track_step_is_time_optimal_bang_bang():
    # dt = 1, a = 1, v = 10: 0 → 9 with steps 1, 2, 3, 2, 1 (the discrete bang-bang), then holds
    lim = limits1()
    out = track(np.full((8, 1), 9.0), lim, 1.0, np.array([0.0]), margin_rad=0.0)
    np.testing.assert_array_equal(out[:, 0], [0, 1, 3, 6, 8, 9, 9, 9])


def test_track_velocity_cap_and_band_braking():
    lim = limits1(q_min=-5.0, q_max=5.0, v=2.0, a=1.0)
    # band [-4.5, 4.5]; steps 1, 2 (V), then the discrete brake 1.25, 0.25 lands exactly on the edge
    out = track(np.full((12, 1), 100.0), lim, 1.0, np.array([0.0]), margin_rad=0.5)
    np.testing.assert_allclose(out[:, 0], [0, 1, 3, 4.25, 4.5, 4.5, 4.5, 4.5, 4.5, 4.5, 4.5, 4.5])
    d = np.diff(out[:, 0])
    assert d.max() <= 2.0 and np.abs(np.diff(d)).max() <= 1.0 + 1e-12


def test_track_follows_a_feasible_reference_exactly():
    lim = limits1(q_min=-3, q_max=3, v=3.0, a=20.0)
    t = np.arange(400) / 50
    ref = -0.8 * np.cos(2 * np.pi * 0.5 * t)[:, None]  # starts still; v ≤ 2.5 rad/s, a ≤ 7.9 rad/s²
    out = track(ref, lim, 1 / 50, ref[0], margin_rad=0.0)
    assert np.max(np.abs(out - ref)) < 1e-12


def test_limit_acceleration_starts_at_first_frame():
    lim = limits1(v=10.0, a=1.0)
    q = np.array([[2.0], [2.0]] + [[9.0]] * 7)
    out = limit_acceleration(q, lim, 1.0, margin_rad=0.0)
    # steps 1, 2, then the largest that can still stop on 9: 7/3 (f = 7/3 + 4/3 + 1/3 = 4), 4/3, 1/3
    np.testing.assert_allclose(out[:, 0], [2, 2, 3, 5, 22 / 3, 26 / 3, 9, 9, 9], atol=1e-12)
    assert out[-1, 0] == 9.0


def test_without_tracking_clamp_smooth_and_velocity_clamp_break_the_acceleration_limit():
    """The pre-tracking stages alone are not enough, so the property tests below are not vacuous."""
    lim = limits1(q_min=-1.0, q_max=1.0, v=3.0, a=20.0)
    fps = 50.0
    q = np.where(np.arange(100) < 50, -5.0, 5.0)[:, None]  # limit-to-limit jump
    raw = clamp_velocity(smooth(clamp_positions(q, lim, 0.02), 5), lim.v_max_rad_s, 1 / fps)
    assert np.abs(np.diff(raw, 2, axis=0)).max() > lim.a_max_rad_s2[0] / fps**2 * 2
    safe = apply_safety(q, lim, fps, q0=np.array([-0.98])).q_rad
    assert np.abs(np.diff(safe, 2, axis=0)).max() <= lim.a_max_rad_s2[0] / fps**2 + 1e-12


# --- silent periods --------------------------------------------------------------------------------------


def test_long_silent_spans_and_rest_targets():
    fps = 10.0
    m = np.zeros(40, dtype=bool)
    m[5:20] = True  # 1.5 s: long
    m[22:31] = True  # 0.9 s: too short
    m[32:40] = True  # 0.8 s but also short
    assert long_silent_spans(m, fps, 1.0) == [(5, 20)]
    q = np.ones((40, 2))
    rest = np.array([0.1, -0.2])
    targets, hold = silent_rest_targets(q, m, rest, fps, 1.0, 0.3)
    # leave 0.3 s = 3 frames before the run ends at frame 20 → rest targets on frames 5..16
    assert np.flatnonzero(hold).tolist() == list(range(5, 17))
    np.testing.assert_array_equal(targets[5:17], np.tile(rest, (12, 1)))
    np.testing.assert_array_equal(targets[17:], 1.0)


def test_rest_targets_hold_to_the_end_when_silence_reaches_it():
    m = np.zeros(30, dtype=bool)
    m[10:] = True
    _, hold = silent_rest_targets(np.ones((30, 1)), m, np.zeros(1), 10.0, 1.0, 0.4)
    assert np.flatnonzero(hold).tolist() == list(range(10, 30))


def test_exactly_rest_after_s_counts_as_long():
    m = np.zeros(100, dtype=bool)
    m[10:40] = True  # 30 frames at 30 fps = 1.0 s
    assert long_silent_spans(m, 30.0, 1.0) == [(10, 40)]
    m[39] = False
    assert long_silent_spans(m, 30.0, 1.0) == []


def test_rest_reach_time_hand_value():
    # v = 1, a = 1, |q − rest| = 1.5: brake 1 s, D = 1.5 + 0.5 = 2 > v²/a → 2/1 + 1 = 3 s; total 4 s
    lim = limits1(q_min=-2, q_max=2, v=1.0, a=1.0)
    assert rest_reach_time_s(np.array([1.5]), lim) == pytest.approx(4.0)
    assert rest_reach_time_s(np.array([1.5]), lim, fps=10) == pytest.approx(4.3)
    assert rest_reach_time_s(None, lim) == pytest.approx(4.5)  # worst pose: 2 rad away
    assert rest_reach_time_s(lim) == rest_reach_time_s(None, lim)


# --- apply_safety: errors and edges ----------------------------------------------------------------------


def test_nan_and_inf_are_errors_naming_frames_and_joints():
    lim = JointLimits([-1, -1], [1, 1], [1, 1], [1, 1], [0, 0], names=("neck", "elbow"))
    q = np.zeros((10, 2))
    q[3, 1] = np.nan
    with pytest.raises(SafetyError, match=r"NaN/inf at 1 samples: frames 3 \(t=0\.060 s\); joints 'elbow' \(#1\)"):
        apply_safety(q, lim, 50)
    q[3, 1] = -np.inf
    with pytest.raises(SafetyError, match="NaN/inf"):
        apply_safety(q, lim, 50)
    with pytest.raises(SafetyError, match="q0 is NaN/inf"):
        apply_safety(np.zeros((10, 2)), lim, 50, q0=np.array([np.nan, 0]))


def test_bad_shapes_and_q0_outside_limits():
    lim = limits1(q_min=-1, q_max=1, n=2)
    with pytest.raises(InputError, match="expected \\(T, 2\\)"):
        apply_safety(np.zeros((10, 3)), lim, 50)
    with pytest.raises(InputError, match="silent mask"):
        apply_safety(np.zeros((10, 2)), lim, 50, silent=np.zeros(9, dtype=bool))
    with pytest.raises(InputError, match="q0 has shape"):
        apply_safety(np.zeros((10, 2)), lim, 50, q0=np.zeros(3))
    with pytest.raises(InputError, match="fps"):
        apply_safety(np.zeros((10, 2)), lim, 0)
    with pytest.raises(SafetyError, match="outside the joint limits"):
        apply_safety(np.zeros((10, 2)), lim, 50, q0=np.array([0.0, 1.5]))


def test_output_is_extended_until_rest_and_still():
    lim = limits1(q_min=-1, q_max=1, v=2.0, a=10.0)
    q = np.full((20, 1), 0.9)
    res = apply_safety(q, lim, 50.0)
    assert res.n_input_frames == 20 and res.n_extra_frames > 0
    assert res.q_rad.shape[0] == 20 + res.n_extra_frames
    assert res.q_rad[-1, 0] == 0.0 and res.q_rad[-2, 0] == 0.0
    tail = res.hold_rest[20:]
    assert tail[-1] and not tail[0]  # False on the way back, True once there
    assert res.rest_target[20:].all()


def test_empty_and_single_frame_inputs():
    lim = limits1(q_min=-1, q_max=1, v=2.0, a=10.0)
    r0 = apply_safety(np.zeros((0, 1)), lim, 50.0)
    assert r0.q_rad.shape == (1, 1) and r0.q_rad[0, 0] == 0.0
    r1 = apply_safety(np.full((1, 1), 0.5), lim, 50.0, q0=np.array([0.3]))
    assert r1.q_rad[0, 0] == 0.3 and r1.q_rad[-1, 0] == 0.0 and r1.q_rad[-2, 0] == 0.0


def test_start_from_rest_false_starts_at_first_frame():
    lim = limits1(q_min=-1, q_max=1, v=2.0, a=10.0)
    res = apply_safety(np.full((5, 1), 0.5), lim, np.int64(50), config=SafetyConfig(start_from_rest=False))
    assert res.q_rad[0, 0] == 0.5 and res.fps == 50.0


def test_clipped_fraction_reports_clamping():
    lim = limits1(q_min=-1, q_max=1, v=2.0, a=10.0, n=2)
    q = np.zeros((50, 2))
    q[:, 1] = 3.0  # joint 1 always beyond its limit
    res = apply_safety(q, lim, 50.0)
    assert res.stage_changed_fraction["clamp"] == pytest.approx(0.5)
    assert 0.5 <= res.clipped_fraction <= 1.0
    res_ok = apply_safety(np.zeros((50, 2)), lim, 50.0)
    assert res_ok.clipped_fraction == 0.0


def test_the_internal_check_refuses_nan_angles():
    lim = limits1()
    q = np.zeros((5, 1))
    check_limits(q, lim, 0.02, lim.q_min_rad, lim.q_max_rad)
    q[3] = np.nan  # compares False with every bound: it used to pass
    with pytest.raises(SafetyError, match="NaN"):
        check_limits(q, lim, 0.02, lim.q_min_rad, lim.q_max_rad)


def test_track_continues_a_motion_already_under_way():
    """With ``step0`` the first step is limited against the motion that led to ``q0`` (a streamed continuation),
    not against standing still."""
    lim = limits1(v=10.0, a=100.0)
    dt = 0.02
    step = 0.15  # rad per frame: 7.5 rad/s, moving up
    targets = np.full((30, 1), -1.0)  # a target behind: it must brake first
    out = track(targets, lim, dt, np.zeros(1), step0=np.array([step]))
    assert out[1, 0] - out[0, 0] == pytest.approx(step - 100.0 * dt * dt)  # one frame of full braking
    check_limits(out, lim, dt, lim.q_min_rad, lim.q_max_rad, d0=np.array([step]))
    with pytest.raises(SafetyError, match="acceleration"):  # the same frames read as starting still break it
        check_limits(out, lim, dt, lim.q_min_rad, lim.q_max_rad)


def _lag_frames(a: np.ndarray, b: np.ndarray, max_lag: int = 15) -> int:
    """Frames by which ``b (T,)`` trails ``a (T,)`` (the cross-correlation peak of their speeds)."""
    sa, sb = np.abs(np.diff(a)), np.abs(np.diff(b))
    sa, sb = sa - sa.mean(), sb - sb.mean()
    n = sa.size
    lags = range(-max_lag, max_lag + 1)
    c = [np.dot(sa[max(0, -k) : n - max(0, k)], sb[max(0, k) : n - max(0, -k)]) for k in lags]
    return list(lags)[int(np.argmax(c))]


def test_fit_within_limits_centres_moves_too_fast_for_the_robot():
    """Strokes faster than the limits: the causal path falls behind, the preview fit does not, and both keep
    every limit (the fit to the solver's tolerance; apply_safety's tracker then exactly)."""
    fps, dt = 50.0, 0.02
    lim = limits1(q_min=-2.0, q_max=2.0, v=3.0, a=40.0)
    t = np.arange(400) * dt
    u = np.clip((t % 1.0 - 0.5) / 0.1, 0.0, 1.0)  # a 0.1 s minimum-jerk stroke every second, alternating sides
    x = (0.6 * np.where(np.floor(t) % 2 == 0, 1, -1) * u**3 * (10 - 15 * u + 6 * u * u))[:, None]
    x[:, 0] += np.where(np.floor(t) % 2 == 0, -0.3, 0.3)
    x[:, 0] -= x[0, 0]  # peak speed 11 rad/s > 3 rad/s
    fit = fit_within_limits(x, lim, dt, np.zeros(1))
    assert fit[0, 0] == 0.0
    d = np.diff(fit[:, 0], prepend=0.0)
    assert np.abs(d).max() <= 3.0 * dt + 1e-6 and np.abs(np.diff(d)).max() <= 40.0 * dt * dt + 1e-6
    assert _lag_frames(x[:, 0], fit[:, 0]) == 0
    causal = apply_safety(x, lim, fps, config=SafetyConfig(preview=False)).q_rad[: len(x), 0]
    preview = apply_safety(x, lim, fps).q_rad[: len(x), 0]
    assert _lag_frames(x[:, 0], causal) >= 2
    assert _lag_frames(x[:, 0], preview) == 0
    for q in (causal, preview):
        check_limits(q[:, None], lim, dt, np.full(1, -2.0), np.full(1, 2.0))
    # the fit is the closest feasible motion: nearer the targets than the causal path
    assert np.sqrt(np.mean((preview - x[:, 0]) ** 2)) < 0.7 * np.sqrt(np.mean((causal - x[:, 0]) ** 2))


def test_fit_within_limits_keeps_feasible_targets_and_weights_rest():
    dt = 0.02
    lim = limits1(v=10.0, a=100.0, n=2)
    t = np.arange(200) * dt
    x = np.stack([0.3 * (1 - np.cos(2 * np.pi * 0.5 * t)), np.zeros_like(t)], axis=1)  # within every limit
    np.testing.assert_allclose(fit_within_limits(x, lim, dt, np.zeros(2)), x, atol=1e-6)
    # too short to fit anything: returned as given, frame 0 set to q0
    short = np.ones((3, 2))
    np.testing.assert_array_equal(fit_within_limits(short, lim, dt, np.zeros(2))[0], np.zeros(2))
    # rest frames come back as their targets (a jump to rest the fit alone could not make), for track to brake onto
    jump = x.copy()
    rest = t >= 3.0
    jump[rest] = 0.0
    fit = fit_within_limits(jump, limits1(v=1.0, a=10.0, n=2), dt, np.zeros(2), rest_mask=rest)
    np.testing.assert_array_equal(fit[rest], jump[rest])
    assert np.abs(np.diff(fit[~rest, 0])).max() <= 1.0 * dt + 1e-6


def test_fit_within_limits_continues_a_motion_under_way():
    """With ``step0`` (a streamed continuation) the first step changes from it by at most the acceleration limit."""
    dt = 0.02
    lim = limits1(v=3.0, a=40.0)
    step0 = np.array([0.05])  # 2.5 rad/s, moving up
    x = np.zeros((30, 1))  # the new plan says: be at 0 now
    fit = fit_within_limits(x, lim, dt, np.zeros(1), step0=step0)
    d = np.diff(fit[:, 0], prepend=-step0[0])
    assert abs(d[1] - step0[0]) <= 40.0 * dt * dt + 1e-9  # it brakes, no instant stop
    assert np.abs(np.diff(d)).max() <= 40.0 * dt * dt + 1e-6 and np.abs(d).max() <= 3.0 * dt + 1e-6
    assert fit[1, 0] > 0.0 and abs(fit[-1, 0]) < 1e-3  # overshoots while braking, then comes back


def test_check_limits_names_the_first_joint_and_frame_that_breaks_a_limit():
    """``play`` of a tampered trajectory said only "breaks the position limit": which joint, when, by how much."""
    lim = JointLimits([-1.0, -1.0], [1.0, 1.0], [2.0, 2.0], [10.0, 10.0], [0.0, 0.0], names=("neck", "elbow"))
    q = np.zeros((50, 2))
    q[30, 1] = 50.0
    with pytest.raises(
        SafetyError,
        match=r"position/velocity/acceleration limit \(internal check\); first: elbow "
        r"at frame 30 \(0\.60 s\): 50\.0000 rad outside \[-1\.0000, 1\.0000\]",
    ):
        check_limits(q, lim, 0.02, lim.q_min_rad, lim.q_max_rad)
    q = np.linspace(0, 0.9, 50)[:, None] * [1.0, 0.0]  # 0.92 rad/s from the first frame: an acceleration step
    with pytest.raises(
        SafetyError, match=r"breaks the acceleration limit .*first: neck at frame 1 .*rad/s² against 10"
    ):
        check_limits(q, lim, 0.02, lim.q_min_rad, lim.q_max_rad)
