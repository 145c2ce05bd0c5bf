"""Rhythmic Gesticulator: beat blocks round-trip, the lexicon/generator/interpreters learn, CLI and generation work."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robogest.data import FeatureConfig, discover_takes, load_take  # noqa: E402
from robogest.data.fixtures import FIXTURE_GESTURE  # noqa: E402
from robogest.data.prep import Normalization  # noqa: E402
from robogest.errors import InputError  # noqa: E402
from robogest.generators.learned.rhythmic.blocks import (  # noqa: E402
    block_fraction,
    clip_bounds,
    denormalize_blocks,
    normalize_clips,
    resample_clip,
    tsm_mel_blocks,
)
from robogest.motion.skeleton import CANONICAL  # noqa: E402
from tests.generators.learned.conftest import HASH16, RHYTHMIC_SMALL  # noqa: E402

SMALL = RHYTHMIC_SMALL
K = 10  # D_M = 0.5 s at 20 fps


@pytest.fixture(scope="module")
def takes_and_speech(fixture_data, tmp_path_factory):
    from robogest.speech import load_speech

    cache = tmp_path_factory.mktemp("rcache")
    out = []
    for f in discover_takes(fixture_data):
        out.append((load_take(f, FeatureConfig(**HASH16), cache_dir=cache), load_speech(f.audio, f.transcript)))
    return out


@pytest.fixture(scope="module")
def rhythmic_run(fixture_data, tmp_path_factory):
    """Last checkpoint of one short overfit run on the fixture (no validation split): the four stages one after
    another (4 + 6 + 11 + 9 epochs). Without validation windows ``best.pt`` follows the train loss, which compares
    different stages' objectives, so the tests take the fully trained last epoch."""
    from robogest.generators.learned import train_model
    from robogest.learn.trainer import TrainConfig

    out = tmp_path_factory.mktemp("rrun")
    cfg = TrainConfig(
        model="rhythmic", data=str(fixture_data), out=str(out), epochs=30, lr=2e-3, batch_size=8, window_stride=6,
        val_fraction=0.0, device="cpu", cache_dir=str(out / "cache"), model_overrides=SMALL, **HASH16,
    )  # fmt: skip
    return train_model(cfg, log=lambda s: None).parent / "last.pt"


def _moving(poses: np.ndarray) -> np.ndarray:
    cols = [CANONICAL.index(j) * 3 + axis for j, (axis, _, _) in FIXTURE_GESTURE.items()]
    return poses[:, cols]


# ------------------------------------------------------------------------------------------------ blocks (numpy)
def test_blocks_round_trip_to_the_frame(takes_and_speech):
    """Normalise a take's motion at its speech beats, denormalise: same frame count, error within the bound.

    Endpoint-aligned linear resampling reproduces piecewise-linear motion exactly; for a clip of ``n <= K`` frames
    the block grid is finer than the frame grid, so each frame's error is a chord across at most one kink of the
    frames' interpolant: at most ``|Δ²x| · h / 4`` with ``h = (n - 1) / (K - 1) <= 1``, i.e. a quarter of the
    largest second difference. Clips of ``K + 1`` frames (a 0.5 s interval rounding up) get ``h = 10 / 9``.
    """
    take, speech = takes_and_speech[0]
    bounds = clip_bounds(speech.beats_s, take.n_frames, take.fps)
    lengths = np.diff(bounds)
    assert lengths.sum() == take.n_frames and lengths.min() >= 1 and lengths.max() <= K + 1
    blocks = normalize_clips(take.poses, bounds, K)
    assert blocks.shape == (len(lengths), K, take.poses.shape[1])
    back = denormalize_blocks(blocks, lengths)
    assert back.shape == take.poses.shape
    d2 = np.abs(np.diff(take.poses, 2, axis=0)).max()
    err = np.abs(back - take.poses).max()
    assert d2 > 1e-3 and err <= 0.25 * (10 / 9) * d2 + 1e-6, (err, d2)
    # piecewise-linear motion (a ramp) and clips of exactly K frames round-trip exactly
    ramp = np.linspace(0, 1, take.n_frames)[:, None].astype(np.float32)
    np.testing.assert_allclose(denormalize_blocks(normalize_clips(ramp, bounds, K), lengths), ramp, atol=1e-6)
    x = np.random.default_rng(0).standard_normal((K, 3)).astype(np.float32)
    np.testing.assert_allclose(resample_clip(resample_clip(x, K), K), x, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1])
def test_denormalised_length_is_exact_for_any_clips(seed):
    rng = np.random.default_rng(seed)
    lengths = rng.integers(1, 25, size=40)
    out = denormalize_blocks(rng.standard_normal((40, K, 4)).astype(np.float32), lengths)
    assert out.shape == (lengths.sum(), 4)
    bounds = clip_bounds(np.sort(rng.uniform(0, 10, 30)), 200, 20.0)
    assert bounds[0] == 0 and bounds[-1] == 200 and np.all(np.diff(bounds) >= 1)


def test_tsm_audio_blocks_reproduce_the_front_end_and_scale_like_it(takes_and_speech):
    """Phase-vocoder TSM + fresh mel analysis (what training and inference use).

    A clip of exactly K frames is not stretched (rate 1) and gives the front-end's own log-mel frames; other clips'
    loud block spectra agree with time-scaling the log-mel frames (correlation > 0.9).
    """
    take, speech = takes_and_speech[0]
    bounds = clip_bounds(speech.beats_s, take.n_frames, take.fps)
    tsm = tsm_mel_blocks(speech.audio, speech.sr, bounds, take.fps, K)
    feat = normalize_clips(speech.features.mel_db, bounds, K)
    assert tsm.shape == feat.shape == (len(bounds) - 1, K, 64)
    exact = np.flatnonzero(np.diff(bounds) == K)
    assert exact.size > 0
    np.testing.assert_allclose(tsm[exact], feat[exact], atol=0.05)
    loud = feat.mean(axis=(1, 2)) > np.percentile(feat.mean(axis=(1, 2)), 50)
    a, b = tsm[loud].mean(axis=1), feat[loud].mean(axis=1)  # block spectra (n, 64)
    r = np.mean([np.corrcoef(x, y)[0, 1] for x, y in zip(a, b, strict=True)])
    assert r > 0.9, r


def test_tsm_preserves_pitch_where_resampling_the_waveform_does_not():
    """A 1 kHz tone in a 5-frame clip stretched to K = 10 frames stays in its mel band; stretching the same clip by
    resampling the samples (no TSM) halves its pitch, which the test would see as another band."""
    import librosa

    from robogest.speech.features import log_mel_db

    sr, fps = 16000, 20.0
    t = np.arange(sr) / sr
    tone = (0.5 * np.sin(2 * np.pi * 1000 * t)).astype(np.float32)
    bounds = np.array([0, 5, 20])  # the first clip: 5 frames -> rate 4/9
    tsm = tsm_mel_blocks(tone, sr, bounds, fps, K)
    band = int(np.argmax(log_mel_db(tone, sr, 800, 1600, 64)[10]))
    assert np.all(tsm[0, 2:-2].argmax(axis=1) == band)
    slowed = librosa.resample(tone[: 5 * 800], orig_sr=sr, target_sr=sr * 9 / 4, res_type="polyphase")
    assert int(np.argmax(log_mel_db(slowed, sr, 800, 1600, 64)[4])) < band - 3


def _no_words(take):
    import dataclasses

    return dataclasses.replace(take, text=np.full_like(take.text, -15.0))


def test_take_without_words_yields_silent_and_speech_blocks(takes_and_speech):
    """Without any transcript the training windows still mark silent blocks (mostly quiet, §6.4.1) and speech
    blocks; with the transcript a block is silent exactly when it overlaps no word."""
    from robogest.generators.learned.rhythmic import SPEC, RhythmicConfig, RhythmicNet, take_rhythm

    takes = [t for t, _ in takes_and_speech]
    norm = Normalization.fit(takes)
    cfg = RhythmicConfig(n_text=takes[0].text.shape[1], **SMALL)
    net = RhythmicNet(cfg)
    take, speech = takes_and_speech[0]
    length = cfg.window_blocks * K
    for t in (take, _no_words(take)):
        x, y, _ = SPEC.make_windows([t], norm, cfg, length, 30)
        assert x.shape[1:] == (length, cfg.n_mels + cfg.n_text + 3) and y.shape[1:] == (length, cfg.n_pose)
        empty = net.segment(torch.from_numpy(x[:]), torch.from_numpy(y[:])).empty.numpy()
        assert empty.any() and not empty.all(), empty.mean()
    mel = norm.acoustic(take.acoustic)[:, :64]
    bounds, silent = take_rhythm(mel, take.acoustic[:, :64], _no_words(take).text, cfg)
    assert silent.any() and not silent.all()
    # the frame-domain quiet rule agrees with the speech front-end's silence flag on those blocks
    front = block_fraction(speech.features.silence.astype(bool), bounds)
    assert front[silent].mean() > 0.5 > front[~silent].mean(), (front[silent].mean(), front[~silent].mean())
    bounds_w, silent_w = take_rhythm(mel, take.acoustic[:, :64], take.text, cfg)
    words = ~np.all(take.text <= -15 + 1e-3, axis=1)
    np.testing.assert_array_equal(bounds_w, bounds)  # beats come from the audio features only
    np.testing.assert_array_equal(silent_w, block_fraction(words, bounds) == 0)


# ------------------------------------------------------------------------------------------------ lexicon
def test_vq_vae_reconstruction_falls_and_codebook_is_used(takes_and_speech):
    from robogest.generators.learned.rhythmic import MotionVQ, RhythmicConfig

    takes = [t for t, _ in takes_and_speech]
    norm = Normalization.fit(takes)
    blocks = np.concatenate(
        [normalize_clips(norm.pose(t.poses), clip_bounds(s.beats_s, t.n_frames, t.fps), K) for t, s in takes_and_speech]
    )
    x = torch.from_numpy(blocks)
    torch.manual_seed(0)
    vq = MotionVQ(RhythmicConfig(vq_channels=32, lexicon_size=12))
    opt = torch.optim.Adam(vq.parameters(), lr=3e-3)
    errs = []
    for _ in range(150):
        xb = x[torch.randint(0, x.shape[0], (64,))]
        vq.maintain(vq.encode(xb).detach())  # the trainer's before_step: start and dead-code restarts
        loss, rec, _ = vq(xb)
        opt.zero_grad()
        loss.backward()
        opt.step()
        errs.append(float(rec))
    vq.eval()
    with torch.no_grad():
        _, rec, idx = vq(x)
    assert float(rec) < 0.3 * np.mean(errs[:5]), (float(rec), errs[:5])
    assert len(set(idx.tolist())) > 1


# ------------------------------------------------------------------------------------------------ trained model
def _gt_codes(gen, take, speech):
    from robogest.generators.learned.rhythmic import take_rhythm
    from robogest.generators.learned.rhythmic.take import take_beats

    beats = take_beats(take.read_audio(gen.config.audio_sr), gen.config)  # how training cuts a cached take
    mel = gen.norm.acoustic(take.acoustic)[:, :64]
    bounds, _ = take_rhythm(mel, take.acoustic[:, :64], take.text, gen.config, beats)
    assert np.array_equal(bounds, gen.generate_blocks(speech).bounds)  # one rule: the speech front-end's beats
    assert np.array_equal(bounds, clip_bounds(speech.beats_s, take.n_frames, 20.0))
    pb = torch.from_numpy(normalize_clips(gen.norm.pose(take.poses), bounds, K))
    start = gen.config.style_rows[gen.config.style_takes.index(take.name)]
    with torch.no_grad():
        idx = gen.model.vq.quantize(gen.model.vq.encode(pb))
        z = gen.model.style_codes.weight[start : start + len(bounds) - 1].detach()  # the take's learned codes
    return bounds, idx.numpy(), z.numpy()


def test_generator_overfits_a_training_take(rhythmic_run, takes_and_speech):
    """Autoregressive generation of a whole training take from its own lexemes and style codes.

    RMSE on the moving joints below 0.7x their standard deviation (the mean pose scores 1.0x; measured 0.37-0.62x
    over runs), with the blocks chained on the model's own previous blocks and denormalised.
    """
    from robogest.generators.learned.rhythmic import RhythmicGenerator

    gen = RhythmicGenerator(rhythmic_run)
    take, speech = takes_and_speech[0]
    _, idx, z = _gt_codes(gen, take, speech)
    plan = gen.generate_blocks(speech, lexemes=idx, styles=z)
    gt, out = _moving(take.poses), _moving(plan.poses)
    rmse = float(np.sqrt(np.mean((out - gt) ** 2)))
    baseline = float(np.sqrt(np.mean((gt - gt.mean(axis=0)) ** 2)))
    assert baseline > 0.05 and rmse < 0.7 * baseline, (rmse, baseline)
    assert len(set(idx.tolist())) > 1  # the trained lexicon uses more than one lexeme on the take


def test_interpreter_picks_the_silent_lexeme_in_silent_blocks(rhythmic_run, takes_and_speech):
    """Without the run-time hint, the learned interpreter itself chooses silent lexemes on empty-word blocks."""
    from robogest.generators.learned.rhythmic import RhythmicGenerator

    gen = RhythmicGenerator(rhythmic_run)
    silent = gen.model.silent_mask().numpy()
    assert 0 < silent.sum() < silent.size
    hits, n_empty, hits_speech, n_speech = 0, 0, 0, 0
    for take, speech in takes_and_speech:
        plan = gen.generate_blocks(speech, force_silent=False)
        words = ~np.all(take.text <= -15 + 1e-3, axis=1)
        empty = block_fraction(words, plan.bounds) == 0
        hits += int(silent[plan.lexemes[empty]].sum())
        n_empty += int(empty.sum())
        hits_speech += int(silent[plan.lexemes[~empty]].sum())
        n_speech += int((~empty).sum())
        forced = gen.generate_blocks(speech)  # with the hint, silent blocks always get a silent lexeme
        assert silent[forced.lexemes[forced.silent]].all()
    assert n_empty >= 5 and hits / n_empty >= 0.8, (hits, n_empty)
    assert hits_speech / n_speech < 0.5  # and it does not simply always pick them


@pytest.mark.parametrize("with_words", [True, False])
def test_inference_blocks_equal_training_blocks(rhythmic_run, takes_and_speech, with_words):
    """A Speech is cut exactly where the trainer cuts the take of the same audio, the same blocks are silent and
    the audio blocks are the same time-scaled audio: both go through take_blocks (take_rhythm, tsm_mel_blocks)."""
    import dataclasses

    from robogest.generators.learned.rhythmic import SPEC, RhythmicGenerator, take_blocks

    gen = RhythmicGenerator(rhythmic_run)
    c = gen.config
    take, speech = takes_and_speech[1]
    np.testing.assert_allclose(take.acoustic[:, :64], speech.features.mel_db, atol=1e-4)
    if not with_words:
        take, speech = _no_words(take), dataclasses.replace(speech, words=())
    plan = gen.generate_blocks(speech)
    train_blocks = take_blocks(take.acoustic[:, :64], take.text, gen.norm, c, take.read_audio(c.audio_sr), take.poses)
    np.testing.assert_array_equal(plan.bounds, train_blocks.bounds)
    assert len(plan.bounds) > 10 and np.diff(plan.bounds).max() <= K + 1
    np.testing.assert_array_equal(plan.silent, train_blocks.silent)
    assert plan.silent.any() and not plan.silent.all()
    run_blocks = take_blocks(speech.features.mel_db, take.text, gen.norm, c, speech.audio)
    np.testing.assert_allclose(run_blocks.mel, train_blocks.mel, atol=1e-3)
    # the trainer's first window is the take's first W blocks laid end to end
    x, y, _ = SPEC.make_windows([take], gen.norm, c, c.window_blocks * K, 10**6)
    w = c.window_blocks
    np.testing.assert_allclose(x[0, :, :64], train_blocks.mel[:w].reshape(w * K, 64), atol=1e-6)
    np.testing.assert_allclose(y[0], train_blocks.poses[:w].reshape(w * K, -1), atol=1e-6)
    np.testing.assert_array_equal(x[0, ::K, -3] > 0.5, train_blocks.silent[:w])


def test_lexeme_entropy_and_pmb_from_generated_blocks(rhythmic_run, takes_and_speech):
    """The evaluation metrics of §7.3 (robogest.eval) run on the generator's output."""
    from robogest.eval import lexeme_entropy, motion_beats, pmb
    from robogest.generators.learned.rhythmic import RhythmicGenerator

    gen = RhythmicGenerator(rhythmic_run)
    _, speech = takes_and_speech[1]
    plan = gen.generate_blocks(speech)
    ent = lexeme_entropy(plan.lexemes, gen.config.lexicon_size)
    assert ent["entropy_nats"] > 0.0
    motion = gen.generate(speech)
    score = pmb(motion_beats(motion.positions(), motion.fps), speech.beats_s)
    assert np.isnan(score) or 0.0 <= score <= 100.0


def test_train_cli_and_generate_text_and_audio_only(fixture_data, tmp_path):
    """`robogest train --model rhythmic --set ...` (paper widths, one epoch per stage) writes a checkpoint; it
    generates on text and audio-only speech with exactly the speech's frames; by default the most likely lexeme
    (the seed does not matter), with a lexeme temperature the same for the same seed and different for another."""
    import dataclasses
    import json

    from robogest.cli.main import main
    from robogest.generators.learned.rhythmic import RhythmicGenerator
    from robogest.learn.checkpoint import load_checkpoint
    from robogest.speech import synthesize

    out = tmp_path / "o"
    rc = main(
        ["train", "--model", "rhythmic", "--data", str(fixture_data), "--out", str(out), "--epochs", "4",
         "--device", "cpu", "--text-encoder", "hash-test", "--cache-dir", str(tmp_path / "c"),
         "--window-stride", "30", "--val-fraction", "0", "--set", "lexicon_size=20", "--set", "stages=sequential"]
    )  # fmt: skip
    assert rc == 0 and (out / "best.pt").is_file()
    ckpt = load_checkpoint(out / "best.pt")
    mc = ckpt["model_config"]
    assert ckpt["model_name"] == "rhythmic" and mc["lexicon_size"] == 20 and mc["latent_groups"] == 64
    assert list(mc["stage_ends"]) == [1, 2, 3, 4]
    history = json.loads((out / "history.json").read_text())
    assert [h["stage"] for h in history] == ["encoder", "lexicon", "generator", "interpreters"]
    assert ckpt["train_state"]["next_epoch"] >= 3  # best.pt: the generator stage or later, when G is trained
    assert ckpt["train_state"]["optimizers"]["optimizer"]["param_groups"][0]["lr"] == 3e-4  # the paper's, no --lr
    gen = RhythmicGenerator(out / "last.pt")
    sampling = RhythmicGenerator(out / "last.pt", lexeme_temperature=1.0)
    speech = synthesize("Hello there, I am a robot ... and I wave.")
    for sp in (speech, dataclasses.replace(speech, words=())):
        motion = gen.generate(sp, seed=1)
        assert motion.n_frames == sp.n_frames and motion.fps == sp.fps
        assert np.isfinite(motion.rotations).all()
        np.testing.assert_array_equal(gen.generate(sp, seed=2).rotations, motion.rotations)  # most likely lexeme
        sampled = sampling.generate(sp, seed=1)
        np.testing.assert_array_equal(sampling.generate(sp, seed=1).rotations, sampled.rotations)
        # the seed drives the lexeme sampling: another seed gives other lexemes, hence other motion
        assert not np.array_equal(sampling.generate(sp, seed=2).rotations, sampled.rotations)
    with pytest.raises(InputError, match="lexeme_temperature=-1"):
        RhythmicGenerator(out / "best.pt", lexeme_temperature=-1)


def test_bad_options_and_missing_checkpoint_are_input_errors(tmp_path):
    from robogest.errors import InputError
    from robogest.generators.learned.rhythmic import SPEC, RhythmicGenerator

    with pytest.raises(InputError, match="unknown rhythmic option"):
        SPEC.make_config(69, 16, 51, {"nope": 1})
    with pytest.raises(InputError, match="--checkpoint"):
        RhythmicGenerator()
    with pytest.raises(InputError, match="not found"):
        RhythmicGenerator(tmp_path / "x.pt")
    with pytest.raises(InputError, match=r"lexicon_size='big': expected int"):
        SPEC.make_config(69, 16, 51, {"lexicon_size": "big"})
    with pytest.raises(InputError, match="stages='staged'"):
        SPEC.make_config(69, 16, 51, {"stages": "staged"})


def test_paper_widths_are_the_defaults():
    """§5.3 and §7.1.2: H = 64, C = 128, d_m~ = d_a~ = 128, d_s = 192, d_z = d_P = 32, N_s = 50, lr 3e-4, D_M 0.5 s."""
    from robogest.generators.learned.rhythmic import RhythmicConfig

    c = RhythmicConfig()
    got = (c.latent_groups, c.latent_classes, c.motion_feat_dim, c.audio_feat_dim, c.lexeme_dim, c.style_dim,
           c.pe_dim, c.lexicon_size, c.lr, c.block, c.audio_layers, c.low_layer)  # fmt: skip
    assert got == (64, 128, 128, 128, 192, 32, 32, 50, 3e-4, 10, 8, 2)


def test_plan_epochs_gives_every_stage_its_share():
    from robogest.errors import InputError
    from robogest.generators.learned.rhythmic import SPEC

    def ends(epochs, **kw):
        return SPEC.plan_epochs(SPEC.make_config(69, 16, 51, kw), epochs).stage_ends

    assert ends(4) == (1, 2, 3, 4)
    assert ends(30) == (4, 10, 21, 30)  # weights 1:2:4:3 on the 26 epochs beyond one each, largest remainders
    assert ends(20, audio_encoder="mel") == (0, 5, 13, 20)  # a parameter-free encoder has nothing to pre-train
    c = SPEC.plan_epochs(SPEC.make_config(69, 16, 51, {}), 30)
    assert [c.stage_at(e) for e in (0, 3, 4, 20, 21, 29, 35)] == [
        "encoder", "encoder", "lexicon", "generator", "interpreters", "interpreters", "interpreters"
    ]  # fmt: skip
    assert SPEC.first_best_epoch(c) == 10  # the first generator-stage epoch
    with pytest.raises(InputError, match=r"needs --epochs >= 4 \(got 3\).*stages=joint"):
        ends(3)
    joint = SPEC.plan_epochs(SPEC.make_config(69, 16, 51, {"stages": "joint"}), 1)
    assert joint.stage_ends == () and joint.stage_at(0) is None and SPEC.first_best_epoch(joint) == 0


def test_each_sequential_stage_trains_only_its_own_part(takes_and_speech):
    """In training mode the loss at an epoch of stage X gives gradients to X's parameters and to nothing else."""
    from robogest.generators.learned.rhythmic import SPEC, STAGES, RhythmicNet

    takes = [t for t, _ in takes_and_speech]
    norm = Normalization.fit(takes)
    cfg = SPEC.plan_epochs(SPEC.make_config(69, takes[0].text.shape[1], 51, SMALL), 4)
    x, y, _ = SPEC.make_windows(takes, norm, cfg, cfg.window_blocks * K, 20)
    torch.manual_seed(0)
    net = RhythmicNet(cfg).train()
    owners = {
        "encoder": ("audio.", "proj_t.", "proj_a."),
        "lexicon": ("vq.",),
        "generator": ("gen.", "style_codes."),
        "interpreters": ("lex_interp", "style_interp"),
    }
    for epoch, stage in enumerate(STAGES):
        if stage == "generator":  # the generator's silent-block augmentation needs the lexicon's statistics
            net.before_step(torch.from_numpy(x[:16]), torch.from_numpy(y[:16]), epoch=1)
        net.zero_grad(set_to_none=True)
        net(torch.from_numpy(x[:16]), torch.from_numpy(y[:16]), epoch=epoch).backward()
        with_grad = {n for n, p in net.named_parameters() if p.grad is not None and float(p.grad.abs().sum()) > 0}
        assert with_grad, stage
        assert all(n.startswith(owners[stage]) for n in with_grad), (stage, sorted(with_grad)[:5])


def test_resumed_run_keeps_its_stage_plan(fixture_data, tmp_path):
    """A run resumed with more epochs keeps the checkpoint's stage plan: the extra epochs train the interpreters."""
    import json

    from robogest.generators.learned import train_model
    from robogest.learn.checkpoint import load_checkpoint
    from robogest.learn.trainer import TrainConfig

    kw = dict(
        model="rhythmic", data=str(fixture_data), out=str(tmp_path / "r"), batch_size=16, window_stride=20,
        val_fraction=0.0, device="cpu", cache_dir=str(tmp_path / "c"), model_overrides=SMALL, **HASH16,
    )  # fmt: skip
    train_model(TrainConfig(epochs=4, **kw), log=lambda s: None)
    best = train_model(TrainConfig(epochs=6, resume=True, **kw), log=lambda s: None)
    history = json.loads((tmp_path / "r" / "history.json").read_text())
    assert [h["stage"] for h in history] == ["encoder", "lexicon", "generator"] + ["interpreters"] * 3
    assert list(load_checkpoint(best)["model_config"]["stage_ends"]) == [1, 2, 3, 4]


def test_generator_trains_on_a_rollout_with_its_state_carried_over(takes_and_speech):
    """Generator stage (as the authors' code): within a window each block is generated from the previous generated
    block and the LSTM state after it; only the window's first block is ground truth. Eval mode (the teacher-forced
    sum of the stages' objectives) runs the same rollout."""
    from robogest.generators.learned.rhythmic import SPEC, RhythmicNet

    takes = [t for t, _ in takes_and_speech]
    norm = Normalization.fit(takes)
    cfg = SPEC.plan_epochs(SPEC.make_config(69, takes[0].text.shape[1], 51, {**SMALL, "silent_augment": 0.0}), 4)
    x, y, _ = SPEC.make_windows(takes, norm, cfg, cfg.window_blocks * K, 20)
    xb, yb = torch.from_numpy(x[:3]), torch.from_numpy(y[:3])
    torch.manual_seed(0)
    net = RhythmicNet(cfg)
    calls = []
    real = net.gen.forward

    def spy(prev, a3, s, z, state=None):
        out, new_state = real(prev, a3, s, z, state)
        calls.append((prev, state, out, new_state))
        return out, new_state

    net.gen.forward = spy
    for mode in (net.train, net.eval):
        mode()
        calls.clear()
        with torch.no_grad():
            net(xb, yb, epoch=2)  # the generator stage in training; all stages in eval
        chain = calls[: cfg.window_blocks - 2]  # the rollout; then eq. 12's one-step call
        assert len(calls) == cfg.window_blocks - 1
        first = yb.reshape(3 * cfg.window_blocks, K, -1)[:: cfg.window_blocks]
        torch.testing.assert_close(chain[0][0], first)  # starts from each window's ground-truth context block
        assert chain[0][1] is None
        for (_, _, out, st), (prev, state, _, _) in itertools.pairwise(chain):
            assert prev is out and state is st  # its own output and LSTM state go on


def test_speak_saves_lexemes_and_eval_reports_their_entropy(rhythmic_run, fixture_data, tmp_path, capsys):
    """`robogest speak --generator rhythmic --save` keeps the blocks' lexemes in the trajectory file;
    `robogest eval --json` reports their entropy (eq. 23) from that file alone."""
    import json

    from robogest.cli.main import main
    from robogest.generators.learned.rhythmic import RhythmicGenerator
    from robogest.speech import load_speech
    from robogest.trajectory.types import Trajectory

    take = discover_takes(fixture_data)[1]
    saved = tmp_path / "talk.npz"
    rc = main(["speak", "--audio", str(take.audio), "--transcript", str(take.transcript), "--generator", "rhythmic",
               "--checkpoint", str(rhythmic_run), "--save", str(saved)])  # fmt: skip
    assert rc == 0
    notes = Trajectory.load(saved).annotations
    gen = RhythmicGenerator(rhythmic_run)
    gen.generate(load_speech(take.audio, take.transcript))
    np.testing.assert_array_equal(notes["lexemes"], gen.annotations["lexemes"])
    assert (
        int(notes["n_lexemes"]) == SMALL["lexicon_size"] and len(notes["block_bounds_s"]) == len(notes["lexemes"]) + 1
    )
    out = tmp_path / "m.json"
    assert main(["eval", "--pred", str(saved), "--json", str(out)]) == 0
    ent = json.loads(out.read_text())["results"]["talk"]["lexeme_entropy"]
    from robogest.eval import lexeme_entropy

    expected = lexeme_entropy(gen.annotations["lexemes"], SMALL["lexicon_size"])
    assert ent["entropy_nats"] == pytest.approx(expected["entropy_nats"]) and ent["entropy_nats"] > 0
    assert ent["n_blocks"] == len(notes["lexemes"]) and ent["n_lexemes"] == SMALL["lexicon_size"]
    assert "lexeme entropy (nats)" in capsys.readouterr().out
