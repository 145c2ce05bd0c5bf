"""Shared helpers for the servo backend tests."""

from __future__ import annotations

import numpy as np
import pytest
import scservo_sdk as scs

from robogest.trajectory.types import Trajectory


@pytest.fixture(autouse=True)
def _scs_end():
    yield
    scs.SCS_SETEND(0)  # the Feetech SDK keeps its byte order in a global


def sine_traj(robot, seconds: float = 2.0, fps: float = 50.0, amp: float = 0.4) -> Trajectory:
    """A 0.5 Hz sine on every joint (phase-shifted per joint), clipped to the robot's limits."""
    t = np.arange(0, seconds + 1e-9, 1 / fps)
    phase = np.arange(len(robot.joints)) * 0.7
    q = amp * np.sin(2 * np.pi * 0.5 * t[:, None] + phase) + 0.1
    return Trajectory(
        t_s=t, q_rad=np.clip(q, robot.q_min_rad, robot.q_max_rad), joint_names=robot.joint_names,
        q_min_rad=robot.q_min_rad, q_max_rad=robot.q_max_rad, v_max_rad_s=robot.v_max_rad_s,
        a_max_rad_s2=robot.a_max_rad_s2, rest_q_rad=robot.rest_q_rad, silent=np.zeros(len(t), bool),
    )  # fmt: skip


def move_by_hand(bus, sid: int, tick: int) -> None:
    """Servo ``sid`` of the simulated ``bus`` is moved by hand to ``tick`` (torque is off)."""
    with bus._lock:
        s = bus.servo(sid)
        s.motion.pos = s.motion.cmd = float(tick)
        s._sync_feedback()
