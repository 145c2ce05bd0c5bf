"""The rhythmic model's block cache (beats and time-scaled audio blocks kept across launches) and the process-group
timeout: what a multi-GPU launch needs so that rank 0 does not redo hours of CPU work while the others wait."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robogest.data.datasets import load_dataset  # noqa: E402
from robogest.data.features import FeatureConfig  # noqa: E402
from robogest.data.prep import Normalization  # noqa: E402
from robogest.errors import InputError  # noqa: E402

FCFG = FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": 16})


@pytest.fixture(scope="module")
def takes(fixture_data, tmp_path_factory):
    return load_dataset(fixture_data, FCFG, tmp_path_factory.mktemp("feat"))[:2]


def _windows(takes, cfg, tmp: Path, name: str, cache):
    from robogest.generators.learned.rhythmic import SPEC

    norm = Normalization.fit(takes)
    x, y, idx = SPEC.make_windows(
        takes, norm, cfg, cfg.window_blocks * cfg.block, 10, store=tmp / name, cache_dir=cache
    )
    return np.asarray(x[: len(x)]), np.asarray(y[: len(y)]), idx


@pytest.mark.slow
def test_second_launch_reads_the_blocks_and_gets_the_same_windows(takes, tmp_path, monkeypatch):
    from robogest.generators.learned.rhythmic import SPEC
    from robogest.generators.learned.rhythmic import cache as block_cache

    cfg = SPEC.make_config(takes[0].acoustic.shape[1], takes[0].text.shape[1], takes[0].poses.shape[1], {})
    plain = _windows(takes, cfg, tmp_path, "plain", None)  # computed, nothing kept
    assert not (tmp_path / "c").exists()
    first = _windows(takes, cfg, tmp_path, "first", tmp_path / "c")
    entries = sorted((tmp_path / "c" / block_cache.FOLDER).iterdir())
    assert len(entries) == len(takes)

    def no_tsm(*a, **k):
        raise AssertionError("time-scaled the audio again")

    monkeypatch.setattr(block_cache, "tsm_mel_blocks", no_tsm)
    monkeypatch.setattr(type(takes[0]), "read_audio", no_tsm)
    second = _windows(takes, cfg, tmp_path, "second", tmp_path / "c")
    for a, b, c in zip(plain, first, second, strict=True):
        np.testing.assert_array_equal(a, b)  # the cache changes nothing
        np.testing.assert_array_equal(b, c)
    # another split's normalisation and another model width reuse the same entries
    wider = dataclasses.replace(cfg, hidden=cfg.hidden * 2)
    _windows(takes[:1], wider, tmp_path, "third", tmp_path / "c")
    assert sorted((tmp_path / "c" / block_cache.FOLDER).iterdir()) == entries


def test_the_key_follows_the_recording_and_the_fields_the_blocks_depend_on(takes, tmp_path):
    from robogest.generators.learned.rhythmic import SPEC
    from robogest.generators.learned.rhythmic.cache import block_cache_key

    t = takes[0]
    cfg = SPEC.make_config(t.acoustic.shape[1], t.text.shape[1], t.poses.shape[1], {})
    key = block_cache_key(t, cfg)
    assert block_cache_key(t, dataclasses.replace(cfg, lexicon_size=7, hidden=16)) == key  # model widths: no
    for field, value in (("max_beat_gap_s", 0.6), ("min_beat_gap_s", 0.25), ("n_mels", 32), ("mel_window_s", 0.05)):
        assert block_cache_key(t, dataclasses.replace(cfg, **{field: value})) != key, field
    copy = tmp_path / "a.wav"
    data = bytearray(Path(t.audio_path).read_bytes())
    data[-2] ^= 1  # one sample's low bit
    copy.write_bytes(bytes(data))
    assert block_cache_key(dataclasses.replace(t, audio_path=copy), cfg) != key
    assert block_cache_key(dataclasses.replace(t, audio_start_frame=1), cfg) != key


def test_the_process_group_timeout_reaches_init_process_group(monkeypatch):
    import torch.distributed as dist

    from robogest.cli.main import build_parser
    from robogest.learn import dist as D

    seen = {}
    monkeypatch.setattr(dist, "is_initialized", lambda: False)
    monkeypatch.setattr(dist, "init_process_group", lambda backend, **kw: seen.update(kw, backend=backend))
    monkeypatch.setitem(os.environ, "RANK", "0")
    monkeypatch.setitem(os.environ, "WORLD_SIZE", "1")
    info, _ = D.setup("cpu", 90.0)
    assert info.enabled and seen["backend"] == "gloo" and seen["timeout"].total_seconds() == 90.0
    with pytest.raises(InputError, match=r"timeout must be > 0 s, got 0.*--dist-timeout-s"):
        D.setup("cpu", 0)
    args = build_parser().parse_args(["train", "--data", "d", "--out", "o"])
    assert args.dist_timeout_s == D.DEFAULT_TIMEOUT_S >= 3600  # rank 0 may build caches for a long time
    assert (
        build_parser().parse_args(["train", "--data", "d", "--out", "o", "--dist-timeout-s", "60"]).dist_timeout_s == 60
    )
