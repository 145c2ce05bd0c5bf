"""Rhythmic Gesticulator as the paper describes it (issue 33): speaker ID into the lexeme interpreter (eq. 16, not
the generator of eq. 5), one learnable style code per training block (§5.2-5.3), and ``best.pt`` chosen on
free-running generation of held-out speech (eq. 15) among the generator-stage epochs too."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robogest.data import FeatureConfig, discover_takes, load_take  # noqa: E402
from robogest.data.prep import Normalization  # noqa: E402
from robogest.errors import InputError  # noqa: E402
from tests.generators.learned.conftest import HASH16, RHYTHMIC_SMALL  # noqa: E402

K = 10  # D_M = 0.5 s at 20 fps


@pytest.fixture(scope="module")
def setup(fixture_data, tmp_path_factory):
    """Two training takes named as BEAT2 speakers 1 and 2, the third a held-out take; their config and windows."""
    from robogest.generators.learned.rhythmic import SPEC
    from robogest.speech import load_speech

    cache = tmp_path_factory.mktemp("rpcache")
    files = discover_takes(fixture_data)
    takes = [load_take(f, FeatureConfig(**HASH16), cache_dir=cache) for f in files]
    takes = [dataclasses.replace(t, name=f"{i + 1}_spk_0_1_1") for i, t in enumerate(takes)]
    train, held_out = takes[:2], takes[2]
    norm = Normalization.fit(train)
    cfg = SPEC.make_config(69, train[0].text.shape[1], 51, {**RHYTHMIC_SMALL, "silent_augment": 0.0})
    cfg = SPEC.plan_epochs(SPEC.fit_config(cfg, train), 4)
    x, y, idx = SPEC.make_windows(train, norm, cfg, cfg.window_blocks * K, 20)
    vx, vy, _ = SPEC.make_windows([held_out], norm, cfg, cfg.window_blocks * K, 40)
    speech = load_speech(files[0].audio, files[0].transcript)
    return {"train": train, "norm": norm, "cfg": cfg, "x": x[:], "y": y[:], "idx": idx, "vx": vx[:], "vy": vy[:],
            "speech": speech}  # fmt: skip


def _net(cfg, seed: int = 0):
    from robogest.generators.learned.rhythmic import RhythmicNet

    torch.manual_seed(seed)
    return RhythmicNet(cfg).eval()


def test_speaker_id_goes_into_the_lexeme_interpreter_not_the_generator(setup):
    """Eq. 16: P_s(s_{i-1}, A^H, T, I); eq. 5 and eq. 19 take no speaker."""
    from robogest.generators.learned.rhythmic import RhythmicGenerator

    cfg, x = setup["cfg"], setup["x"]
    assert cfg.speakers == ("1", "2")
    np.testing.assert_array_equal(x[:, 0, -2], setup["idx"])  # every window carries its take's speaker
    net = _net(cfg)
    assert "speaker" not in inspect.signature(net.gen.forward).parameters
    assert not any("speaker" in n for n, _ in net.gen.named_parameters())
    assert net.style_interp.speaker is None and net.style_interp_audio.speaker is None
    n = 4
    h3 = torch.randn(n, K, 3 * net.high_dim)
    text, ctx = torch.randn(n, K, cfg.n_text), torch.randn(n, cfg.lexeme_dim)
    with torch.no_grad():
        for lex in (net.lex_interp, net.lex_interp_audio):
            a = lex(h3, text, ctx, torch.zeros(n, dtype=torch.long))
            b = lex(h3, text, ctx, torch.ones(n, dtype=torch.long))
            assert not torch.allclose(a, b)  # the lexeme logits depend on who speaks
    feats = FeatureConfig(**HASH16)
    one = RhythmicGenerator.from_model(net, feats, setup["norm"], speaker="1").generate_blocks(setup["speech"])
    same = RhythmicGenerator.from_model(net, feats, setup["norm"], speaker=0).generate_blocks(setup["speech"])
    np.testing.assert_array_equal(one.poses, same.poses)
    with pytest.raises(InputError, match=r"speaker '7' is not one of the model's speakers \['1', '2'\]"):
        RhythmicGenerator.from_model(net, feats, setup["norm"], speaker="7")


def test_style_code_is_a_learned_parameter_per_training_block(setup):
    """§5.3: {z_i} are free variables trained with the generator, one per training block; the generator stage's
    loss reads them (not a code encoded from the target block) and trains exactly the batch's blocks' rows."""
    cfg, x, y = setup["cfg"], setup["x"], setup["y"]
    train = setup["train"]
    assert cfg.style_takes == tuple(t.name for t in train) and len(cfg.style_rows) == 3
    net = _net(cfg).train()
    assert net.style_codes.weight.shape == (cfg.style_rows[-1], cfg.style_dim)
    rows = x[:, ::K, -1].astype(int)  # (N, W) every block's row
    assert rows.min() >= 0 and rows.max() < cfg.style_rows[-1]
    first = rows[setup["idx"] == 0][0]
    np.testing.assert_array_equal(first, np.arange(cfg.window_blocks) + first[0])  # consecutive blocks, own rows
    assert (setup["vx"][:, ::K, -1] == -1).all()  # a held-out take has no style codes (its come from P_z)
    xb, yb = torch.from_numpy(x[:6]), torch.from_numpy(y[:6])
    gen_epoch = cfg.stage_ends[1]
    net.before_step(xb, yb, epoch=1)
    net.zero_grad(set_to_none=True)
    net(xb, yb, epoch=gen_epoch).backward()
    grad_rows = set(torch.nonzero(net.style_codes.weight.grad.abs().sum(1)).flatten().tolist())
    assert grad_rows == set(rows[:6, 1:-1].flatten().tolist())  # the sample blocks' codes, nothing else
    with torch.no_grad():
        torch.manual_seed(1)
        before = float(net(xb, yb, epoch=gen_epoch))
        net.style_codes.weight[rows[:6, 1:-1].flatten()] += 3.0
        torch.manual_seed(1)
        assert float(net(xb, yb, epoch=gen_epoch)) != before


def test_selection_score_is_free_running(setup):
    """The held-out score is eq. 15's generation: it changes with the lexeme interpreter and ignores the target's
    context block (a teacher-forced or ground-truth-seeded rollout would read it)."""
    from robogest.generators.learned.rhythmic import SPEC
    from robogest.generators.learned.rhythmic.freerun import free_run, window_inputs

    cfg = setup["cfg"]
    net = _net(cfg)
    vx, vy = torch.from_numpy(setup["vx"]), torch.from_numpy(setup["vy"])
    assert vx.shape[0] >= 2
    with torch.no_grad():
        score = float(SPEC.validation_loss(net, vx, vy, cfg.stage_ends[1], cfg))
        other_context = vy.clone()
        other_context[:, :K] += 5.0  # each window's first block: context only
        assert float(SPEC.validation_loss(net, vx, other_context, cfg.stage_ends[1], cfg)) == score
        _, lex = free_run(net, window_inputs(net, net.segment(vx, vy)), force_silent=False)
        favourite = int(torch.mode(lex.flatten()).values)
        for interp in (net.lex_interp, net.lex_interp_audio):
            interp.head.bias[(favourite + 1) % cfg.lexicon_size] += 100.0  # another lexeme everywhere
        _, lex2 = free_run(net, window_inputs(net, net.segment(vx, vy)), force_silent=False)
        assert not torch.equal(lex, lex2)
        assert float(SPEC.validation_loss(net, vx, vy, cfg.stage_ends[1], cfg)) != score


def test_a_generator_stage_epoch_best_on_free_running_validation_is_picked(fixture_data, tmp_path, monkeypatch):
    """Rigged: the generator-stage epoch scores best on the (real) free-running validation score plus a rig that
    favours it; best.pt must be that epoch. Epochs before the generator trains are never picked."""
    from robogest.generators.learned import train_model
    from robogest.generators.learned.rhythmic import training
    from robogest.learn.checkpoint import load_checkpoint
    from robogest.learn.trainer import TrainConfig

    real = training.RhythmicSpec.validation_loss
    seen = []

    def rigged(self, model, speech, poses, epoch, config):
        seen.append(epoch)
        score = real(self, model, speech, poses, epoch, config)
        return score - 1e3 if config.stage_at(epoch) == "generator" else score

    monkeypatch.setattr(training.RhythmicSpec, "validation_loss", rigged)
    cfg = TrainConfig(
        model="rhythmic", data=str(fixture_data), out=str(tmp_path / "r"), epochs=4, batch_size=16,
        window_stride=20, val_fraction=0.34, device="cpu", cache_dir=str(tmp_path / "c"),
        model_overrides=RHYTHMIC_SMALL, **HASH16,
    )  # fmt: skip
    best = train_model(cfg, log=lambda s: None)
    ckpt = load_checkpoint(best)
    assert set(seen) == {0, 1, 2, 3}  # every epoch is scored on held-out windows
    assert ckpt["train_state"]["stage"] == "generator" and ckpt["train_state"]["next_epoch"] == 3


def test_checkpoint_from_before_is_refused_with_the_file_and_the_fix(setup, tmp_path):
    """A checkpoint from before the per-block style codes cannot load: one line naming the file and 'retrain'."""
    from robogest.generators.learned.rhythmic import SPEC, RhythmicGenerator
    from robogest.learn.checkpoint import FORMAT, VERSION, save_checkpoint

    old = dataclasses.asdict(setup["cfg"])
    del old["style_takes"], old["style_rows"]
    path = save_checkpoint(
        {
            "format": FORMAT,
            "version": VERSION,
            "model_name": "rhythmic",
            "model_config": old,
            "model_state": {},
            "feature_config": dataclasses.asdict(FeatureConfig(**HASH16)),
            "normalization": {},
        },
        tmp_path / "old.pt",
    )
    with pytest.raises(InputError) as e:
        RhythmicGenerator(path)
    msg = str(e.value)
    assert str(path) in msg and "retrain" in msg and "\n" not in msg
    with pytest.raises(InputError, match=r"--resume: .*retrain"):
        SPEC.config_from_dict(old)
