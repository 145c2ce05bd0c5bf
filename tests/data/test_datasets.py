"""Dataset readers (three layouts), feature cache, split by take, normalisation, windows, fixture maker."""

from __future__ import annotations

import os
from pathlib import Path

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


@pytest.mark.parametrize(
    ("layout", "fmt"), [("pairs", "bvh"), ("pairs", "npz"), ("genea", "bvh"), ("genea2023", "bvh"), ("beat2", "npz")]
)
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


def test_genea2023_split_folder_or_its_main_agent_folder(tmp_path):
    """GENEA 2023 ships ``trn/main-agent/{wav,bvh,tsv}`` (and ``interloctr/``): either folder can be given."""
    root = make_fixture_dataset(tmp_path / "trn", n_takes=2, duration_s=3.0, layout="genea2023")
    (root / "interloctr" / "wav").mkdir(parents=True)  # the interlocutor is not read
    for where in (root, root / "main-agent"):
        assert detect_layout(where) == "genea2023"
        files = discover_takes(where)
        assert [f.name for f in files] == ["take_000", "take_001"]
        assert all(f.transcript is not None and f.transcript.suffix == ".tsv" for f in files)


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
    (entry,) = (tmp_path / "c").iterdir()  # one folder per take, nothing left half-written beside it
    assert sorted(p.name for p in entry.iterdir()) == ["acoustic.npy", "meta.json", "poses.npy", "text.npy"]
    assert isinstance(first[0].poses, np.memmap) and not first[0].poses.flags.writeable  # mapped read-only

    def boom(*a, **k):
        raise AssertionError("recomputed although cached")

    monkeypatch.setattr(ds, "compute_take", boom)
    again = load_dataset(root, CFG, cache_dir=tmp_path / "c")
    np.testing.assert_array_equal(first[0].poses, again[0].poses)
    (entry / "text.npy").unlink()  # a new file: writing into a mapped one would change `first`'s arrays
    (entry / "text.npy").write_bytes(b"garbage")  # an unreadable entry is recomputed, not fatal
    with pytest.raises(AssertionError, match="recomputed"):
        load_dataset(root, CFG, cache_dir=tmp_path / "c")
    monkeypatch.undo()
    again = load_dataset(root, CFG, cache_dir=tmp_path / "c")
    np.testing.assert_array_equal(first[0].text, again[0].text)
    monkeypatch.setattr(ds, "compute_take", boom)
    with pytest.raises(InputError, match="not in the feature cache"):  # a DDP rank that only maps
        load_dataset(root, FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": 4}), tmp_path / "c",
                     build=False)  # fmt: skip
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


def _words_json(words) -> str:
    import json

    return json.dumps({"words": [{"word": w, "start_time": f"{a}s", "end_time": f"{b}s"} for w, a, b in words]})


def test_a_malformed_word_skips_that_word_and_a_bad_take_skips_that_take(tmp_path):
    """One warning line each; the run goes on with the rest (a zero-length Google STT word used to abort it)."""
    root = make_fixture_dataset(tmp_path / "d", n_takes=3, duration_s=3.0)
    (root / "take_000.json").write_text(_words_json([("hi", 0.5, 0.8), ("there", 1.0, 1.0), ("you", 1.0, 1.4)]))
    (root / "take_001.json").write_text("{not json")
    lines: list[str] = []
    takes = load_dataset(root, CFG, tmp_path / "cache", warn=lines.append)
    assert [t.name for t in takes] == ["take_000", "take_002"]
    assert len(lines) == 2
    assert lines[0].startswith("take_000: skipped 1 malformed word(s)") and "'there'" in lines[0]
    assert lines[1].startswith("take_001: take skipped") and "invalid JSON" in lines[1]
    assert "\n" not in "".join(lines)
    (root / "take_000.json").write_text("{not json")
    (root / "take_002.json").write_text("{not json")
    with pytest.raises(InputError, match=r"no take could be read; first problem: .*take_000\.json"):
        load_dataset(root, CFG, tmp_path / "cache2", warn=lines.append)


def test_tsv_transcripts_are_read(tmp_path):
    root = make_fixture_dataset(tmp_path / "d", n_takes=1, duration_s=3.0)
    (root / "take_000.json").unlink()
    (root / "take_000.tsv").write_text("start\tend\tword\n0.5\t0.9\thello\n1.0\t1.5\trobot\n")
    files = discover_takes(root)[0]
    assert files.transcript is not None and files.transcript.suffix == ".tsv"
    take = load_dataset(root, CFG, tmp_path / "cache")[0]
    words = np.any(take.text > -15.0 + 1e-3, axis=1)  # frames inside a word
    assert words[12] and words[25] and not words[5] and not words[40]


def test_a_take_longer_than_600_s_trains(tmp_path):
    """GENEA 2020 takes are about 10 min; the speech front-end's 600 s guard is for interactive input only."""
    import soundfile as sf

    src = make_fixture_dataset(tmp_path / "src", n_takes=1, duration_s=5.0, motion_format="npz")
    audio, sr = sf.read(src / "take_000.wav", dtype="float32")
    z = dict(np.load(src / "take_000.npz"))
    reps = 121  # 605 s
    root = tmp_path / "long"
    root.mkdir()
    sf.write(root / "long.wav", np.tile(audio, reps), sr)
    np.savez(root / "long.npz", poses=np.tile(z["poses"], (reps, 1)), trans=np.tile(z["trans"], (reps, 1)),
             mocap_frame_rate=z["mocap_frame_rate"])  # fmt: skip
    (take,) = load_dataset(root, CFG, tmp_path / "cache", warn=pytest.fail)
    assert take.n_frames >= 605 * 20 - 1 and np.isfinite(take.acoustic).all()


def test_beat2_official_split_is_used(tmp_path):
    root = make_fixture_dataset(tmp_path / "b", n_takes=4, duration_s=3.0, motion_format="npz", layout="beat2")
    names = [f.name for f in discover_takes(root)]
    (root / ds.SPLIT_FILE).write_text(
        f"id,type\n{names[0]},train\n{names[1]},val\n{names[2]},test\n{names[3]},additional\n"
    )
    lines: list[str] = []
    takes = load_dataset(root, CFG, tmp_path / "cache", warn=lines.append)
    assert [t.name for t in takes] == [names[0], names[1], names[3]]  # the test take is never loaded
    assert lines == [f"{ds.SPLIT_FILE}: official split used, 1 test (or unlisted) take(s) left out"]
    train, val = split_takes(takes, 0.5, 0, ds.official_split(root))
    assert [t.name for t in train] == [names[0], names[3]] and [t.name for t in val] == [names[1]]
    (root / ds.SPLIT_FILE).write_text("name,split\nx,train\n")
    with pytest.raises(InputError, match="expected the columns id,type"):
        ds.official_split(root)


_LAZY_SCRIPT = """
import resource, sys
import numpy as np
from robogest.data.prep import slice_windows

def vm_bytes():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))

limit = vm_bytes() + 300 * 2**20  # what this process allows itself from here on
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
length, d, n_takes, frames = 70, 256, 8, 4000  # 8 takes: 33 MB of frames, 2.2 GB of windows at stride 1

def take(i):
    rng = np.random.default_rng(i)
    return rng.standard_normal((frames, d), dtype=np.float32)

x, y, idx = slice_windows(((i, take(i), take(i)[:, :3]) for i in range(n_takes)), length, 1, d, 3)
assert len(x) == n_takes * (frames - length + 1)
assert len(x) * length * d * 4 > 6 * 300 * 2**20  # stored whole: 6 times the allowance
rng = np.random.default_rng(0)
for _ in range(20):
    b = rng.integers(0, len(x), 64)
    xb = x[b]
    i, s = idx[b[0]], b[0] - idx[b[0]] * (frames - length + 1)
    assert xb.shape == (64, length, d) and np.array_equal(xb[0], take(i)[s : s + length])
try:
    np.stack([x[k] for k in range(0, len(x), 1)])
except MemoryError:
    print("ok")
"""


def test_training_windows_are_read_lazily_from_disk_within_a_memory_limit():
    """Windows bigger than the memory the process allows itself are built and read batch by batch; stacking them
    (the old in-memory way) fails under the same limit."""
    import subprocess
    import sys

    if not os.path.exists("/proc/self/status"):
        pytest.skip("needs /proc (Linux) to set the limit relative to the process size")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}  # this checkout's robogest
    r = subprocess.run([sys.executable, "-c", _LAZY_SCRIPT], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]


_CACHE_SCRIPT = """
import json, resource, sys
from pathlib import Path
import numpy as np
from robogest.data import FeatureConfig, Normalization, discover_takes, load_dataset, make_windows, split_takes
from robogest.data.datasets import cache_entry

root, cache = Path(sys.argv[1]) / "takes", Path(sys.argv[1]) / "cache"
root.mkdir()
n_takes, frames, d_text, allow = 12, 14000, 300, 80 * 2**20
for i in range(n_takes):  # empty recordings: every take is already in the cache, written below
    (root / f"take_{i:03d}.wav").touch()
    (root / f"take_{i:03d}.npz").touch()
cfg = FeatureConfig(text_encoder="hash-test", text_encoder_kwargs={"dim": d_text})
for i, f in enumerate(discover_takes(root)):
    e = cache_entry(f, cfg, cache)
    e.mkdir(parents=True)
    rng = np.random.default_rng(i)
    for k, d in (("acoustic", 69), ("text", d_text), ("poses", 51)):
        np.save(e / f"{k}.npy", rng.standard_normal((frames, d), dtype=np.float32) + i)
    (e / "meta.json").write_text(json.dumps({"fps": 20.0}))
size = sum(p.stat().st_size for p in cache.rglob("*.npy"))
assert size > 3 * allow, size

def vm_data():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmData:"))

limit = vm_data() + allow  # heap and private mappings this process allows itself from here on
resource.setrlimit(resource.RLIMIT_DATA, (limit, limit))
takes = load_dataset(root, cfg, cache, warn=print)
train, val = split_takes(takes, 0.25, 0)
norm = Normalization.fit(train)
x, y, idx = make_windows(train, norm, 70, 5)
assert len(x) == len(train) * ((frames - 70) // 5 + 1)
k = 1234
t = train[idx[k]]
s = (k - idx[k] * ((frames - 70) // 5 + 1)) * 5
np.testing.assert_allclose(x[[k]][0, :, 69:], t.text[s : s + 70])
np.testing.assert_allclose(y[[k]][0], norm.pose(t.poses[s : s + 70]), rtol=1e-6)
mean = np.mean([t.poses[:].mean(0, dtype=np.float64) for t in train], axis=0)  # equal-length takes
np.testing.assert_allclose(norm.pose_mean, mean, rtol=1e-5)
try:
    np.concatenate([t.text for t in takes])  # the dataset's features in memory, as before
except MemoryError:
    print("ok", size // 2**20)
"""


def test_feature_cache_larger_than_the_memory_allowed_is_mapped_not_loaded(tmp_path):
    """A feature cache 3x the memory (heap, RLIMIT_DATA) the process allows itself loads, gives normalisation
    statistics and training windows; holding its features in memory (the old way) fails under the same limit."""
    import subprocess
    import sys

    if not os.path.exists("/proc/self/status"):
        pytest.skip("needs /proc (Linux) to set the limit relative to the process size")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}  # this checkout's robogest
    r = subprocess.run([sys.executable, "-c", _CACHE_SCRIPT, str(tmp_path)], capture_output=True, text=True,
                       env=env, timeout=300)  # fmt: skip
    assert r.returncode == 0 and r.stdout.split()[0] == "ok", (r.stdout[-2000:], r.stderr[-2000:])


def test_unpaired_files_and_a_length_mismatch_are_warned_about(tmp_path):
    """A take's other half missing (a typo in a name) or audio and motion of very different lengths (a wrong frame
    rate, a wrong pairing) trained silently: the first left out, the second cut to the shorter."""
    import soundfile as sf

    root = make_fixture_dataset(tmp_path / "d", n_takes=3, duration_s=3.0)
    (root / "take_001.bvh").rename(root / "take_1.bvh")  # a renamed motion file: both halves are now alone
    audio, sr = sf.read(root / "take_002.wav")
    sf.write(root / "take_002.wav", np.concatenate([audio, audio, audio]), sr)  # 9 s of audio, 3 s of motion
    lines: list[str] = []
    takes = load_dataset(root, CFG, tmp_path / "cache", warn=lines.append)
    assert [t.name for t in takes] == ["take_000", "take_002"]
    assert any(line.startswith("2 file(s) without their audio or motion half, left out: take_001.wav, take_1.bvh")
               for line in lines), lines  # fmt: skip
    assert any(line.startswith("take_002: audio 9.0 s and motion 3.0 s differ") for line in lines), lines
    assert not any(line.startswith("take_000") for line in lines)
