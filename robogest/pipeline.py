"""The main job, stage by stage: speech -> generator -> human motion -> IK -> safety -> trajectory.

The CLI and the tests call these functions; nothing here knows about a particular backend.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robogest.errors import InputError
from robogest.motion.human_motion import HumanMotion
from robogest.retarget import DirectionIK, RetargetResult
from robogest.robot.config import RobotConfig
from robogest.safety import JointLimits, SafetyConfig, SafetyResult, apply_safety
from robogest.speech.types import Speech
from robogest.trajectory import Trajectory

#: Command rate of saved/streamed trajectories, Hz: fast enough for smooth servo motion, low enough for
#: one sync write + one sync read per tick on a 1 Mbaud bus with 11 servos.
DEFAULT_TRAJECTORY_FPS = 50.0


@dataclass(frozen=True)
class SpeakResult:
    """Everything one run produced, for saving, plotting and reporting."""

    speech: Speech | None
    motion: HumanMotion
    retarget: RetargetResult
    safety: SafetyResult
    trajectory: Trajectory


def load_speech_input(
    text: str | None = None,
    audio: str | Path | None = None,
    transcript: str | Path | None = None,
    voice: str = "en-us",
    words_per_minute: int = 160,
    lenient: bool = False,
    units: Mapping[str, object] | None = None,
) -> Speech:
    """Text through eSpeak NG, or an audio file with an optional transcript.

    Text may carry tags (``^gesture``, NAOqi's ``^start``... and ``\\pau=MS\\``: docs/animated-speech.md): a bad
    one is an InputError, or with ``lenient`` dropped with one logged warning; tags are never spoken. ``units``: the
    generator's gesture units by name, to check the tags' names against (None: the generator checks them).
    """
    from robogest import speech as sp

    if (text is None) == (audio is None):
        raise InputError("give either text to speak (TEXT, or --text) or --audio FILE (not both, not neither)")
    if audio is not None:
        return sp.load_speech(audio, transcript)
    if transcript is not None:
        raise InputError("--transcript goes with --audio; with TEXT the words are already known")
    from robogest.generators.tags import ANY_TAG

    text = str(text)  # given: exactly one of text and audio is
    if not ANY_TAG.search(text):
        return sp.synthesize(text, voice=voice, words_per_minute=words_per_minute)
    from robogest.generators.animated_speech import synthesize_script

    # Tags are not spoken; Speech.text keeps them for the generator.
    return synthesize_script(text, voice, words_per_minute, lenient=lenient, units=units)


def silent_mask(spans: tuple[tuple[float, float], ...], t_s: np.ndarray) -> np.ndarray:
    """``(T,)`` bool: sample time lies inside one of ``spans``."""
    mask = np.zeros(t_s.shape, dtype=bool)
    for a, b in spans:
        mask |= (t_s >= a) & (t_s < b)
    return mask


def motion_to_trajectory(
    motion: HumanMotion,
    robot: RobotConfig,
    *,
    silent_spans: tuple[tuple[float, float], ...] = (),
    fps: float = DEFAULT_TRAJECTORY_FPS,
    q0: np.ndarray | None = None,
    safety: SafetyConfig | None = None,
    audio_path: str = "",
) -> tuple[Trajectory, RetargetResult, SafetyResult]:
    """Retarget at the command rate, then make every command safe for ``robot``.

    ``q0 (J,)`` is the robot's present pose (default: rest); the trajectory starts there.
    """
    motion = motion.resample(fps)
    ret = DirectionIK(robot).retarget(motion, q0=q0)
    t_s = np.arange(ret.q_rad.shape[0]) / fps
    silent = silent_mask(silent_spans, t_s)
    res = apply_safety(
        ret.q_rad, JointLimits.from_robot(robot), fps, silent=silent, q0=q0, config=safety or SafetyConfig()
    )
    n = res.q_rad.shape[0]  # may be longer than the motion: the tail comes to rest
    t_all = np.arange(n) / fps
    traj = Trajectory.for_robot(robot, res.q_rad, fps, silent=silent_mask(silent_spans, t_all), audio_path=audio_path)
    return traj, ret, res


def speak(
    speech: Speech,
    robot: RobotConfig,
    generator_name: str = "rhythm",
    *,
    seed: int = 0,
    fps: float = DEFAULT_TRAJECTORY_FPS,
    q0: np.ndarray | None = None,
    safety: SafetyConfig | None = None,
    generator_options: dict | None = None,
) -> SpeakResult:
    """Speech to a safe command trajectory for ``robot``."""
    from robogest.generators import make_generator

    gen = make_generator(generator_name, **(generator_options or {}))
    motion = gen.generate(speech, seed=seed)
    audio_path = str(speech.audio_path) if speech.audio_path else ""
    traj, ret, res = motion_to_trajectory(
        motion, robot, silent_spans=speech.silent_spans, fps=fps, q0=q0, safety=safety, audio_path=audio_path
    )
    traj.annotations = dict(getattr(gen, "annotations", {}))  # plugins need not subclass Generator
    return SpeakResult(speech, motion, ret, res, traj)
