"""The model matches the paper: window 10 past + 20 ahead, 70-frame sequences, annealing 16/8/4, sizes."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from robogest.errors import MissingDependencyError

torch = pytest.importorskip("torch")

from robogest.generators.learned.gesticulator import (  # noqa: E402
    SPEC,
    GesticulatorConfig,
    GesticulatorNet,
    teacher_forcing_period,
    uses_ground_truth,
)


def test_paper_hyper_parameters():
    c = GesticulatorConfig()
    assert (c.past, c.future, c.window, c.train_frames, c.sequence_length) == (10, 20, 30, 40, 70)
    assert c.window * c.frame_dim == 3720  # §4.4: 124 per frame x 30 frames
    assert c.hidden == (612, 256) and c.cond_dim == 512 and c.n_prev_poses == 3
    assert (c.dropout, c.pose_dropout, c.pretrain_epochs) == (0.2, 0.8, 7)
    net = GesticulatorNet(c)
    assert net.layer1[0].in_features == 3720 and net.output.in_features == 256
    assert net.pose_encoder[2].p == 0.8 and net.layer1[2].p == 0.2


def test_annealing_schedule_matches_paper():
    """§4.3: 7 epochs without autoregression, one without teacher forcing, then every 16, 8, 4 frames, then always."""
    periods = [teacher_forcing_period(e) for e in range(14)]
    assert periods == [None] * 7 + [0, 16, 8, 4, 1, 1, 1]
    # Ground truth for two consecutive frames at each teacher-forcing point, counted over the 40 predicted frames.
    assert [k for k in range(40) if uses_ground_truth(k, 16)] == [0, 1, 16, 17, 32, 33]
    assert [k for k in range(16) if uses_ground_truth(k, 8)] == [0, 1, 8, 9]
    assert [k for k in range(8) if uses_ground_truth(k, 4)] == [0, 1, 4, 5]
    assert all(uses_ground_truth(k, 1) for k in range(40))
    assert not any(uses_ground_truth(k, p) for k in range(40) for p in (0, None))


def _small(**kw) -> GesticulatorNet:
    torch.manual_seed(0)
    return GesticulatorNet(GesticulatorConfig(n_acoustic=4, n_text=3, n_pose=6, **kw)).eval()


@pytest.mark.parametrize("period", [None, 1])
def test_window_is_10_past_and_20_ahead(period):
    """Pose of frame t depends on speech frames t-10 .. t+19 and on nothing outside (no autoregression)."""
    net = _small()
    x = torch.randn(1, 70, 7)
    y = net(x, None, None)  # (1, 40, 6): frames 10..49
    assert y.shape == (1, 40, 6)
    t, k = 30, 20  # frame 30 is output k = 20
    for frame, inside in [(t - 10, True), (t + 19, True), (t - 11, False), (t + 20, False)]:
        x2 = x.clone()
        x2[0, frame] += 5.0
        changed = not torch.allclose(net(x2, None, None)[0, k], y[0, k])
        assert changed == inside, frame
    if period is not None:  # autoregression carries the past further back, never the future
        x2 = x.clone()
        x2[0, t + 20 :] += 5.0
        torch.testing.assert_close(net(x2, None, period)[0, : k + 1], net(x, None, period)[0, : k + 1])


def test_loss_uses_the_40_central_frames_and_velocity_term():
    net = _small()
    cfg = net.config
    x, y = torch.randn(2, 70, 7), torch.randn(2, 70, 6)
    pred = net(x, y, None)
    target = y[:, 10:50]
    mse = torch.mean((pred - target) ** 2)
    vel = torch.mean(((pred[:, 1:] - pred[:, :-1]) - (target[:, 1:] - target[:, :-1])) ** 2)
    torch.testing.assert_close(SPEC.loss(net, x, y, 0, cfg), mse + 0.6 * vel)


def test_teacher_forcing_feeds_ground_truth():
    """With period 1 the output depends on the ground-truth poses; with period 0 (own predictions) it does not."""
    net = _small()
    with torch.no_grad():
        net.film.weight.normal_()  # FiLM starts as the identity; make the conditioning matter
    x, y = torch.randn(1, 70, 7), torch.randn(1, 70, 6)
    y2 = y.clone()
    y2[:, 20:] += 3.0
    assert not torch.allclose(net(x, y, 1)[0, 11:], net(x, y2, 1)[0, 11:])
    torch.testing.assert_close(net(x, y, 0), net(x, y2, 0))  # only the seed frames 7..9 are read


@pytest.mark.parametrize("epoch", [0, 8, 20])
def test_validation_is_a_free_running_rollout_at_every_epoch(epoch):
    """best.pt is chosen on the rollout generation does (mean-pose seed, own poses fed back), whatever the epoch's
    teacher forcing: the teacher-forced loss changes with the ground-truth poses, the validation loss does not."""
    net = _small().eval()
    with torch.no_grad():
        net.film.weight.normal_()
    cfg = net.config
    x, y = torch.randn(2, 70, 7), torch.randn(2, 70, 6)
    y2 = y.clone()
    y2[:, :10] += 3.0  # seed poses and ground truth outside the 40 scored frames
    y2[:, 50:] += 3.0
    with torch.no_grad():
        val = SPEC.validation_loss(net, x, y, epoch, cfg)
        torch.testing.assert_close(SPEC.validation_loss(net, x, y2, epoch, cfg), val)
        free = net(x, None, 1)  # what GesticulatorGenerator.predict runs
        target = y[:, 10:50]
        vel = torch.mean(((free[:, 1:] - free[:, :-1]) - (target[:, 1:] - target[:, :-1])) ** 2)
        torch.testing.assert_close(val, torch.mean((free - target) ** 2) + 0.6 * vel)
        if epoch >= 11:  # full teacher forcing: the training loss reads the ground truth, the validation does not
            assert not torch.allclose(SPEC.loss(net, x, y, epoch, cfg), SPEC.loss(net, x, y2, epoch, cfg))


def test_stream_equals_batch():
    """infer_stream (frame by frame, 1 s look-ahead) gives the same poses as predict on the whole input."""
    from robogest.data import FeatureConfig
    from robogest.data.prep import Normalization
    from robogest.generators.learned.gesticulator import GesticulatorGenerator

    net = _small()
    with torch.no_grad():
        net.film.weight.normal_(std=0.1)
    norm = Normalization(
        np.zeros(4, np.float32), np.ones(4, np.float32), np.zeros(6, np.float32), np.ones(6, np.float32)
    )
    gen = GesticulatorGenerator.from_model(net, FeatureConfig(text_encoder="hash-test"), norm)
    for n in (5, 45):  # shorter and longer than the window
        x = np.random.default_rng(n).standard_normal((n, 7)).astype(np.float32)
        streamed = np.stack(list(gen.infer_stream(iter(x))))
        assert streamed.shape == (n, 6)
        np.testing.assert_allclose(streamed, gen.predict(x), atol=1e-5)


def test_stream_look_ahead_is_one_second():
    """The pose of frame 0 comes out when frame 19 (the 20th, 1 s at 20 fps) has been read."""
    from robogest.data import FeatureConfig
    from robogest.data.prep import Normalization
    from robogest.generators.learned.gesticulator import GesticulatorGenerator

    norm = Normalization(
        np.zeros(4, np.float32), np.ones(4, np.float32), np.zeros(6, np.float32), np.ones(6, np.float32)
    )
    gen = GesticulatorGenerator.from_model(_small(), FeatureConfig(text_encoder="hash-test"), norm)
    read: list[int] = []

    def frames():
        for i in range(30):
            read.append(i)
            yield np.zeros(7, np.float32)

    stream = gen.infer_stream(frames())
    next(stream)
    assert read[-1] == 19


def test_missing_torch_raises_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)  # makes `import torch` fail
    for name in [m for m in sys.modules if m.startswith("robogest.generators.learned.gesticulator")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(MissingDependencyError, match=r"pip install -e '.*\[learn\]'"):
        import robogest.generators.learned.gesticulator  # noqa: F401
    from robogest.learn import require_torch

    with pytest.raises(MissingDependencyError, match=r"install it with: .*pip install -e '.*\[learn\]'"):
        require_torch()


def test_generator_without_checkpoint_is_input_error(tmp_path):
    from robogest.errors import InputError
    from robogest.generators.learned.gesticulator import GesticulatorGenerator

    with pytest.raises(InputError, match="--checkpoint"):
        GesticulatorGenerator()
    with pytest.raises(InputError, match="not found"):
        GesticulatorGenerator(tmp_path / "nope.pt")
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="not a readable checkpoint"):
        GesticulatorGenerator(tmp_path / "bad.pt")
