"""The player's speech output goes through the same ``AudioOut`` as a live session (a stand-in sounddevice)."""

from __future__ import annotations

import numpy as np
import pytest

import robogest.backends.player as player
from robogest.backends.mujoco_sim import MujocoBackend, sine_test_trajectory
from robogest.robot import find_robot


class FakeStream:
    def __init__(self, callback, **kw):
        self.callback, self.kw, self.started, self.closed = callback, kw, False, False

    def start(self):
        self.started = True

    def abort(self):
        self.aborted = True

    def close(self):
        self.closed = True


class FakeSD:
    class CallbackStop(Exception):  # sounddevice's name
        pass

    def __init__(self):
        self.streams: list[FakeStream] = []

    def OutputStream(self, callback, **kw):
        self.streams.append(FakeStream(callback, **kw))
        return self.streams[-1]


def test_play_streams_the_speech_samples_and_closes_the_stream(monkeypatch):
    sd = FakeSD()
    monkeypatch.setattr(player, "open_output", lambda: (sd, ""))
    robot = find_robot("humanoid_xl430")
    audio = np.linspace(-0.5, 0.5, 800, dtype=np.float32)
    report = player.play(sine_test_trajectory(robot, duration_s=0.3), MujocoBackend(robot), audio=audio, audio_sr=8000)
    assert report.audio and len(sd.streams) == 1
    stream = sd.streams[0]
    assert stream.started and stream.closed and stream.kw["samplerate"] == 8000
    out = np.ones((1000, 1), np.float32)
    stream.callback(out, 1000, None, None)
    np.testing.assert_array_equal(out[:800, 0], audio)  # every sample, in order
    assert not out[800:].any()  # then silence
    with pytest.raises(FakeSD.CallbackStop):  # and the stream stops itself: all of the speech has played
        stream.callback(out, 1000, None, None)


def test_a_live_stream_plays_until_closed_and_an_interrupt_silences_it_at_once():
    from robogest.media.audio import AudioOut

    sd = FakeSD()
    out = AudioOut(sd, 8000)
    out.write(np.full(100, 0.25, np.float32))
    out.open()  # the device stream is made outside the control tick; the tick only starts it
    stream = sd.streams[0]
    assert not stream.started
    assert out.start() and stream.started and len(sd.streams) == 1
    buf = np.ones((200, 1), np.float32)
    stream.callback(buf, 200, None, None)  # the stream is still open: silence after the chunk, no stop
    stream.callback(buf, 200, None, None)
    out.write(np.full(50, 0.5, np.float32))
    out.finish()
    stream.callback(buf, 200, None, None)
    assert (buf[:50, 0] == 0.5).all()
    with pytest.raises(FakeSD.CallbackStop):
        stream.callback(buf, 200, None, None)
    out.stop()
    assert stream.aborted and stream.closed  # abort drops what is buffered, stop would play it out first


def test_no_output_device_plays_silently(monkeypatch):
    monkeypatch.setattr(player, "open_output", lambda: (None, "no audio output device"))
    robot = find_robot("humanoid_xl430")
    report = player.play(sine_test_trajectory(robot, duration_s=0.2), MujocoBackend(robot), audio=np.zeros(100))
    assert report.completed and not report.audio


@pytest.mark.parametrize(
    ("raised", "says"),
    [
        (ImportError("No module named 'sounddevice'"), "sounddevice is not installed"),
        (OSError("PortAudio library not found"), "the PortAudio library is missing (PortAudio library not found)"),
    ],
)
def test_no_audio_output_names_what_is_missing(monkeypatch, raised, says):
    """With sounddevice installed and only PortAudio missing (sounddevice's import raises OSError) the note said
    "sounddevice is not installed", sending the user to reinstall what they had."""
    import builtins
    import sys

    from robogest.media.audio import open_output

    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name == "sounddevice":
            raise raised
        return real_import(name, *args, **kwargs)

    monkeypatch.delitem(sys.modules, "sounddevice", raising=False)
    monkeypatch.setattr(builtins, "__import__", fake_import)
    sd, why = open_output()
    assert sd is None
    assert why.startswith(says), why
