"""Issue 31 end to end on the synthetic floating-base humanoid (tests/robots/humanoid_fixture.py): `speak --save`
gestures with both arms and the head while the held legs stay exactly at rest; a robot whose retargeting check
fails is refused by speak, play, serve and Robot(...) with exit code 3 and one line, before any work."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml

from robogest.cli.main import main
from robogest.errors import ConfigError
from robogest.tools.validate import _FOLLOW_CACHE
from robogest.trajectory import Trajectory
from tests.robots.humanoid_fixture import ARMS, LEGS, robot_yaml, write_humanoid

SENTENCE = "Hello! I am glad to meet you. Look over there, and then we can start."


@pytest.mark.slow
def test_speak_save_arms_gesture_legs_stay_head_moves(tmp_path, capsys):
    path = write_humanoid(tmp_path)
    out = tmp_path / "s.npz"
    assert main(["speak", SENTENCE, "--robot", str(path), "--save", str(out)]) == 0
    traj = Trajectory.load(out)
    ptp = dict(zip(traj.joint_names, np.ptp(traj.q_rad, axis=0), strict=True))
    for side in ("l", "r"):
        assert max(ptp[n] for n in ARMS[side]) >= 0.3, ptp
    legs = [traj.joint_names.index(n) for n in LEGS]
    assert np.array_equal(traj.q_rad[:, legs], np.broadcast_to(traj.rest_q_rad[legs], (traj.n_frames, len(legs))))
    assert max(ptp["neck_pan"], ptp["neck_tilt"]) > 0.05


def _unfollowable(tmp_path):
    """The humanoid with its left upper-arm link's sites swapped: that link points away from the bone."""
    path = write_humanoid(tmp_path)
    raw = robot_yaml()
    raw["retarget"][2]["robot"] = raw["retarget"][2]["robot"][::-1]
    path.write_text(yaml.safe_dump(raw))
    return path


REFUSED = r"fails the retargeting check.*retarget\[2\].*deg away.*`robogest robots validate .*` lists every problem"


@pytest.mark.parametrize("command", ["speak", "play", "serve"])
def test_a_robot_that_cannot_follow_is_refused_with_exit_3_before_any_work(tmp_path, capsys, command):
    path = _unfollowable(tmp_path)
    out = tmp_path / "s.npz"
    motion = tmp_path / "m.npz"
    motion.write_bytes(b"not read: the robot is refused first")
    argv = {"speak": ["speak", SENTENCE, "--save", str(out)], "play": ["play", str(motion)], "serve": ["serve"]}
    assert main([*argv[command], "--robot", str(path)]) == 3
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert re.search(REFUSED, err), err
    assert not out.exists()


def test_robot_session_refuses_it_too(tmp_path):
    from robogest.live import Robot

    with pytest.raises(ConfigError, match=REFUSED):
        Robot(str(_unfollowable(tmp_path)), warm_up=False)


def test_the_check_is_cached_per_definition_and_model_content(tmp_path):
    from robogest.robot.config import load_robot_config
    from robogest.tools.validate import follow_problems

    robot = load_robot_config(write_humanoid(tmp_path, held=[*LEGS, *ARMS["l"]]))
    _FOLLOW_CACHE.clear()
    assert follow_problems(robot) == [] and len(_FOLLOW_CACHE) == 1
    follow_problems(robot)
    assert len(_FOLLOW_CACHE) == 1
    robot.model_path.write_text(robot.model_path.read_text() + "\n<!-- edited -->\n")
    follow_problems(robot)
    assert len(_FOLLOW_CACHE) == 2  # an edited model is checked again


@pytest.mark.slow
def test_speak_video_frames_the_upper_body_like_the_framing_camera(tmp_path, capsys):
    """The CLI's video comes through the framing camera (tests/sim/test_framing.py checks what it frames): its first
    frame, the robot at rest, is the PNG render of the rest pose at the same size, up to H.264's loss."""
    av = pytest.importorskip("av")
    from matplotlib import image as mpimg

    from robogest.backends.render import render_png
    from robogest.errors import MissingDependencyError
    from robogest.robot.config import load_robot_config

    path = write_humanoid(tmp_path)
    try:
        png = render_png(load_robot_config(path), None, tmp_path / "rest.png", 96, 72)
    except MissingDependencyError as e:
        pytest.skip(f"no offscreen GL here: {e}")
    video = tmp_path / "s.mp4"
    assert main(["speak", "Hello there.", "--robot", str(path), "--video", str(video), "--video-size", "96x72"]) == 0
    with av.open(str(video)) as c:
        first = next(c.decode(video=0)).to_ndarray(format="rgb24").astype(float)
    rest = mpimg.imread(png)[..., :3] * 255.0
    assert first.shape == rest.shape == (72, 96, 3)
    assert np.abs(first - rest).mean() < 8.0  # of 255; another camera differs by tens
