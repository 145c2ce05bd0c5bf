"""The MP4 writer: RGB frames as H.264 video with the speech muxed in as AAC audio, through PyAV.

Knows nothing of robots or simulators (the simulator's :class:`~robogest.backends.recorder.VideoRecorder` feeds it
frames); the file appears whole or not at all.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError, RobogestError
from robogest.fileio import check_output_path, publish, temp_prefix, write_error

if TYPE_CHECKING:
    from av.audio.stream import AudioStream

_AAC_RATES = (96000, 88200, 64000, 48000, 44100, 32000, 24000, 22050, 16000, 12000, 11025, 8000, 7350)


class VideoWriter:
    """Stream RGB frames into an H.264 MP4, with optional speech audio muxed in as AAC.

    Audio is encoded progressively, up to the end of each video frame, so the two streams interleave.
    The file is written under a temporary name beside ``path`` and moved into place by :meth:`close`;
    :meth:`abort` (or an exception inside a ``with`` block) deletes it, so no half-written MP4 is left.

    Parameters
    ----------
    path : str or Path
        Output ``.mp4``.
    width, height : int
        Frame size in pixels (even).
    fps : int
        Video frame rate.
    audio : ndarray [shape=(N,) or (N, C)], optional
        Speech samples, float in [-1, 1] or int16. Only the first channel is used.
    audio_sr : int
        Audio sample rate, Hz.
    """

    def __init__(
        self,
        path: str | Path,
        width: int,
        height: int,
        fps: int = 25,
        audio: np.ndarray | None = None,
        audio_sr: int = 16000,
    ) -> None:
        import av

        self.path = Path(path)
        self._real = check_output_path(path)  # no folder, device or FIFO; symlinks written through
        self.fps = int(fps)
        self.width, self.height = int(width), int(height)
        try:
            self._real.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self._real.parent, prefix=temp_prefix(self._real.stem), suffix=".mp4.tmp")
        except OSError as e:
            raise write_error(self.path, e) from None
        os.close(fd)
        self._tmp = Path(tmp)
        self.n_frames = 0
        #: Set once the file is dropped: what to raise on any later call. PyAV's container is closed then, and
        #: encoding into it crashed the process (SIGSEGV: on a full disk the control loop's glide to rest still
        #: rendered frames after the first failed write).
        self._dead: RobogestError | None = None
        try:
            # Our own file object, so that abort() can always close it (PyAV keeps its own handle open when
            # flushing fails, e.g. on a full disk); unbuffered, so a full disk fails in a write, which PyAV
            # re-raises, never in a seek, which it would print as a traceback and drop.
            self._file = open(self._tmp, "wb", buffering=0)  # noqa: SIM115 - closed by close()/abort()
            self._container = av.open(self._file, mode="w", format="mp4")
            self._video = self._container.add_stream("libx264", rate=Fraction(self.fps, 1))
            self._video.width, self._video.height = self.width, self.height
            self._video.pix_fmt = "yuv420p"
            self._video.options = {"crf": "23", "preset": "veryfast"}
            self._audio_stream: AudioStream | None = None
            self._audio: np.ndarray | None = None
            self._audio_pos = 0
            if audio is not None and len(audio):
                self._setup_audio(np.asarray(audio), int(audio_sr))
        except Exception as e:
            self.abort()
            if isinstance(e, OSError):
                raise write_error(self.path, e) from None
            raise

    def _setup_audio(self, audio: np.ndarray, sr: int) -> None:
        if audio.ndim == 2:
            audio = audio[:, 0]
        if audio.ndim != 1:
            raise InputError(f"audio must have shape (N,) or (N, C), got {audio.shape}")
        if np.issubdtype(audio.dtype, np.integer):
            audio = audio.astype(np.float32) / float(np.iinfo(audio.dtype).max)
        audio = np.clip(np.nan_to_num(audio.astype(np.float32)), -1.0, 1.0)
        rate = sr
        if sr not in _AAC_RATES:  # linear resampling to 48 kHz is plenty for speech
            rate = 48000
            n_out = round(len(audio) * rate / sr)
            audio = np.interp(np.arange(n_out) * sr / rate, np.arange(len(audio)), audio).astype(np.float32)
        self._audio = audio
        self._audio_rate = rate
        stream = self._container.add_stream("aac", rate=rate)
        stream.layout = "mono"
        stream.bit_rate = 64000
        self._audio_stream = stream
        self._audio_chunk = 1024  # AAC frame size

    def _push_audio(self, until_s: float | None) -> None:
        import av

        if self._audio is None or self._audio_stream is None:
            return
        end = len(self._audio) if until_s is None else min(len(self._audio), int(until_s * self._audio_rate))
        while self._audio_pos < end and (until_s is None or end - self._audio_pos >= self._audio_chunk):
            chunk = self._audio[self._audio_pos : self._audio_pos + self._audio_chunk]
            frame = av.AudioFrame.from_ndarray(chunk[None, :], format="fltp", layout="mono")
            frame.sample_rate = self._audio_rate
            frame.pts = self._audio_pos
            frame.time_base = Fraction(1, self._audio_rate)
            self._audio_pos += len(chunk)
            for packet in self._audio_stream.encode(frame):
                self._container.mux(packet)

    def add_frame(self, rgb: np.ndarray) -> None:
        """Append one frame ``(H, W, 3)`` uint8; audio follows up to the end of this frame."""
        import av

        self._check_alive()
        if rgb.shape != (self.height, self.width, 3):
            raise ValueError(f"frame shape {rgb.shape} != {(self.height, self.width, 3)}")
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb, dtype=np.uint8), format="rgb24")
        frame.pts = self.n_frames
        frame.time_base = Fraction(1, self.fps)
        try:
            for packet in self._video.encode(frame):
                self._container.mux(packet)
            self.n_frames += 1
            self._push_audio(self.n_frames / self.fps)
        except OSError as e:  # disk full, I/O error: one line, and no partial file
            error = write_error(self.path, e)
            self.abort(error)
            raise error from None

    def _check_alive(self) -> None:
        """Raise again what ended the writer, if it has ended (never call PyAV after :meth:`abort`)."""
        if self._dead is not None:
            raise type(self._dead)(str(self._dead))

    def close(self) -> Path:
        """Flush both encoders and move the finished file into place; returns the path."""
        self._check_alive()
        try:
            self._push_audio(None)
            if self._audio_stream is not None:
                for packet in self._audio_stream.encode(None):
                    self._container.mux(packet)
            for packet in self._video.encode(None):
                self._container.mux(packet)
            self._container.close()
            self._file.close()
            publish(self._tmp, self._real)
        except OSError as e:
            error = write_error(self.path, e)
            self.abort(error)
            raise error from None
        except BaseException:
            self.abort()
            raise
        self._dead = RobogestError(f"{self.path}: the video is already closed")
        return self.path

    def abort(self, error: RobogestError | None = None) -> None:
        """Drop the partial file; any later :meth:`add_frame` or :meth:`close` raises ``error`` again."""
        if self._dead is None:
            self._dead = error or RobogestError(f"{self.path}: video writing was stopped; nothing was written")
        for part in (getattr(self, "_container", None), getattr(self, "_file", None)):
            if part is not None:
                with contextlib.suppress(Exception):
                    part.close()
        self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, et: object, e: object, tb: object) -> None:
        if et is None:
            self.close()
        else:
            self.abort()
