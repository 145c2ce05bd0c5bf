"""The optional pretrained speech encoder, with a tiny randomly initialised wav2vec2 saved to a temp folder (no
download): loading, per-frame features aligned with the audio, and clear errors naming the path."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
transformers = pytest.importorskip("transformers")

from robogest.errors import InputError  # noqa: E402
from robogest.generators.learned.speech_encoder import PretrainedSpeechEncoder, load_speech_encoder  # noqa: E402


@pytest.fixture(scope="module")
def tiny_wav2vec2(tmp_path_factory):
    """A 2-layer, 16-d wav2vec2 (hop 20 samples) saved with ``save_pretrained``."""
    config = transformers.Wav2Vec2Config(
        hidden_size=16, num_hidden_layers=2, num_attention_heads=2, intermediate_size=24, conv_dim=(8, 8),
        conv_stride=(5, 4), conv_kernel=(10, 8), num_conv_pos_embeddings=8, num_conv_pos_embedding_groups=2,
    )  # fmt: skip
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("w2v")
    transformers.Wav2Vec2Model(config).save_pretrained(path)
    return path


def test_frames_follow_the_audio_at_the_frame_rate(tiny_wav2vec2):
    enc = load_speech_encoder(tiny_wav2vec2)
    assert enc is load_speech_encoder(tiny_wav2vec2)  # loaded once per process
    assert (enc.dim, enc.sample_rate, enc.hop, enc.field) == (16, 16000, 20, 45)
    rng = np.random.default_rng(0)
    audio = np.concatenate([np.zeros(8000), rng.standard_normal(8000)]).astype(np.float32)  # silence, then noise
    feats = enc.frames(audio, 16000, 20, 20.0)  # 1 s at 20 fps
    assert feats.shape == (20, 16) and feats.dtype == np.float32 and np.isfinite(feats).all()
    louder = audio.copy()
    louder[12000:] *= 3.0  # the features follow the audio
    assert not np.allclose(enc.frames(louder, 16000, 20, 20.0)[15:], feats[15:])
    assert enc.frames(audio[:10], 16000, 1, 20.0).shape == (1, 16)  # shorter than one output frame


def test_long_audio_goes_in_chunks_on_one_grid(tiny_wav2vec2, monkeypatch):
    from robogest.generators.learned import speech_encoder

    enc = load_speech_encoder(tiny_wav2vec2)
    calls: list[int] = []
    encode = enc._encode
    monkeypatch.setattr(enc, "_encode", lambda a: calls.append(a.size) or encode(a))
    monkeypatch.setattr(speech_encoder, "CHUNK_S", 0.25)
    feats = enc.frames(np.random.default_rng(1).standard_normal(16000).astype(np.float32), 16000, 20, 20.0)
    assert feats.shape == (20, 16) and len(calls) == 4 and all(n % enc.hop == 0 for n in calls)


def test_errors_name_the_path(tmp_path, tiny_wav2vec2):
    with pytest.raises(InputError, match=rf"speech encoder {tmp_path / 'nope'}: no config\.json"):
        PretrainedSpeechEncoder(tmp_path / "nope")
    bert = tmp_path / "bert"
    transformers.BertConfig(
        hidden_size=8, num_hidden_layers=1, num_attention_heads=2, intermediate_size=8
    ).save_pretrained(bert)
    with pytest.raises(InputError, match=rf"speech encoder {bert}: a 'bert' checkpoint, not a wav2vec2-family"):
        PretrainedSpeechEncoder(bert)
    no_weights = tmp_path / "no_weights"
    no_weights.mkdir()
    (no_weights / "config.json").write_text((tiny_wav2vec2 / "config.json").read_text())
    with pytest.raises(InputError, match=rf"speech encoder {no_weights}: its weights cannot be loaded"):
        PretrainedSpeechEncoder(no_weights)
    with pytest.raises(InputError, match=r"audio at 8000 Hz, the model reads 16000 Hz"):
        load_speech_encoder(tiny_wav2vec2).frames(np.zeros(800, np.float32), 8000, 2, 20.0)


def test_rhythmic_takes_its_high_level_features_from_the_encoder(tiny_wav2vec2, fixture_data, tmp_path):
    """``--set speech_encoder=PATH``: the checkpoint records the encoder and its width, the lexeme interpreters read
    its features as ``a_high`` (the log-mel's conv layers stay ``a_low``), and the model generates from speech."""
    from robogest.generators.learned import train_model
    from robogest.generators.learned.rhythmic import RhythmicGenerator
    from robogest.learn.checkpoint import load_checkpoint
    from robogest.learn.trainer import TrainConfig
    from robogest.speech import synthesize
    from tests.generators.learned.conftest import HASH16, RHYTHMIC_SMALL

    cfg = TrainConfig(
        model="rhythmic", data=str(fixture_data), out=str(tmp_path / "o"), epochs=4, lr=2e-3, batch_size=8,
        window_stride=30, val_fraction=0.0, device="cpu", cache_dir=str(tmp_path / "cache"),
        model_overrides={**RHYTHMIC_SMALL, "speech_encoder": str(tiny_wav2vec2)}, **HASH16,
    )  # fmt: skip
    best = train_model(cfg, log=lambda s: None)
    mc = load_checkpoint(best)["model_config"]
    assert mc["speech_encoder"] == str(tiny_wav2vec2) and mc["speech_dim"] == 16
    gen = RhythmicGenerator(best)
    net, c = gen.model, gen.config
    assert c.n_audio == c.n_mels + 16 and net.high_dim == 16 and net.low_dim == RHYTHMIC_SMALL["audio_channels"]
    blocks = torch.randn(3, c.block, c.n_audio)
    a_low, a_high, _ = net.audio_features(blocks)
    torch.testing.assert_close(a_high, blocks[..., c.n_mels :])  # the encoder's features, block by block
    torch.testing.assert_close(a_low, net.audio(blocks[..., : c.n_mels])[net.low_index])
    speech = synthesize("Hello there, I am a robot and I wave.")
    motion = gen.generate(speech)
    assert motion.n_frames == speech.n_frames and np.isfinite(motion.rotations).all()

    bert = tmp_path / "bert"
    transformers.BertConfig(
        hidden_size=8, num_hidden_layers=1, num_attention_heads=2, intermediate_size=8
    ).save_pretrained(bert)
    bad = TrainConfig(**{**cfg.__dict__, "out": str(tmp_path / "p"), "model_overrides": {"speech_encoder": str(bert)}})
    with pytest.raises(InputError, match=rf"speech encoder {bert}: a 'bert' checkpoint"):
        train_model(bad, log=lambda s: None)
    assert not (tmp_path / "p" / "last.pt").exists()
