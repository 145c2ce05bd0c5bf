"""The BEAT2/EMAGE FGD evaluator: architecture pinned to the reference's state dict, loader checks, FGD sanity."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from robogest.errors import InputError
from robogest.eval.fgd import axis_angle_to_rot6d, check_poses
from robogest.eval.fgd.topology import LATENT_DIM, edge_chains, encoder_plan, smplx_edges

#: Every key and shape of EMAGE's ``VAESKConv`` state dict (``AESKConv_240_100.bin``, key prefix ``module.``
#: removed), written out from the reference code (emage_evaltools/motion_encoder.py, skeleton.py,
#: skeleton_DME.py, decoders.py with vae_length=240, vae_layer=4, vae_grow=[1, 1, 2, 1], vae_test_dim=330):
#: encoder layers pool 55 -> 35 -> 20 edges, layers 2-3 keep 20 edges (no pooling matrix), 20 x 12 = 240.
OFFICIAL_SHAPES: dict[str, tuple[int, ...]] = {
    "fc_mu.weight": (240, 240),
    "fc_mu.bias": (240,),
    "fc_logvar.weight": (240, 240),
    "fc_logvar.bias": (240,),
    "encoder.layers.0.0.residual.0.weight": (330, 330, 4),
    "encoder.layers.0.0.residual.0.bias": (330,),
    "encoder.layers.0.0.residual.0.mask": (330, 330, 4),
    "encoder.layers.0.0.residual.1.weight": (330,),
    "encoder.layers.0.0.residual.1.bias": (330,),
    "encoder.layers.0.0.shortcut.weight": (330, 330, 1),
    "encoder.layers.0.0.shortcut.bias": (330,),
    "encoder.layers.0.0.shortcut.mask": (330, 330, 1),
    "encoder.layers.0.0.common.0.weight": (210, 330),
    "encoder.layers.1.0.residual.0.weight": (210, 210, 4),
    "encoder.layers.1.0.residual.0.bias": (210,),
    "encoder.layers.1.0.residual.0.mask": (210, 210, 4),
    "encoder.layers.1.0.residual.1.weight": (210,),
    "encoder.layers.1.0.residual.1.bias": (210,),
    "encoder.layers.1.0.shortcut.weight": (210, 210, 1),
    "encoder.layers.1.0.shortcut.bias": (210,),
    "encoder.layers.1.0.shortcut.mask": (210, 210, 1),
    "encoder.layers.1.0.common.0.weight": (120, 210),
    "encoder.layers.2.0.residual.0.weight": (240, 120, 4),
    "encoder.layers.2.0.residual.0.bias": (240,),
    "encoder.layers.2.0.residual.0.mask": (240, 120, 4),
    "encoder.layers.2.0.residual.1.weight": (240,),
    "encoder.layers.2.0.residual.1.bias": (240,),
    "encoder.layers.2.0.shortcut.weight": (240, 120, 1),
    "encoder.layers.2.0.shortcut.bias": (240,),
    "encoder.layers.2.0.shortcut.mask": (240, 120, 1),
    "encoder.layers.3.0.residual.0.weight": (240, 240, 4),
    "encoder.layers.3.0.residual.0.bias": (240,),
    "encoder.layers.3.0.residual.0.mask": (240, 240, 4),
    "encoder.layers.3.0.residual.1.weight": (240,),
    "encoder.layers.3.0.residual.1.bias": (240,),
    "encoder.layers.3.0.shortcut.weight": (240, 240, 1),
    "encoder.layers.3.0.shortcut.bias": (240,),
    "encoder.layers.3.0.shortcut.mask": (240, 240, 1),
    "decoder.main.0.model.0.weight": (240, 240, 3),
    "decoder.main.0.model.0.bias": (240,),
    "decoder.main.0.model.2.weight": (240, 240, 3),
    "decoder.main.0.model.2.bias": (240,),
    "decoder.main.1.model.0.weight": (240, 240, 3),
    "decoder.main.1.model.0.bias": (240,),
    "decoder.main.1.model.2.weight": (240, 240, 3),
    "decoder.main.1.model.2.bias": (240,),
    "decoder.main.3.weight": (240, 240, 3),
    "decoder.main.3.bias": (240,),
    "decoder.main.6.weight": (240, 240, 3),
    "decoder.main.6.bias": (240,),
    "decoder.main.9.weight": (240, 240, 3),
    "decoder.main.9.bias": (240,),
    "decoder.main.12.weight": (330, 240, 3),
    "decoder.main.12.bias": (330,),
    "decoder.main.14.weight": (330, 330, 3),
    "decoder.main.14.bias": (330,),
}


def test_topology_matches_the_reference_sizes():
    plan = encoder_plan()
    assert [layer.n_edges for layer in plan] == [55, 35, 20, 20]
    assert [len(layer.groups) for layer in plan] == [35, 20, 20, 20]
    assert [layer.pools for layer in plan] == [True, True, False, False]
    assert len(plan[-1].groups) * plan[-1].out_per_edge == LATENT_DIM
    edges = smplx_edges()
    assert edges[0] == (0, 55) and edges[21] == (19, 21) and edges[54] == (53, 54)
    chains = edge_chains(edges)
    assert sorted(i for c in chains for i in c) == list(range(55))  # every edge in exactly one chain
    assert [0] in chains and [3, 6, 9] in chains  # virtual root edge; spine up to the branching spine3


def test_rot6d_is_the_first_two_rows_of_the_rotation_matrix():
    poses = np.zeros((1, 165))
    poses[0, 3 * 5 + 2] = np.pi / 2  # joint 5 rotated 90 degrees about z
    r6 = axis_angle_to_rot6d(poses).reshape(55, 6)
    np.testing.assert_allclose(r6[5], [0, -1, 0, 1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(r6[0], [1, 0, 0, 0, 1, 0], atol=1e-12)


@pytest.mark.parametrize(
    ("poses", "fps", "match"),
    [
        (np.zeros((64, 66)), 30.0, r"poses: FGD needs SMPL-X axis-angle poses \(T, 165\).*\(64, 66\)"),
        (np.zeros((64, 165)), 20.0, r"trained at 30 fps, got 20 fps; resample to 30"),
        (np.zeros((31, 165)), 30.0, r"at least 32 frames"),
        (np.full((64, 165), np.nan), 30.0, r"NaN"),
    ],
)
def test_bad_poses_are_refused(poses, fps, match):
    with pytest.raises(InputError, match=match):
        check_poses(poses, fps=fps)


def test_importing_fgd_does_not_import_torch():
    code = "import sys, robogest.eval.fgd, robogest.eval.report; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


# ------------------------------------------------------------------------------------------- with torch


@pytest.fixture(scope="module")
def torch():
    return pytest.importorskip("torch")


@pytest.fixture(scope="module")
def weights(torch, tmp_path_factory):
    """A file laid out like the published one, with random weights of the official shapes."""
    from robogest.eval.fgd.network import MotionAutoencoder

    torch.manual_seed(0)
    model = MotionAutoencoder()
    path = tmp_path_factory.mktemp("fgd") / "AESKConv_240_100.bin"
    state = {f"module.{k}": v for k, v in model.state_dict().items()}  # saved from DDP, as the original
    torch.save({"model_state": state, "epoch": 100}, path)
    return path, model


def test_network_state_dict_matches_the_official_table(torch):
    from robogest.eval.fgd.network import MotionAutoencoder

    got = {k: tuple(v.shape) for k, v in MotionAutoencoder().state_dict().items()}
    assert got == OFFICIAL_SHAPES


def _motion(n: int = 640, seed: int = 0) -> np.ndarray:
    """Smooth synthetic SMPL-X poses ``(n, 165)``: each joint angle a slow sinusoid with a random phase."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None] / 30.0
    return 0.3 * np.sin(2 * np.pi * rng.uniform(0.2, 1.5, 165) * t + rng.uniform(0, 2 * np.pi, 165))


def test_round_trip_gives_the_saved_network(torch, weights):
    from robogest.eval.fgd import load_evaluator

    path, model = weights
    ev = load_evaluator(path)
    x = _motion(100)
    feats = ev.features(x)
    assert feats.shape == (6, 240)  # 100 frames -> cut to 96 -> 96 / 16 latent frames
    ref = model.eval().encode(torch.from_numpy(axis_angle_to_rot6d(x[:96]).astype(np.float32))[None])[0]
    np.testing.assert_allclose(feats, ref.detach().numpy(), rtol=1e-5, atol=1e-6)


def test_bare_state_dict_also_loads(torch, weights, tmp_path):
    from robogest.eval.fgd import load_evaluator

    _, model = weights
    path = tmp_path / "bare.bin"
    torch.save(model.state_dict(), path)
    assert load_evaluator(path).features(_motion(64)).shape == (4, 240)


def _save_modified(torch, model, tmp_path, edit):
    state = dict(model.state_dict())
    edit(state)
    path = tmp_path / "bad.bin"
    torch.save({"model_state": state}, path)
    return path


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (
            lambda s: s.__setitem__(
                "encoder.layers.2.0.residual.0.weight", s["encoder.layers.2.0.residual.0.weight"][:, :, :3]
            ),
            r"bad\.bin: not the BEAT2/EMAGE FGD evaluator: 1 tensors of another shape "
            r"\(encoder\.layers\.2\.0\.residual\.0\.weight \(240, 120, 3\) != \(240, 120, 4\)\)\. Download",
        ),
        (lambda s: s.pop("fc_mu.bias"), r"missing 1 keys \(fc_mu\.bias\)"),
        (lambda s: s.__setitem__("encoder.extra", s["fc_mu.bias"]), r"1 unexpected keys \(encoder\.extra\)"),
        (
            lambda s: s["encoder.layers.0.0.shortcut.mask"].fill_(1.0),
            r"skeleton masks/pooling differ from the SMPL-X tree \(encoder\.layers\.0\.0\.shortcut\.mask\)",
        ),
    ],
)
def test_a_file_of_another_network_is_refused(torch, weights, tmp_path, edit, match):
    from robogest.eval.fgd import load_evaluator
    from robogest.eval.fgd.network import MotionAutoencoder

    path = _save_modified(torch, MotionAutoencoder(), tmp_path, edit)
    with pytest.raises(InputError, match=match):
        load_evaluator(path)


def test_missing_and_unreadable_files_say_where_to_get_the_weights(torch, tmp_path):
    from robogest.eval.fgd import load_evaluator

    with pytest.raises(InputError, match=r"nope\.bin: no such FGD weights file\. Download .*huggingface\.co/H-Liu1997"):
        load_evaluator(tmp_path / "nope.bin")
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(InputError, match=r"junk\.bin: cannot read as torch weights"):
        load_evaluator(junk)


def test_fgd_is_zero_for_identical_motion_and_grows_with_noise(torch, weights):
    from robogest.eval.fgd import fgd, load_evaluator

    ev = load_evaluator(weights[0])
    real = _motion(960)
    assert fgd(real, real, ev) == pytest.approx(0.0, abs=1e-6)
    rng = np.random.default_rng(1)
    scores = [fgd(real, real + rng.normal(0, s, real.shape), ev) for s in (0.02, 0.1, 0.3)]
    assert 0 < scores[0] < scores[1] < scores[2]


def test_several_takes_are_pooled(torch, weights):
    from robogest.eval.fgd import load_evaluator

    ev = load_evaluator(weights[0])
    a, b = _motion(320, 1), _motion(320, 2)
    pooled = ev.fgd([a, b], [a, b])
    assert pooled == pytest.approx(0.0, abs=1e-6)
    assert ev.fgd([a, b], [a, a]) > 0


def _smplx_file(path, poses: np.ndarray, fps: float = 30.0) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, poses=poses, trans=np.zeros((len(poses), 3)), mocap_frame_rate=np.float64(fps))


def test_eval_cli_reports_fgd_per_file_and_pooled(torch, weights, tmp_path, capsys):
    import json

    from robogest.cli.main import main

    real_a, real_b = _motion(320, 1), _motion(320, 2)
    _smplx_file(tmp_path / "gt" / "a.npz", real_a)
    _smplx_file(tmp_path / "gt" / "b.npz", real_b)
    _smplx_file(tmp_path / "pred" / "a.npz", real_a)  # a perfect copy
    _smplx_file(tmp_path / "pred" / "b.npz", real_b + np.random.default_rng(3).normal(0, 0.2, real_b.shape))
    out = tmp_path / "m.json"
    args = ["eval", "--pred", str(tmp_path / "pred"), "--gt", str(tmp_path / "gt"), "--fgd-weights", str(weights[0])]
    assert main([*args, "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    a, b = data["results"]["a"]["fgd"], data["results"]["b"]["fgd"]
    assert a["fgd"] == pytest.approx(0.0, abs=1e-6) and b["fgd"] > 0.01
    assert a["real_vs_real"] > 0 and a["n_latent_pred"] == a["n_latent_gt"] == 20
    assert data["fgd_pooled"]["n_files"] == 2 and data["fgd_pooled"]["n_latent_gt"] == 40
    assert "_features" not in a
    text = capsys.readouterr().out
    assert "FGD, BEAT2 evaluator (real vs real)" in text and "FGD pooled over 2 files" in text


def test_eval_cli_fgd_needs_smplx_pairs(torch, weights, tmp_path, capsys):
    from robogest.cli.main import main

    _smplx_file(tmp_path / "p.npz", _motion(64))
    np.savez(tmp_path / "g.npz", poses=_motion(64)[:, :66], trans=np.zeros((64, 3)), mocap_frame_rate=30.0)
    base = ["eval", "--pred", str(tmp_path / "p.npz"), "--fgd-weights", str(weights[0])]
    assert main(base) != 0
    assert "p.npz: --fgd-weights compares with ground truth; pass --gt" in capsys.readouterr().err
    assert main([*base, "--gt", str(tmp_path / "g.npz")]) != 0
    assert "g.npz: --fgd-weights needs SMPL-X .npz files with 'poses' (T, 165)" in capsys.readouterr().err
