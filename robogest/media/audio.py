"""Speech output (the player and a live session): ``sounddevice`` when installed and an output device exists, else
nothing.

Without it, a live session still schedules the audio: every utterance's events carry the ``time.monotonic()``
at which each stretch of its audio should start playing, so the caller can play it in sync.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

import numpy as np


def open_output() -> tuple[Any, str]:
    """``(sounddevice module or None, why not)``: None when not installed, no PortAudio or no output device."""
    try:
        import sounddevice as sd
    except ImportError:
        from robogest.extras import install_command

        return None, f"sounddevice is not installed ({install_command('audio')})"
    except OSError as e:  # sounddevice is there but its C library is not: installing sounddevice again won't help
        return None, f"the PortAudio library is missing ({e}); install it (Debian/Ubuntu: apt install libportaudio2)"
    try:
        sd.query_devices(kind="output")
    except Exception:
        return None, "no audio output device"
    return sd, ""


class AudioOut:
    """Plays float32 mono chunks back to back from a start call on; ``write`` may come before or after it.

    One ``sounddevice.OutputStream`` per utterance; chunks queue in memory (an utterance is seconds long).
    """

    def __init__(self, sd: Any, sr: int) -> None:
        self.sd = sd
        self.sr = int(sr)
        self._buf: list[np.ndarray] = []
        self._pos = 0
        self._lock = threading.Lock()
        self._stream: Any = None
        self._finished = False  # no more writes: the stream stops itself once it has played the rest

    def finish(self) -> None:
        """No more :meth:`write`: once what is queued has played, the output stream stops by itself (a session
        otherwise keeps a device stream playing silence until its next utterance)."""
        self._finished = True

    def write(self, chunk: np.ndarray) -> None:
        if self.sd is None:  # nothing will play it: keeping it would hold a whole stream's audio (a server's hours)
            return
        with self._lock:
            self._buf.append(np.asarray(chunk, np.float32))

    def _callback(self, out: np.ndarray, frames: int, _time: Any, _status: Any) -> None:
        out.fill(0)
        with self._lock:
            if self._finished and not self._buf:
                raise self.sd.CallbackStop
            got = 0
            while got < frames and self._buf:
                head = self._buf[0]
                take = min(frames - got, head.shape[0] - self._pos)
                out[got : got + take, 0] = head[self._pos : self._pos + take]
                got += take
                self._pos += take
                if self._pos >= head.shape[0]:
                    self._buf.pop(0)
                    self._pos = 0

    def open(self) -> None:
        """Create the device stream now, not started: opening PortAudio takes time that :meth:`start`, called in a
        control tick when the motion starts, should not."""
        if self.sd is None or self._stream is not None:
            return
        try:
            self._stream = self.sd.OutputStream(
                samplerate=self.sr, channels=1, dtype="float32", callback=self._callback
            )
        except Exception:
            self._stream = None

    def start(self) -> bool:
        """Start playing (opening the stream first if :meth:`open` was not called); False if it cannot."""
        self.open()
        if self._stream is None:
            return False
        try:
            self._stream.start()
            return True
        except Exception:
            self.stop()
            return False

    def stop(self) -> None:
        """Silence now (``abort``: what is buffered is dropped, where ``stop`` would play it out first) and close."""
        if self._stream is not None:
            with contextlib.suppress(Exception):
                self._stream.abort()
                self._stream.close()
            self._stream = None
