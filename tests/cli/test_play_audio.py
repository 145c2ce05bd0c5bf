"""``robogest play X.npz --video``: the video carries the audio the trajectory names, else ``X.wav`` beside it, and
the command says which (or why the video is silent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from robogest.cli.main import main
from robogest.robot.registry import find_robot

av = pytest.importorskip("av", reason="the video extra: pip install -e '.[video]'")

ROBOT = "humanoid_xl430"


def _trajectory(path: Path, audio_path: str, n: int = 10) -> None:
    """A rest-pose trajectory of ROBOT at 50 Hz naming ``audio_path`` (as ``speak --save`` writes it)."""
    r = find_robot(ROBOT)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        path, t_s=np.arange(n) / 50.0, q_rad=np.tile(r.rest_q_rad, (n, 1)), joint_names=np.array(r.joint_names),
        q_min_rad=r.q_min_rad, q_max_rad=r.q_max_rad, v_max_rad_s=r.v_max_rad_s, a_max_rad_s2=r.a_max_rad_s2,
        rest_q_rad=r.rest_q_rad, silent=np.zeros(n, bool), audio_path=np.array(audio_path), robot=np.array(ROBOT),
    )  # fmt: skip


def _wav(path: Path, sr: int = 16000) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    t = np.arange(sr // 2) / sr
    sf.write(path, 0.3 * np.sin(2 * np.pi * 220 * t), sr, format="WAV", subtype="PCM_16")


def _audio_streams(mp4: Path) -> int:
    with av.open(str(mp4)) as c:
        return len(c.streams.audio)


def _play(argv: list[str], capsys) -> list[str]:
    assert main(["play", *argv, "--video", "out/v.mp4", "--video-size", "32x32"]) == 0, capsys.readouterr().err
    return capsys.readouterr().out.splitlines()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("recorded", "audio_at", "shown"),
    [
        ("talk/hi.wav", "talk/hi.wav", "audio: talk/hi.wav (named in the trajectory)"),  # as recorded, from here
        ("elsewhere/t.wav", "out/t.wav", "audio: out/t.wav (named in the trajectory)"),  # saved from another folder
        ("", "out/t.wav", "audio: out/t.wav (beside t.npz)"),  # names none: the .wav of its name beside it
    ],
    ids=["named", "named-beside", "beside"],
)
def test_play_video_uses_the_trajectorys_audio_and_says_which(recorded, audio_at, shown, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _trajectory(Path("out/t.npz"), recorded)
    _wav(Path(audio_at))
    assert shown in _play(["out/t.npz"], capsys)
    assert _audio_streams(Path("out/v.mp4")) == 1


@pytest.mark.slow
@pytest.mark.parametrize(
    ("recorded", "why"),
    [
        ("", "t.npz names no audio"),
        ("gone.wav", "the trajectory names gone.wav, which is missing,"),
    ],
    ids=["names-none", "named-missing"],
)
def test_play_video_says_why_it_is_silent(recorded, why, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _trajectory(Path("out/t.npz"), recorded)
    assert f"video: silent: {why} and there is no out/t.wav; give --audio FILE" in _play(["out/t.npz"], capsys)
    assert _audio_streams(Path("out/v.mp4")) == 0


@pytest.mark.slow
def test_play_audio_flag_wins_over_the_trajectorys(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _trajectory(Path("out/t.npz"), "gone.wav")
    _wav(Path("mine.wav"))
    out = _play(["out/t.npz", "--audio", "mine.wav"], capsys)
    assert not [line for line in out if line.startswith(("audio:", "video: silent"))]
    assert _audio_streams(Path("out/v.mp4")) == 1


def test_play_without_video_reads_no_audio(tmp_path, monkeypatch, capsys):
    """Without --video (sim) the named audio is not needed: not looked up, not reported."""
    monkeypatch.chdir(tmp_path)
    _trajectory(Path("t.npz"), "")
    _wav(Path("t.wav"))
    assert main(["play", "t.npz"]) == 0
    assert not [line for line in capsys.readouterr().out.splitlines() if line.startswith(("audio:", "video:"))]
