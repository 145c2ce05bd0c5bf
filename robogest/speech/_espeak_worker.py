"""Child process for eSpeak NG: one utterance per process, so eSpeak's internal state is always fresh.

eSpeak NG keeps synthesis state in C function statics (pitch-flutter index, automatic gain control,
harmonic sign...) that no API call resets, so a second utterance in the same process comes out slightly
different. Running each synthesis in a new interpreter (started with ``-I -S``, stdlib only) makes the
output a pure function of text, voice and rate.

Protocol: argv = library path, data path. stdin = JSON ``{"text", "voice", "wpm", "phonemes"}``. stdout = one
JSON line ``{"sr", "n_samples", "events": [[sample, char_start, char_end], ...], "phonemes": [[sample,
char_start, name], ...], "stress_marks": n, "error"}`` followed by ``n_samples`` little-endian int16 samples.

``phonemes`` (optional, default false) turns on eSpeak's phoneme events (``espeakINITIALIZE_PHONEME_EVENTS``);
the audio is the same either way. ``name`` is the phoneme mnemonic as eSpeak reports it (the build that
``espeakng-loader`` ships writes a stress mark, ``'`` or ``,``, before stressed syllabic phonemes);
``stress_marks`` counts the stress marks in eSpeak's own phoneme transcription of the text (the phoneme
callback), so the caller can tell a build whose events carry no stress marks from a text without stress.
"""

import ctypes
import json
import sys

_AUDIO_OUTPUT_SYNCHRONOUS = 2
_INITIALIZE_DONT_EXIT = 0x8000
_EVENT_LIST_TERMINATED = 0
_EVENT_WORD = 1
_EVENT_PHONEME = 7
_INITIALIZE_PHONEME_EVENTS = 0x0001
_POS_CHARACTER = 1
_CHARS_UTF8 = 1
_PARAM_RATE = 1
_EE_OK = 0


class _Event(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", ctypes.c_char * 8),
    ]


_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.POINTER(_Event))
_PHONEME_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_char_p)


def main() -> int:
    lib_path, data_path = sys.argv[1], sys.argv[2]
    req = json.loads(sys.stdin.read())
    out = sys.stdout.buffer

    def reply(header: dict, pcm: bytes = b"") -> int:
        out.write(json.dumps(header).encode() + b"\n")
        out.write(pcm)
        out.flush()
        return 0

    lib = ctypes.CDLL(lib_path)
    lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
    lib.espeak_SetSynthCallback.argtypes = [_CALLBACK]
    lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
    lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
    lib.espeak_Synth.argtypes = [
        ctypes.c_void_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int, ctypes.c_uint, ctypes.c_uint,
        ctypes.c_void_p, ctypes.c_void_p,
    ]  # fmt: skip
    want_phonemes = bool(req.get("phonemes", False))
    options = _INITIALIZE_DONT_EXIT | (_INITIALIZE_PHONEME_EVENTS if want_phonemes else 0)
    sr = lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, data_path.encode(), options)
    if sr <= 0:
        return reply({"error": "init", "detail": "eSpeak NG failed to initialise (data files missing?)"})
    chunks: list[bytes] = []
    events: list[list[int]] = []
    phonemes: list[list] = []
    stress_marks = [0]

    def on_synth(wav, n, ev):  # type: ignore[no-untyped-def]
        if wav and n > 0:
            chunks.append(ctypes.string_at(wav, 2 * n))
        i = 0
        while ev and ev[i].type != _EVENT_LIST_TERMINATED:
            if ev[i].type == _EVENT_WORD:
                start = ev[i].text_position - 1
                events.append([int(ev[i].sample), start, start + int(ev[i].length)])
            elif ev[i].type == _EVENT_PHONEME:
                name = bytes(ev[i].id).split(b"\0", 1)[0].decode("utf-8", "replace")
                phonemes.append([int(ev[i].sample), ev[i].text_position - 1, name])
            i += 1
        return 0

    def on_clause_phonemes(text):  # type: ignore[no-untyped-def]
        if text:
            stress_marks[0] += text.count(b"'") + text.count(b",")
        return 0

    callback = _CALLBACK(on_synth)
    lib.espeak_SetSynthCallback(callback)
    if want_phonemes:
        phoneme_callback = _PHONEME_CALLBACK(on_clause_phonemes)
        lib.espeak_SetPhonemeCallback.argtypes = [_PHONEME_CALLBACK]
        lib.espeak_SetPhonemeCallback(phoneme_callback)
    if lib.espeak_SetVoiceByName(req["voice"].encode()) != _EE_OK:
        return reply({"error": "voice"})
    lib.espeak_SetParameter(_PARAM_RATE, int(req["wpm"]), 0)
    data = req["text"].encode("utf-8") + b"\0"
    err = lib.espeak_Synth(data, len(data), 0, _POS_CHARACTER, 0, _CHARS_UTF8, None, None)
    if err != _EE_OK:
        return reply({"error": "synth", "detail": f"espeak_Synth returned {err}"})
    pcm = b"".join(chunks)
    if sys.byteorder != "little":  # pragma: no cover
        import array

        a = array.array("h", pcm)
        a.byteswap()
        pcm = a.tobytes()
    header = {"sr": sr, "n_samples": len(pcm) // 2, "events": events, "error": None}
    if want_phonemes:
        header |= {"phonemes": phonemes, "stress_marks": stress_marks[0]}
    return reply(header, pcm)


if __name__ == "__main__":
    sys.exit(main())
