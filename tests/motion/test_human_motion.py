import numpy as np
import pytest

from robogest.errors import InputError
from robogest.motion import CANONICAL, HumanMotion
from robogest.motion import rotations as R


def _wave(n: int, fps: float) -> HumanMotion:
    t = np.arange(n) / fps
    rot = np.broadcast_to(R.IDENTITY, (n, CANONICAL.n_joints, 4)).copy()
    rot[:, CANONICAL.index("l_shoulder")] = R.from_axis_angle(np.outer(0.8 * np.sin(2 * np.pi * t), [0, 0, 1]))
    root = np.stack([0.1 * t, np.ones(n), np.zeros(n)], axis=1)
    return HumanMotion(fps, rot, root)


def test_resample_preserves_duration_and_content():
    m = _wave(91, 30.0)
    up = m.resample(60.0)
    assert up.fps == 60.0
    assert up.duration_s == pytest.approx(m.duration_s, abs=1 / 60)
    assert np.allclose(up.rotations[::2], m.rotations[: len(up.rotations[::2])], atol=1e-9)
    down = m.resample(15.0)
    assert down.duration_s == pytest.approx(m.duration_s, abs=1 / 15)
    assert np.allclose(down.root_pos_m[:, 0], 0.1 * down.t_s)
    assert np.allclose(np.linalg.norm(down.rotations, axis=-1), 1.0)


def test_resample_to_an_exact_frame_count_holds_or_drops_the_end():
    m = _wave(91, 30.0)
    free = m.resample(20.0)  # 91 frames at 30 fps -> 61 at 20 fps
    longer, shorter = m.resample(20.0, n_frames=64), m.resample(20.0, n_frames=58)
    assert (longer.n_frames, shorter.n_frames, longer.fps) == (64, 58, 20.0)
    np.testing.assert_array_equal(longer.rotations[: free.n_frames], free.rotations)
    np.testing.assert_array_equal(longer.rotations[free.n_frames :], np.repeat(free.rotations[-1:], 3, axis=0))
    np.testing.assert_array_equal(longer.root_pos_m[-1], free.root_pos_m[-1])
    np.testing.assert_array_equal(shorter.rotations, free.rotations[:58])
    same = m.resample(30.0, n_frames=91)
    np.testing.assert_array_equal(same.rotations, m.rotations)


def test_positions_shape_and_rest():
    m = HumanMotion.rest(4, 25.0)
    assert m.positions().shape == (4, CANONICAL.n_joints, 3)
    assert m.duration_s == pytest.approx(4 / 25)


def test_invalid_motion_rejected():
    m = HumanMotion.rest(2, 30.0)
    bad = m.rotations.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        HumanMotion(30.0, bad, m.root_pos_m)
    with pytest.raises(InputError, match="frame rate"):
        HumanMotion(0.0, m.rotations, m.root_pos_m)
    with pytest.raises(InputError, match="target frame rate"):
        m.resample(-1)
