"""Where a word's stressed syllable falls, from eSpeak NG's pronunciation lexicon (no audio needed).

A live stream learns a word (from its TTS or voice agent) when the word's audio starts to arrive, only the
look-ahead before the robot plays it: too soon to hear the word's stressed syllable, where a stroke belongs. Its
lexical stress is known from the text, though, and its place in the word follows from the word's phonemes: the
share of the word's duration before the stressed vowel, a vowel counting :data:`VOWEL_WEIGHT` consonants.

eSpeak NG (``espeakng-loader``, already needed for text-to-speech) is loaded once per process for this; it only
translates text to phonemes here, so the per-utterance child process that synthesis uses is not needed.
"""

from __future__ import annotations

import ctypes
import functools
import re
import threading

from robogest.errors import MissingDependencyError
from robogest.speech._espeak_worker import _AUDIO_OUTPUT_SYNCHRONOUS, _CHARS_UTF8, _EE_OK, _INITIALIZE_DONT_EXIT

#: A vowel lasts about this many consonants when a word's duration is shared among its phonemes. On the words of
#: the BEAT2 sample's calibration half (0-32 s) that carry a stressed vowel, 1 / 1.5 / 2 / 3 put its onset off
#: its forced alignment by 0.044 / 0.042 / 0.043 / 0.046 s on average (a fixed 0.08 s after the word's start:
#: 0.060 s): a flat optimum; 2 is the weight the streamed stroke sync was calibrated with (``rhythm.STRESS_BEAT_S``).
VOWEL_WEIGHT = 2.0

_VOWELS = frozenset("aeiouɐɑɒæəɘɚɛɜɝɞɪɨʉʊʌɔøœɤɵʏᵻ")
_PRIMARY = "ˈ"
_IPA_SEPARATED = 2 | (ord("_") << 8)  # IPA, phonemes separated by "_"
_lock = threading.Lock()  # eSpeak NG is not thread-safe (nor is a first initialisation)


@functools.cache
def _espeak() -> ctypes.CDLL:
    """eSpeak NG's library, initialised for phoneme translation (once per process)."""
    from robogest.speech.tts import _espeak_paths

    lib_path, data_path = _espeak_paths()
    lib = ctypes.cdll.LoadLibrary(lib_path)
    if lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, data_path.encode(), _INITIALIZE_DONT_EXIT) < 0:
        raise MissingDependencyError(f"eSpeak NG at {lib_path} failed to initialise with data {data_path}")
    if lib.espeak_SetVoiceByName(b"en-us") != _EE_OK:
        raise MissingDependencyError(f"eSpeak NG data at {data_path} has no en-us voice")
    lib.espeak_TextToPhonemes.restype = ctypes.c_char_p
    lib.espeak_TextToPhonemes.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_int, ctypes.c_int]
    return lib


def phonemes(word: str) -> list[str]:
    """eSpeak NG's IPA phonemes of ``word`` spoken alone (en-us), a primary stress mark ``ˈ`` (or secondary
    ``ˌ``) before the stressed vowel: ``"about"`` -> ``["ɐ", "b", "ˈaʊ", "t"]``."""
    text = word.strip()
    if not text:
        return []
    with _lock:
        lib = _espeak()
        buf = ctypes.create_string_buffer(text.encode("utf-8"))
        ptr = ctypes.c_void_p(ctypes.addressof(buf))
        out: list[str] = []
        while ptr.value:  # one clause per call ("42" -> "forty two")
            got = lib.espeak_TextToPhonemes(ctypes.byref(ptr), _CHARS_UTF8, _IPA_SEPARATED)
            out += [p for p in re.split(r"[_\s]+", (got or b"").decode("utf-8")) if p]
    return out


@functools.lru_cache(maxsize=8192)
def stress_fraction(word: str) -> float | None:
    """Where ``word``'s primary-stressed vowel starts, as a fraction of the word's duration in [0, 1), or None
    when eSpeak NG stresses none of its syllables (most function words: "the", "to", "and").

    The duration is shared among the phonemes, a vowel counting :data:`VOWEL_WEIGHT` consonants:
    ``"table"`` (t ˈeɪ b əl) -> 1/6, ``"about"`` (ɐ b ˈaʊ t) -> 1/2. On the held-out half (32-64 s) of the BEAT2
    sample, ``start + fraction x duration`` is off the forced alignment of the stressed vowel by 0.023 s (median;
    mean 0.040 s) where a fixed 0.08 s after the word's start is off by 0.040 s (0.056 s). English (en-us) only.
    """
    ph = phonemes(word)
    weights = [VOWEL_WEIGHT if any(ch in _VOWELS for ch in p) else 1.0 for p in ph]
    for k, p in enumerate(ph):
        if _PRIMARY in p:
            return sum(weights[:k]) / sum(weights)
    return None
