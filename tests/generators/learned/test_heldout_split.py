"""The held-out benchmark's train / validation / test split (benchmarks/bench_learned_heldout.py), without training:
the trainer sees only train + validation, selects on validation, and nothing of the test part reaches it."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[3] / "benchmarks" / "bench_learned_heldout.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_learned_heldout", BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("n", [20, 1271, 5000])
def test_split_is_contiguous_in_time_and_follows_the_fractions(bench, n):
    val_start, test_start = bench.split_frames(n)
    assert 0 < val_start < test_start < n
    assert bench.SPLIT == (0.60, 0.15, 0.25)
    assert abs(val_start - 0.60 * n) <= 0.5 and abs(test_start - 0.75 * n) <= 0.5


def test_split_refuses_bad_fractions_and_too_few_frames(bench):
    with pytest.raises(ValueError, match="summing to 1"):
        bench.split_frames(100, (0.6, 0.2, 0.3))
    with pytest.raises(ValueError, match="three positive fractions"):
        bench.split_frames(100, (0.75, 0.0, 0.25))
    with pytest.raises(ValueError, match="too few"):
        bench.split_frames(2)


@pytest.mark.parametrize("n", [40, 1271])
def test_trainer_validates_on_the_validation_part_only(bench, n):
    """The trainer gets the first ``test_start`` frames; its one-take split in time must validate on
    ``[val_start, test_start)`` (up to one frame of rounding) and train on what comes before."""
    from robogest.data.datasets import Take
    from robogest.data.prep import split_takes

    val_start, test_start = bench.split_frames(n)
    take = Take("t", np.zeros((test_start, 2), np.float32), np.zeros((test_start, 1), np.float32),
                np.arange(test_start, dtype=np.float32)[:, None], 20.0)  # fmt: skip
    train, val = split_takes([take], bench.trainer_val_fraction(val_start, test_start))
    assert len(train) == len(val) == 1
    assert abs(val[0].audio_start_frame - val_start) <= 1
    assert val[0].poses[-1, 0] == test_start - 1  # validation ends where the test part starts
    assert train[0].n_frames + val[0].n_frames == test_start


@pytest.mark.parametrize(("layout", "motion_format"), [("beat2", "npz"), ("pairs", "bvh")])
def test_trimmed_take_ends_at_the_test_part(bench, tmp_path, layout, motion_format):
    """The copy the trainer reads holds the recording, the motion and the words up to the cut, nothing after."""
    import soundfile as sf

    from robogest.data import make_fixture_dataset
    from robogest.data.datasets import discover_takes
    from robogest.motion import load_motion
    from robogest.speech.transcript import read_transcript

    src = make_fixture_dataset(tmp_path / "src", n_takes=1, duration_s=8.0, motion_format=motion_format, layout=layout)
    files = discover_takes(src)[0]
    out = tmp_path / "data"
    out.mkdir()
    cut_s = 6.0
    bench._write_trimmed_take(files.audio, files.motion, files.transcript, cut_s, out)

    trimmed = discover_takes(out)
    assert len(trimmed) == 1 and trimmed[0].transcript is not None and trimmed[0].transcript.suffix == ".tsv"
    assert sf.info(str(trimmed[0].audio)).duration == pytest.approx(cut_s, abs=1e-3)
    assert load_motion(trimmed[0].motion).duration_s == pytest.approx(cut_s, abs=0.05)
    before = [(w.text, w.start_s) for w in read_transcript(files.transcript).words if w.end_s <= cut_s]
    after = [(w.text, round(w.start_s, 3)) for w in read_transcript(trimmed[0].transcript).words]
    assert after == [(t, round(s, 3)) for t, s in before] and before
    assert all(w.end_s <= cut_s for w in read_transcript(trimmed[0].transcript).words)
