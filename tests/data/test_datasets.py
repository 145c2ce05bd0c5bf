"""Dataset readers (three layouts), feature cache, split by take, normalisation, windows, fixture maker."""

from __future__ import annotations

import os

import numpy as np
import pytest

from robogest.data import (
    FeatureConfig,
    Normalization,
    detect_layout,
    discover_takes,
    load_dataset,
    make_fixture_dataset,
    make_windows,
    split_takes,
)
from robogest.data import datasets as ds
from robogest.errors import InputError
from robogest.motion.skeleton import CANONICAL

CFG = FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": 8})


@pytest.mark.parametrize(("layout", "fmt"), [("pairs", "bvh"), ("pairs", "npz"), ("genea", "bvh"), ("beat2", "npz")])
def test_layouts_give_the_same_aligned_takes(tmp_path, layout, fmt):
    root = make_fixture_dataset(tmp_path / layout, n_takes=2, duration_s=4.0, motion_format=fmt, layout=layout)
    assert detect_layout(root) == layout
    files = discover_takes(root)
    assert [f.name for f in files] == ["take_000", "take_001"]
    assert all(f.transcript is not None for f in files)
    takes = load_dataset(root, CFG, cache_dir=tmp_path / "cache")
    reference = load_dataset(
        make_fixture_dataset(tmp_path / "ref", n_takes=2, duration_s=4.0), CFG, cache_dir=tmp_path / "cache"
    )
    for t, r in zip(takes, reference, strict=True):
        assert t.n_frames == 80 and t.acoustic.shape == (80, 69) and t.text.shape == (80, 8)
        assert t.poses.shape == (80, CANONICAL.n_joints * 3)
        np.testing.assert_allclose(t.poses, r.poses, atol=1e-4)  # same motion whatever the file format
        np.testing.assert_allclose(t.acoustic[:, :64], r.acoustic[:, :64], atol=1e-4)  # log-mel
        np.testing.assert_allclose(t.acoustic[:, 64:], r.acoustic[:, 64:], atol=0.02)  # TextGrid keeps more digits
        assert (t.text[:, 0] != -15.0).any() and (t.text == -15.0).all(axis=1).any()  # words and silence


def test_fixture_motion_follows_audio_energy(tmp_path):
    root = make_fixture_dataset(tmp_path / "d", n_takes=1, duration_s=8.0)
    (take,) = load_dataset(root, CFG, cache_dir=tmp_path / "c")
    loud = take.acoustic[:, :64].mean(axis=1)  # (T,) mean log-mel, dB
    arm = take.poses[:, CANONICAL.index("r_elbow") * 3 + 1]
    lagged = np.convolve(loud, np.ones(5) / 5, mode="same")
    assert np.corrcoef(lagged, arm)[0, 1] > 0.5


def test_feature_cache_is_used_and_invalidated(tmp_path, monkeypatch):
    root = make_fixture_dataset(tmp_path / "d", n_takes=1, duration_s=4.0)
    first = load_dataset(root, CFG, cache_dir=tmp_path / "c")
    assert len(list((tmp_path / "c").glob("*.npz"))) == 1

    def boom(*a, **k):
        raise AssertionError("recomputed although cached")

    monkeypatch.setattr(ds, "compute_take", boom)
    again = load_dataset(root, CFG, cache_dir=tmp_path / "c")
    np.testing.assert_array_equal(first[0].poses, again[0].poses)
    with pytest.raises(AssertionError, match="recomputed"):  # another feature config is another key
        load_dataset(root, FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": 4}), tmp_path / "c")
    wav = root / "take_000.wav"
    st = wav.stat()
    os.utime(wav, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # touched file: new key
    with pytest.raises(AssertionError, match="recomputed"):
        load_dataset(root, CFG, cache_dir=tmp_path / "c")


def _take(name: str, n: int = 100, seed: int = 0) -> ds.Take:
    rng = np.random.default_rng(seed)
    return ds.Take(name, rng.normal(3, 2, (n, 69)).astype(np.float32), np.zeros((n, 8), np.float32),
                   rng.normal(0, 0.5, (n, 51)).astype(np.float32), 20.0)  # fmt: skip


def test_split_by_take_is_disjoint_and_stable():
    takes = [_take(f"t{i}") for i in range(10)]
    train, val = split_takes(takes, 0.2, seed=0)
    assert len(val) == 2 and len(train) == 8
    assert not {t.name for t in train} & {t.name for t in val}
    _, val2 = split_takes(list(reversed(takes)), 0.2, seed=0)
    assert [t.name for t in val] == [t.name for t in val2]  # independent of listing order
    (tr,), (va,) = split_takes([_take("one")], 0.1)
    assert (tr.n_frames, va.n_frames) == (90, 10)  # a single take is split in time
    with pytest.raises(InputError):
        split_takes([], 0.1)


def test_normalization_and_windows():
    takes = [_take("a", 100, 1), _take("b", 60, 2)]
    norm = Normalization.fit(takes)
    x, y, idx = make_windows(takes, norm, length=70, stride=10)
    assert x.shape == (4, 70, 69 + 8) and y.shape == (4, 70, 51)  # 100 -> 4 windows, 60 -> none
    assert list(idx) == [0, 0, 0, 0]
    allx = np.concatenate([norm.acoustic(t.acoustic) for t in takes])
    np.testing.assert_allclose(allx.mean(0), 0, atol=1e-4)
    np.testing.assert_allclose(allx.std(0), 1, atol=1e-3)
    np.testing.assert_allclose(norm.pose_inverse(norm.pose(takes[0].poses)), takes[0].poses, atol=1e-5)
    back = Normalization.from_dict(norm.to_dict())
    np.testing.assert_array_equal(back.pose_std, norm.pose_std)


def test_take_knows_its_audio_also_when_cut_from_a_longer_one(tmp_path):
    """Models that re-analyse time-scaled audio (the Rhythmic Gesticulator) read a take's samples from its file,
    from the take's first frame on, cached or not, and for the time split of a single take."""
    from robogest.speech.audio import read_audio

    root = make_fixture_dataset(tmp_path / "d", n_takes=1, duration_s=4.0)
    files = discover_takes(root)[0]
    take = ds.load_take(files, CFG, cache_dir=tmp_path / "c")
    cached = ds.load_take(files, CFG, cache_dir=tmp_path / "c")
    assert take.audio_path == cached.audio_path == files.audio
    raw, sr = read_audio(files.audio, 60.0)
    assert sr == 16000
    np.testing.assert_array_equal(take.read_audio(16000), raw)
    train, val = split_takes([take], 0.25)
    assert val[0].audio_start_frame == train[0].n_frames
    np.testing.assert_array_equal(val[0].read_audio(16000), raw[train[0].n_frames * 800 :])
    assert val[0].slice(10, 20).audio_start_frame == train[0].n_frames + 10
    with pytest.raises(InputError, match="no audio file"):
        _take("a", 10, 0).read_audio(16000)


def test_empty_folder_is_input_error(tmp_path):
    with pytest.raises(InputError, match="no takes found"):
        discover_takes(tmp_path)
    with pytest.raises(InputError, match="not found"):
        discover_takes(tmp_path / "missing")


@pytest.mark.shared
def test_beat2_sample_reads(shared_data, tmp_path):
    """The real BEAT2 sample (flat NAME.wav/.npz/.TextGrid) reads as a plain-pairs take at 20 fps."""
    files = discover_takes(shared_data / "beat2")
    assert len(files) == 1 and files[0].transcript.suffix == ".TextGrid"
    take = ds.compute_take(files[0], CFG)
    assert abs(take.n_frames - 63.53 * 20) <= 2  # trimmed to the motion, which ends first
    assert (take.text != -15.0).any(axis=1).mean() > 0.5  # mostly speech
    assert take.poses.std(axis=0).max() > 0.05
