"""The control loop and its online limiter: every limit holds on what reaches the backend, at any playback rate.

Finite differences of the goals sent, at the playback period T, are checked against the limits. They are weighted
means of the continuous velocity, acceleration and jerk of the limiter's trajectory, so the bound is exact up to
rounding: the tolerance is 1e-9 relative (plus 1e-12 rad absolute on the differences), far below the 1e-6 by
which the limiter shrinks its limits.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robogest.backends.base import Backend
from robogest.backends.control import ControlLoop
from robogest.backends.player import play
from robogest.backends.rest import go_to_rest
from robogest.errors import BackendError, InputError
from robogest.robot.config import RobotConfig
from robogest.safety import JointLimits, apply_safety
from robogest.safety.online import OnlineLimiter
from robogest.trajectory.types import Trajectory

REL = 1e-9
ABS = 1e-12


class Recorder(Backend):
    """A backend double: remembers every goal written; present position = last goal; torque and connection flags."""

    realtime = False

    def __init__(self, robot: RobotConfig, start_q_rad: np.ndarray | None = None) -> None:
        super().__init__(robot)
        self.q = np.array(robot.rest_q_rad if start_q_rad is None else start_q_rad, dtype=float)
        self.sent: list[np.ndarray] = []
        self.torque_log: list[tuple[int, bool]] = []
        self.is_connected = False
        self.torque = False
        self.advanced_s = 0.0

    def connect(self) -> None:
        self.is_connected = True

    def read_positions(self) -> np.ndarray:
        return self.q.copy()

    def set_torque(self, on: bool) -> None:
        self.torque = on
        self.torque_log.append((len(self.sent), on))

    def _send_goal(self, q_rad: np.ndarray) -> None:
        q = np.array(q_rad, dtype=float)
        self.sent.append(q)
        self.q = q

    def advance(self, dt_s: float) -> None:
        self.advanced_s += dt_s

    def disconnect(self) -> None:
        self.is_connected = False

    def shutdown(self) -> None:
        if self.is_connected and self.torque:
            go_to_rest(self)
        super().shutdown()


def make_robot(q_min, q_max, v_max, a_max, rest, j_max=None) -> RobotConfig:
    joints = []
    for k in range(len(q_min)):
        j = {
            "name": f"j{k}",
            "lower_rad": float(q_min[k]),
            "upper_rad": float(q_max[k]),
            "max_velocity_rad_s": float(v_max[k]),
            "max_acceleration_rad_s2": float(a_max[k]),
            "rest_rad": float(rest[k]),
        }
        if j_max is not None:
            j["max_jerk_rad_s3"] = float(j_max[k])
        joints.append(j)
    return RobotConfig.model_validate(
        {
            "name": "double",
            "model": "none.xml",
            "joints": joints,
            "retarget": [{"human": ["r_shoulder", "r_elbow"], "robot": ["a", "b"]}],
        }
    )


def traj_for(robot: RobotConfig, q: np.ndarray, fps: float) -> Trajectory:
    """Commands made like the pipeline makes them: ``apply_safety`` at ``fps`` from rest."""
    res = apply_safety(q, JointLimits.from_robot(robot), fps, q0=robot.rest_q_rad)
    n = res.q_rad.shape[0]
    return Trajectory(
        t_s=np.arange(n) / fps, q_rad=res.q_rad, joint_names=robot.joint_names, q_min_rad=robot.q_min_rad,
        q_max_rad=robot.q_max_rad, v_max_rad_s=robot.v_max_rad_s, a_max_rad_s2=robot.a_max_rad_s2,
        rest_q_rad=robot.rest_q_rad, silent=np.zeros(n, bool), robot=robot.name,
    )  # fmt: skip


def check_limits(goals: np.ndarray, robot: RobotConfig, period_s: float) -> None:
    """Position, velocity, acceleration and jerk of ``goals (N, J)`` at ``period_s``; the robot was still before."""
    g = np.vstack([np.repeat(goals[:1], 3, axis=0), goals])
    assert np.all(g >= robot.q_min_rad - ABS) and np.all(g <= robot.q_max_rad + ABS), "position limit"
    for order, lim, name in (
        (1, robot.v_max_rad_s, "velocity"),
        (2, robot.a_max_rad_s2, "acceleration"),
        (3, robot.j_max_rad_s3, "jerk"),
    ):
        d = np.abs(np.diff(g, n=order, axis=0))
        bound = lim * period_s**order * (1 + REL) + ABS * 2**order
        worst = float(np.max(d / bound)) if d.size else 0.0
        assert worst <= 1.0, f"{name} limit exceeded by a factor {worst:.6f}"


@st.composite
def cases(draw: st.DrawFn) -> dict:
    n_j = draw(st.integers(1, 5))
    fps = draw(st.integers(10, 60))
    rate = draw(st.integers(20, 200))
    seed = draw(st.integers(0, 2**32 - 1))
    explicit_jerk = draw(st.booleans())
    rng = np.random.default_rng(seed)
    q_min = rng.uniform(-2.5, 0.0, n_j)
    q_max = q_min + rng.uniform(0.05, 3.5, n_j)
    rest = rng.uniform(q_min, q_max)
    v = rng.uniform(0.3, 8.0, n_j)
    a = rng.uniform(1.0, 60.0, n_j)
    j = rng.uniform(20.0, 3000.0, n_j) if explicit_jerk else None
    robot = make_robot(q_min, q_max, v, a, rest, j)
    n_t = int(rng.integers(2, int(2.5 * fps)))
    kind = rng.choice(["steps", "walk", "far"])
    if kind == "steps":  # jumps between (and beyond) the limits
        levels = rng.uniform(q_min - 0.2, q_max + 0.2, (n_t, n_j))
        q = levels[np.minimum(np.cumsum(rng.random(n_t) < 0.15), n_t - 1)]
    elif kind == "walk":
        q = rest + np.cumsum(rng.normal(0, 0.1, (n_t, n_j)), axis=0)
    else:
        q = rng.uniform(-50, 50, (n_t, n_j))
    return {"robot": robot, "traj": traj_for(robot, q, fps), "rate": float(rate)}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_every_limit_holds_on_the_goals_at_any_playback_rate(case):
    """Trajectories made at 10–60 fps, played at 20–200 Hz: position, velocity, acceleration and jerk limits hold
    on every goal written, from the hold before torque on to the end of the glide to rest."""
    robot, rate = case["robot"], case["rate"]
    b = Recorder(robot)
    rep = play(case["traj"], b, rate_hz=rate)
    assert rep.completed and not b.torque and not b.is_connected
    goals = np.array(b.sent)
    check_limits(goals, robot, 1.0 / rate)
    np.testing.assert_allclose(goals[-1], robot.rest_q_rad, atol=1e-9)


def test_a_trajectory_made_at_20_fps_played_at_100_hz_keeps_acceleration():
    """The issue's case: without the limiter a 20 fps trajectory played at 100 Hz reached 5x the acceleration
    limit (steps of velocity between frames); now the bound holds."""
    robot = make_robot([-1.0], [1.0], [3.0], [15.0], [0.0])
    t = np.arange(0, 2.0, 1 / 20)
    q = 0.8 * np.sign(np.sin(2 * np.pi * 1.0 * t))[:, None]
    traj = traj_for(robot, q, 20.0)
    naive = np.array([traj.sample(k / 100) for k in range(int(traj.duration_s * 100))])
    acc = np.abs(np.diff(naive, 2, axis=0)).max() * 100**2
    assert acc > 2.0 * 15.0  # linear interpolation alone breaks the limit
    b = Recorder(robot)
    play(traj, b, rate_hz=100.0)
    check_limits(np.array(b.sent), robot, 0.01)


@pytest.mark.parametrize(("fps", "rate"), [(20.0, 100.0), (60.0, 30.0)])
def test_limits_hold_on_the_simulated_robot(fps, rate):
    from robogest.backends.mujoco_sim import MujocoBackend
    from robogest.robot import find_robot

    robot = find_robot("humanoid_xl430")

    class RecSim(MujocoBackend):
        def _send_goal(self, q_rad):
            self.sent.append(np.array(q_rad, dtype=float))
            super()._send_goal(q_rad)

    rng = np.random.default_rng(int(fps))
    n = int(3 * fps)
    q = robot.rest_q_rad + np.cumsum(rng.normal(0, 0.08, (n, len(robot.joints))), axis=0)
    b = RecSim(robot)
    b.sent = []
    rep = play(traj_for(robot, q, fps), b, rate_hz=rate)
    assert rep.completed
    check_limits(np.array(b.sent), robot, 1.0 / rate)
    np.testing.assert_allclose(b.sent[-1], robot.rest_q_rad, atol=1e-9)


def test_position_limits_hold_even_for_targets_beyond_them_at_full_speed():
    """The limiter's own guarantee (not only apply_safety's): targets far outside, switching at full speed."""
    from robogest.safety.online import OnlineLimiter

    robot = make_robot([-0.3, 0.0], [0.3, 2.0], [5.0, 8.0], [10.0, 60.0], [0.0, 1.9], [50.0, 5000.0])
    lim = OnlineLimiter.for_robot(robot, 0.005, robot.rest_q_rad)
    rng = np.random.default_rng(0)
    out = [robot.rest_q_rad]  # still there before the first step
    target, v = robot.q_max_rad + 5, np.zeros(2)
    for k in range(3000):
        if k % int(rng.integers(5, 200)) == 0:  # far outside, or inside but rushing towards a limit
            outside = rng.random() < 0.3
            target = rng.choice([-1.0, 1.0]) * 10 + rng.normal(size=2) if outside else rng.uniform(-0.3, 0.3, 2)
            v = rng.choice([-1.0, 1.0], 2) * 10.0
        out.append(lim.step(target, v))
    check_limits(np.array(out), robot, 0.005)
    assert lim.brakes > 0  # the braking check did bite (slow-jerk joint near its limits)
    assert lim.fallbacks == 0


# --- the loop --------------------------------------------------------------------------------------------
def small_robot() -> RobotConfig:
    return make_robot([-1.0, -1.5], [1.0, 1.5], [3.0, 3.0], [15.0, 20.0], [0.0, 0.2])


def sine(robot: RobotConfig, seconds: float = 1.5, fps: float = 50.0, amp: float = 0.6) -> Trajectory:
    t = np.arange(0, seconds + 1e-9, 1 / fps)
    q = robot.rest_q_rad + amp * np.sin(np.pi * t / seconds)[:, None] ** 2 * np.array([1.0, -1.0])
    return traj_for(robot, q, fps)


def test_start_holds_the_present_pose_with_torque_on_then_close_turns_it_off():
    robot = small_robot()
    b = Recorder(robot, start_q_rad=np.array([0.4, -0.3]))
    loop = ControlLoop(b, 100.0).start()
    assert b.torque and b.is_connected
    loop.run_for(0.2)
    np.testing.assert_allclose(np.array(b.sent), np.tile([0.4, -0.3], (len(b.sent), 1)))
    assert b.torque_log[0] == (1, True)  # the hold was written before torque went on
    assert loop.close() is None
    assert loop.close() is None  # idempotent
    assert not b.torque and not b.is_connected
    np.testing.assert_allclose(b.sent[-1], robot.rest_q_rad, atol=1e-9)
    check_limits(np.array(b.sent), robot, 0.01)


def test_two_trajectories_back_to_back_keep_torque_on_in_between():
    robot = small_robot()
    b = Recorder(robot)
    loop = ControlLoop(b, 100.0).start()
    h1 = loop.play(sine(robot))
    assert h1.wait() and h1.completed
    n1 = len(b.sent)
    loop.run_for(0.3)  # idle between the two: torque stays on, the pose is held
    assert b.torque and np.ptp(np.array(b.sent[n1:]), axis=0).max() < 1e-12
    h2 = loop.play(sine(robot, amp=-0.4), start_at=loop.now_s + 0.2)
    h2.wait()
    assert h2.completed and [e for e in ("started", "first_goal", "done") if e in h2.events] == [
        "started",
        "first_goal",
        "done",
    ]
    assert h2.events["started"].loop_s >= h1.events["done"].loop_s + 0.5 - 1e-9  # 0.3 s idle + 0.2 s start_at
    assert h2.events["first_goal"].monotonic_s >= h2.events["started"].monotonic_s
    assert [on for _, on in b.torque_log] == [True]
    loop.close()
    assert [on for _, on in b.torque_log] == [True, False]
    check_limits(np.array(b.sent), robot, 0.01)


def test_interrupt_mid_trajectory_glides_to_rest_within_the_limits_quickly():
    """At typical gesture speed (velocity limit 3 rad/s), interrupt() reaches rest within the limits; the loop
    time from interrupt to rest is deterministic here (stepped loop)."""
    robot = small_robot()
    b = Recorder(robot)
    loop = ControlLoop(b, 100.0).start()
    h = loop.play(sine(robot, seconds=2.0, amp=0.9))
    loop.run_for(0.6)
    t_int = loop.now_s
    away = np.abs(loop.goal_rad - robot.rest_q_rad).max()
    r = loop.interrupt()
    assert h.done and "interrupted" in h.events and not h.completed
    r.wait()
    glide_s = r.events["done"].loop_s - t_int
    np.testing.assert_allclose(loop.goal_rad, robot.rest_q_rad, atol=1e-4)
    assert away > 0.3 and glide_s < 0.75, (away, glide_s)
    assert b.torque  # interrupt keeps the loop (and torque) on
    loop.close()
    check_limits(np.array(b.sent), robot, 0.01)


def test_idle_motion_drives_the_goal_when_nothing_plays():
    robot = small_robot()
    b = Recorder(robot)
    loop = ControlLoop(b, 50.0).start()
    loop.set_idle(lambda t: robot.rest_q_rad + 0.1 * np.sin(2 * np.pi * 0.5 * t))
    loop.run_for(2.0)
    assert np.ptp(np.array(b.sent), axis=0).min() > 0.1  # it breathes
    loop.close()
    check_limits(np.array(b.sent), robot, 0.02)


def test_stepped_simulation_is_deterministic():
    from robogest.backends.mujoco_sim import MujocoBackend
    from robogest.robot import find_robot

    robot = find_robot("desk_arm_sts3215")
    logs = []
    for _ in range(2):
        b = MujocoBackend(robot)
        loop = ControlLoop(b, 100.0).start()
        assert not loop.threaded
        loop.play(sine_like(robot)).wait()
        logs.append(b.log["q_rad"].copy())
        loop.close()
    assert logs[0].shape == logs[1].shape and np.array_equal(logs[0], logs[1])


def sine_like(robot: RobotConfig) -> Trajectory:
    t = np.arange(0, 1.0, 0.02)
    q = robot.rest_q_rad + 0.3 * np.sin(np.pi * t)[:, None]
    return traj_for(robot, q, 50.0)


class RealtimeRecorder(Recorder):
    """Realtime double (the loop waits on the clock); every ``late_every``-th write takes ``late_s`` extra."""

    realtime = True

    def __init__(self, robot: RobotConfig, late_every: int = 0, late_s: float = 0.0) -> None:
        super().__init__(robot)
        self.late_every, self.late_s = late_every, late_s

    def _send_goal(self, q_rad: np.ndarray) -> None:
        super()._send_goal(q_rad)
        if self.late_every and len(self.sent) % self.late_every == 0:
            time.sleep(self.late_s)


def test_threaded_loop_plays_and_stamps_events_on_the_monotonic_clock():
    robot = small_robot()
    b = RealtimeRecorder(robot)
    loop = ControlLoop(b, 100.0, time_scale=4.0)
    assert loop.threaded
    before = time.monotonic()
    loop.start()
    try:
        at = time.monotonic() + 0.2
        h = loop.play(sine(robot, seconds=1.0), start_at=loop.loop_s_at(at))
        assert h.wait(timeout_s=30.0) and h.completed
        ev = h.events
        assert before <= at <= ev["started"].monotonic_s <= ev["first_goal"].monotonic_s <= ev["done"].monotonic_s
        assert ev["done"].monotonic_s <= time.monotonic()
    finally:
        loop.close()
    assert not b.torque and not b.is_connected
    check_limits(np.array(b.sent), robot, 0.01)  # the real period, even with the trajectory sped up 4x


def test_late_ticks_advance_the_target_but_not_the_step():
    """Ticks made late on purpose (every 7th write takes 5 periods): whole slots are skipped (the target time
    jumps), yet each goal moves at most one limited step from the last goal sent."""
    robot = small_robot()
    b = RealtimeRecorder(robot, late_every=7, late_s=0.05)
    loop = ControlLoop(b, 100.0, threaded=False)
    loop.start()
    try:
        loop.play(sine(robot, seconds=1.0)).wait()
    finally:
        loop.close()
    assert loop.stats.skipped_slots >= 10 and loop.stats.late_ticks >= 10
    check_limits(np.array(b.sent), robot, 0.01)


def test_a_failing_backend_stops_the_threaded_loop_and_says_why():
    robot = small_robot()

    class Failing(RealtimeRecorder):
        def _send_goal(self, q_rad):
            if len(self.sent) > 30:
                raise BackendError("servo id 3 (joint j1): lost")
            super()._send_goal(q_rad)

    b = Failing(robot)
    loop = ControlLoop(b, 100.0).start()
    h = loop.play(sine(robot))
    with pytest.raises(BackendError, match="servo id 3"):
        h.wait(timeout_s=30.0)
    assert "could not reach rest" in (loop.close() or "")
    assert not b.torque and not b.is_connected


def test_jerk_limits_come_from_the_yaml_or_the_default_rule(tmp_path):
    import yaml

    from robogest.errors import ConfigError
    from robogest.robot.config import load_robot_config

    default = make_robot([-1.0], [1.0], [3.0], [15.0], [0.0])
    assert default.j_max_rad_s3 == pytest.approx([15.0 / 0.05])  # the acceleration limit reached in 50 ms
    explicit = make_robot([-1.0], [1.0], [3.0], [15.0], [0.0], j_max=[120.0])
    assert explicit.j_max_rad_s3 == pytest.approx([120.0])
    doc = {
        "name": "x", "model": "x.xml", "retarget": [{"human": ["r_shoulder", "r_elbow"], "robot": ["a", "b"]}],
        "joints": [{"name": "j", "lower_rad": -1, "upper_rad": 1, "max_velocity_rad_s": 1,
                    "max_acceleration_rad_s2": 1, "max_jerk_rad_s3": -5}],
    }  # fmt: skip
    (tmp_path / "x.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r"joints\[0\]\.max_jerk_rad_s3"):
        load_robot_config(tmp_path / "x.yaml")


# --- the stop envelope -------------------------------------------------------------------------------
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases(), st.floats(0.2, 1.0), st.floats(0.0, 1.0))
def test_with_a_stop_envelope_an_interrupt_at_any_moment_is_at_rest_in_time(case, stop_s, when):
    """``stop_within_s``: an interrupt at any moment is at rest within it (plus the tick that takes it), and every
    other limit still holds. (Not asserted per tick: ruckig's duration from a state at the velocity limit with
    acceleration left over is sometimes a slower profile's, for that one tick.)"""
    robot, rate = case["robot"], case["rate"]
    b = Recorder(robot)
    loop = ControlLoop(b, rate, threaded=False, stop_within_s=stop_s)
    loop.start()
    loop.play(case["traj"])
    loop.run_for(when * case["traj"].duration_s)
    n0 = loop.stats.n_ticks
    rest = loop.interrupt()
    rest.wait()
    took_s = (loop.stats.n_ticks - n0) / rate
    loop.close()
    check_limits(np.array(b.sent), robot, 1.0 / rate)
    assert took_s <= stop_s + 1.0 / rate + 1e-9


def test_the_stop_envelope_cuts_gestures_short_only_beyond_its_reach():
    robot = small_robot()
    lim = OnlineLimiter.for_robot(robot, 0.01, robot.rest_q_rad, stop_within_s=0.3)
    reach = lim.reach_rad(0.3)
    assert np.all(reach > 0) and np.all(lim.reach_rad(0.6) > reach)  # farther with more time
    near, far = robot.rest_q_rad + 0.5 * reach, robot.rest_q_rad + 3 * reach
    np.testing.assert_allclose(lim.clamp_target(near), np.clip(near, lim.band_lo_rad, lim.band_hi_rad))
    assert np.all(np.abs(lim.clamp_target(far) - robot.rest_q_rad) <= reach)
    with pytest.raises(InputError, match="stop_within_s"):
        OnlineLimiter.for_robot(robot, 0.01, robot.rest_q_rad, stop_within_s=0.015)


def test_a_move_on_ruckigs_knife_edge_is_planned_not_raised():
    """Found by hypothesis (CI): with jerk = 20 x acceleration, a rest-to-rest move whose acceleration just reaches
    its limit as the velocity does makes ruckig 0.19's step 1 raise ``RuckigError`` (not a RuntimeError), so
    building this limiter crashed. It is planned with limits a hair lower instead."""
    a = 17.29462777080277
    rest = -0.650469435983421
    lim = OnlineLimiter([-0.6575101172870303], [-0.4747296581230917], [1.9357858369736631], [a], [20 * a], 0.01, [rest],
                        rest_q_rad=[rest], stop_within_s=0.2)  # fmt: skip
    reach = lim.reach_rad(0.2)
    assert 0.08 < reach[0] < 0.09  # the move that ruckig refused, 0.0865 rad, is inside this bisection
    assert lim.time_to_reach_s([rest + reach[0]]) <= 0.2 + 1e-6
    assert lim.fallbacks == 0


def test_a_glide_to_rest_slower_than_the_default_timeout_still_ends_at_rest():
    """0.9 rad at 0.03 rad/s takes about 30 s, beyond REST_TIMEOUT_S: the glide's timeout follows the limits, since
    giving up turns torque off with the joint away from rest."""
    robot = make_robot([-1.0], [1.0], [0.03], [0.5], [0.0])
    b = Recorder(robot, start_q_rad=np.array([0.9]))
    loop = ControlLoop(b, 50.0).start()
    assert loop.close() is None
    np.testing.assert_allclose(b.sent[-1], robot.rest_q_rad, atol=1e-9)
    assert not b.torque
    check_limits(np.array(b.sent), robot, 0.02)


def test_go_to_rest_takes_over_a_moving_goal_stream_within_the_acceleration_and_jerk_limits():
    """A backend driven directly (no loop) and then shut down mid-motion: the glide brakes from the goals' velocity
    instead of stopping them dead in one tick."""
    robot = small_robot()
    b = Recorder(robot)
    b.set_control_rate(100.0)
    b.connect()
    b.set_torque(True)
    lim = OnlineLimiter.for_robot(robot, 0.01, robot.rest_q_rad)
    b.write_goal(robot.rest_q_rad)  # still at rest (what check_limits takes the goals before the first to be)
    for _ in range(40):  # towards a far pose: at full speed by now
        b.write_goal(lim.step(np.array([0.95, -1.4])))
    assert np.abs(b.last_goal_v_rad_s).max() > 1.0
    b.shutdown()
    np.testing.assert_allclose(b.sent[-1], robot.rest_q_rad, atol=1e-9)
    check_limits(np.array(b.sent), robot, 0.01)


def test_a_with_block_whose_start_fails_after_torque_on_turns_torque_off():
    class TorqueAckLost(Recorder):
        def set_torque(self, on: bool) -> None:
            super().set_torque(on)
            if on:
                raise BackendError("servo id 3 (joint j1): no valid reply to writing register TORQUE_ENABLE")

    b = TorqueAckLost(small_robot())
    with pytest.raises(BackendError, match="TORQUE_ENABLE"), ControlLoop(b, 100.0):
        pass
    assert not b.torque and not b.is_connected


def test_leaving_a_with_block_raises_a_loop_failure_the_block_did_not_see():
    robot = small_robot()

    class FailsOnce(RealtimeRecorder):
        def _send_goal(self, q_rad):
            if len(self.sent) == 30 and not hasattr(self, "failed"):
                self.failed = True
                raise BackendError("servo id 3 (joint j1): lost")
            super()._send_goal(q_rad)

    b = FailsOnce(robot)
    with pytest.raises(BackendError, match="servo id 3"), ControlLoop(b, 100.0) as loop:
        loop.play(sine(robot))
        time.sleep(0.3)  # not the loop's wait: nothing in the block looks at the loop again
    assert loop.rest_problem is None  # the glide went to rest: the failure itself is what is raised
    assert not b.torque and not b.is_connected


def test_a_signal_during_the_closing_glide_is_raised_once_at_rest_with_torque_off():
    """Ctrl-C while the loop glides to rest at close: the glide goes on within every limit and the signal is raised
    once the robot is at rest with torque off (raised mid-glide, the backend's own glide started over from a
    standstill: 8.6 times the acceleration limit)."""
    import os
    import signal

    from robogest.backends.signals import signals_end_at_rest

    robot = small_robot()

    class SignalMidGlide(Recorder):
        closing_at: int | None = None

        def advance(self, dt_s: float) -> None:  # between two ticks, outside the tick's own signal section
            super().advance(dt_s)
            if self.closing_at is not None and len(self.sent) == self.closing_at + 10:
                os.kill(os.getpid(), signal.SIGINT)

    b = SignalMidGlide(robot)
    with signals_end_at_rest():
        loop = ControlLoop(b, 100.0, threaded=False).start()
        loop.play(sine(robot))
        loop.run_for(0.7)  # mid-gesture, moving
        b.closing_at = len(b.sent)
        with pytest.raises(KeyboardInterrupt):
            loop.close()
    assert len(b.sent) > b.closing_at + 10 and not b.torque
    np.testing.assert_allclose(b.sent[-1], robot.rest_q_rad, atol=1e-9)
    check_limits(np.array(b.sent), robot, 0.01)
