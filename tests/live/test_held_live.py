"""A live session on the synthetic humanoid (sim, time-scaled): batch say, streamed speech (the planner) and idle
motion in between never send its held legs anything but their rest angle."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.live import Robot
from robogest.robot.config import load_robot_config
from robogest.speech import synthesize
from tests.robots.humanoid_fixture import LEGS, write_humanoid


@pytest.mark.slow
def test_say_stream_and_idle_keep_the_legs_exactly_at_rest(tmp_path):
    path = write_humanoid(tmp_path)
    robot = load_robot_config(path)
    goals: list[np.ndarray] = []
    sp = synthesize("Hello there, how are you?")
    pcm = np.round(sp.audio * 32767).astype(np.int16)
    with Robot(str(path), time_scale=10.0, audio=False, warm_up=False, on_tick=lambda t, q: goals.append(q)) as rob:
        assert rob.say("Nice to meet you.").wait(60)
        with rob.stream(sp.sr) as s:
            for i in range(0, len(pcm), 320):
                s.feed(pcm[i : i + 320])
        assert s.wait(60)
        plan = s.planner.feed.q_rad
        rob.loop.run_for(0.5)  # idle motion
    q = np.array(goals)
    legs = [robot.joint_names.index(n) for n in LEGS]
    assert np.array_equal(q[:, legs], np.broadcast_to(robot.rest_q_rad[legs], (len(q), len(legs))))
    assert np.array_equal(plan[:, legs], np.broadcast_to(robot.rest_q_rad[legs], (len(plan), len(legs))))
    assert np.ptp(q, axis=0).max() > 0.1  # the rest of it gestured
