import numpy as np
import pytest

from robogest.errors import InputError
from robogest.motion import CANONICAL, load_motion, load_smplx
from robogest.motion import rotations as R
from robogest.motion.smplx import SMPLX_INDEX


def _poses(n: int, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(-0.5, 0.5, size=(n, 165))


def test_upper_body_rotations_copy_joint_for_joint(tmp_path):
    rng = np.random.default_rng(0)
    poses = _poses(12, rng)
    trans = np.tile([0.1, 1.29, -0.2], (12, 1))
    path = tmp_path / "a.npz"
    np.savez(path, poses=poses.astype(np.float32), trans=trans, mocap_frame_rate=np.int32(30), betas=np.zeros(300))
    m = load_motion(path)
    assert m.skeleton is CANONICAL and m.fps == 30.0 and m.n_frames == 12
    aa = poses.astype(np.float32).astype(float).reshape(12, 55, 3)
    for name, i in SMPLX_INDEX.items():
        got = m.rotations[:, CANONICAL.index(name)]
        want = R.normalize(R.from_axis_angle(aa[:, i]))
        assert np.allclose(got, want, atol=1e-9), name
    assert np.allclose(m.rotations[:, CANONICAL.index("l_hand")], R.IDENTITY)
    assert m.root_pos_m[0, 1] == pytest.approx((1.29 - 0.35) / 0.94)


def test_amass_zup_keys(tmp_path):
    n = 5
    root = np.tile([np.pi / 2, 0, 0], (n, 1))  # AMASS: body up (+Y model) rotated to world +Z
    path = tmp_path / "amass.npz"
    np.savez(
        path, root_orient=root, pose_body=np.zeros((n, 63)), trans=np.tile([0, 0, 0.9], (n, 1)), mocap_framerate=120.0
    )
    m = load_smplx(path)
    assert m.fps == 120.0
    pos = m.positions()
    assert np.allclose(m.rotations[:, 0], R.IDENTITY, atol=1e-9)  # upright in canonical Y-up
    assert (pos[:, CANONICAL.index("head"), 1] > pos[:, 0, 1] + 0.3).all()


def test_errors(tmp_path):
    with pytest.raises(InputError, match="no such SMPL-X file"):
        load_smplx(tmp_path / "none.npz")
    p = tmp_path / "x.npz"
    np.savez(p, trans=np.zeros((3, 3)))
    with pytest.raises(InputError, match=r"x\.npz: no 'poses' array \(keys: trans\)"):
        load_smplx(p)
    np.savez(p, poses=np.zeros((3, 165)))
    with pytest.raises(InputError, match=r"no frame rate.*fps="):
        load_smplx(p)
    assert load_smplx(p, fps=25).fps == 25
    np.savez(p, poses=np.zeros((3, 10)), mocap_frame_rate=30)
    with pytest.raises(InputError, match="'poses' must be"):
        load_smplx(p)
    p.write_text("not a zip")
    with pytest.raises(InputError, match=r"not a readable \.npz"):
        load_smplx(p)


def test_a_file_with_no_frames_is_one_line(tmp_path):
    """``poses`` shaped (0, 165) was a numpy reshape traceback."""
    np.savez(tmp_path / "p.npz", poses=np.zeros((0, 165)), trans=np.zeros((0, 3)), mocap_frame_rate=30.0)
    np.savez(tmp_path / "a.npz", root_orient=np.zeros((0, 3)), pose_body=np.zeros((0, 63)), mocap_frame_rate=30.0)
    for name in ("p.npz", "a.npz"):
        with pytest.raises(InputError, match=rf"{name}: the file has no frames"):
            load_smplx(tmp_path / name)


def test_an_all_zero_unused_array_is_no_decompression_bomb(tmp_path, rng):
    """Only the arrays used are checked and loaded: a compressed file whose (unused) expressions are all zeros
    expands 1000x and would be refused as a decompression bomb; poses that do are still refused."""
    poses = rng.normal(scale=0.1, size=(30, 165))
    np.savez_compressed(tmp_path / "a.npz", poses=poses, expressions=np.zeros((20_000, 100)), mocap_frame_rate=30.0)
    assert load_smplx(tmp_path / "a.npz").n_frames == 30
    np.savez_compressed(tmp_path / "b.npz", poses=np.zeros((20_000, 165)), mocap_frame_rate=30.0)
    with pytest.raises(InputError, match=r"b\.npz: array 'poses' expands from \d+ to 26400128 bytes"):
        load_smplx(tmp_path / "b.npz")


def test_save_smplx_is_load_smplxs_inverse_in_beat2s_layout(tmp_path):
    """Canonical motion -> SMPL-X .npz (BEAT2's keys and shapes) -> the same canonical motion."""
    from robogest.motion import HumanMotion, save_motion

    rng = np.random.default_rng(1)
    n = 20
    rot = np.broadcast_to(R.IDENTITY, (n, CANONICAL.n_joints, 4)).copy()
    for name in SMPLX_INDEX:
        rot[:, CANONICAL.index(name)] = R.from_axis_angle(rng.uniform(-0.6, 0.6, (n, 3)))
    root = np.c_[rng.uniform(-0.1, 0.1, n), np.full(n, 1.0), rng.uniform(-0.1, 0.1, n)]
    motion = HumanMotion(fps=30.0, rotations=rot, root_pos_m=root, skeleton=CANONICAL)
    path = tmp_path / "g.npz"
    save_motion(motion, path)
    d = np.load(path)
    assert {k: d[k].shape for k in d.files} == {
        "poses": (n, 165), "trans": (n, 3), "betas": (300,), "expressions": (n, 100), "mocap_frame_rate": (),
        "model": (), "gender": (),
    }  # fmt: skip
    assert d["poses"].dtype == np.float32 and int(d["mocap_frame_rate"]) == 30 and str(d["model"]) == "smplx2020"
    legs = [i for i in range(55) if i not in SMPLX_INDEX.values()]
    assert not d["poses"].reshape(n, 55, 3)[:, legs].any()  # legs, jaw, eyes, fingers at zero
    back = load_smplx(path)
    assert back.fps == 30.0 and back.n_frames == n
    for name in SMPLX_INDEX:
        j = CANONICAL.index(name)
        same = np.abs(np.sum(back.rotations[:, j] * rot[:, j], axis=-1))  # |<q1, q2>| = 1: same rotation
        assert np.allclose(same, 1.0, atol=1e-6), name
    np.testing.assert_allclose(back.root_pos_m, root, atol=1e-9)


def test_motion_is_written_only_as_bvh_or_smplx(tmp_path):
    from robogest.motion import HumanMotion, save_motion

    motion = HumanMotion(fps=30.0, rotations=np.broadcast_to(R.IDENTITY, (3, CANONICAL.n_joints, 4)).copy(),
                         root_pos_m=np.zeros((3, 3)), skeleton=CANONICAL)  # fmt: skip
    with pytest.raises(InputError, match=r"m\.txt: cannot write motion as '\.txt'; name the file \.bvh .* or \.npz"):
        save_motion(motion, tmp_path / "m.txt")
    assert not (tmp_path / "m.txt").exists()


@pytest.mark.shared
def test_a_beat2_take_survives_export_and_reload(shared_data, tmp_path):
    """Real BEAT2 motion onto the canonical skeleton, exported, read back: the same upper-body motion."""
    from robogest.motion import save_smplx

    m = load_smplx(shared_data / "beat2" / "2_scott_0_1_1.npz")
    save_smplx(m, tmp_path / "b.npz")
    back = load_smplx(tmp_path / "b.npz")
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-5)  # joint positions, metres
