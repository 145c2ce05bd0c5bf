"""``robogest speak`` and ``robogest play``: the main job, on the MuJoCo sim or real servos."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.cli import checks
from robogest.cli.common import (
    add_gesture_args,
    add_speech_args,
    ensure_audio_file,
    generator_options,
    robot_files,
    speech_from_args,
    speech_inputs,
)
from robogest.robot.registry import DEFAULT_ROBOT

if TYPE_CHECKING:  # imported lazily: `robogest --help` must not load numpy
    from collections.abc import Mapping

    import numpy as np

    from robogest.backends.base import Backend
    from robogest.robot.config import RobotConfig
    from robogest.trajectory import Trajectory

SPEAK_EPILOG = """examples:
  robogest speak "Hello, I am a robot. Nice to meet you!" --video out/hello.mp4
  robogest speak --audio talk.wav --transcript talk.TextGrid --robot humanoid_sts3215 --save out/talk.npz
  robogest speak "Hi" --backend dynamixel --port /dev/ttyUSB0
  robogest speak "Look ^gesture(point_away) over there. It is huge!" --style lively
  robogest speak "Hello! \\pau=800\\ ^start(animations/Stand/Gestures/Explain_1) Let me explain." --lenient

With --backend sim (the default) nothing moves but the MuJoCo model; with dynamixel/feetech the robot's
bus section gives ids and models, --port/--baud override it. Every command goes through the safety layer
(joint limits, velocity and acceleration limits, rest in silent pauses) and, at the control rate (--fps),
the online limiter (position, velocity, acceleration and jerk); on a crash, Ctrl-C, Ctrl-\\, SIGTERM or SIGHUP
the robot glides to rest and torque is turned off, and so it does, naming the servo (exit 5), when a servo is found
in error, lost, or limp (its torque off: a brownout, or another program on the bus).
"""


def _add_output_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", default=DEFAULT_ROBOT, help="robot name from `robogest robots list`, or a YAML path "
                   "(default: %(default)s)")  # fmt: skip
    p.add_argument(
        "--backend", default="sim", help="sim (MuJoCo, default), dynamixel, feetech, or an installed plugin's backend"
    )
    p.add_argument("--port", help="serial port for dynamixel/feetech (default: the robot YAML's bus.port)")
    p.add_argument("--baud", type=checks.baud, help="baud rate (default: the robot YAML's bus.baudrate)")
    p.add_argument("--fps", type=checks.rate_hz, default=50.0, help="command rate, 1..1000 Hz (default: %(default)s)")
    p.add_argument("--save", metavar="FILE.npz", help="write the final command trajectory (and spoken TEXT beside it "
                   "as FILE.wav, which may replace only an earlier --save's audio)")  # fmt: skip
    p.add_argument(
        "--export",
        metavar="FILE",
        help="also write the command trajectory for other tools: FILE.mcap (ROS 2 bag), FILE.csv, or a "
        "name without suffix (ROS 2 bag folder); times on the speech audio's clock",
    )
    p.add_argument(
        "--video",
        metavar="FILE.mp4",
        help="render the simulated robot with the speech audio (sim; three-quarter view; needs the video extra)",
    )
    p.add_argument("--video-size", metavar="WxH", type=checks.frame_size,
                   help="video frame size in pixels, even numbers (default: 1280x720 with a GPU renderer, 640x360 "
                   "with a software one such as Mesa llvmpipe, where it renders near real time)")  # fmt: skip
    p.add_argument(
        "--plot",
        metavar="FILE.png",
        help="plot wrist trajectories, beats, silent spans, joint commands (needs the plot extra)",
    )
    checks.needs_extra(p, "--video", "video")
    checks.needs_extra(p, "--plot", "plot")
    p.add_argument("--realtime", action="store_true", help="run the simulation in real time (sim)")
    p.add_argument("--view", action="store_true", help="open the MuJoCo viewer (needs a display)")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "speak",
        help="speak a sentence (or audio file) with co-speech gestures on a robot or the simulator",
        description="Speech -> gestures -> retargeting -> safety layer -> robot. Default: the simulated "
        f"{DEFAULT_ROBOT} in MuJoCo.",
        epilog=SPEAK_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_speech_args(p)
    p.add_argument(
        "--generator",
        default="rhythm",
        help="gesture generator: rhythm, gesticulator, rhythmic, s2ag, or an installed plugin's (default: %(default)s)",
    )
    p.add_argument("--checkpoint", metavar="FILE", help="trained weights for a learned generator")
    p.add_argument(
        "--seed", type=checks.seed, default=0, help="random seed, 0..2**32-1; same input + seed = same motion"
    )
    add_gesture_args(p)
    p.add_argument("--lenient", action="store_true", help="drop tags in TEXT that robogest cannot use (one warning) "
                   "instead of refusing them; tags are never spoken (docs/animated-speech.md)")  # fmt: skip
    _add_output_args(p)
    p.set_defaults(func=run_speak)

    q = sub.add_parser(
        "play",
        help="play a motion file (BVH, SMPL-X .npz) or a saved trajectory .npz on a robot",
        description="Imported human motion goes through the same retargeting and safety layer as `speak`; "
        "a trajectory saved with --save is re-checked against the robot's limits and played as is.",
    )
    q.add_argument("motion", metavar="MOTION", help=".bvh, SMPL-X .npz, or a trajectory .npz from --save")
    q.add_argument(
        "--audio",
        metavar="FILE",
        help="audio to play/mux with the motion (--video without it: the audio the trajectory names, else the "
        ".wav of MOTION's name beside it)",
    )
    _add_output_args(q)
    q.set_defaults(func=run_play)


def _check_paths(args: argparse.Namespace, inputs: Mapping[str, str | list[str] | None]) -> None:
    """Refuse bad output paths before any work (see :func:`robogest.cli.checks.check_outputs`)."""
    outputs = {"--save": args.save, "--video": args.video, "--plot": args.plot}
    if args.export and Path(args.export).suffix:  # a file (.mcap, .csv); a bag folder is check_export's to judge
        outputs["--export"] = args.export
    if args.save and getattr(args, "text", None) is not None:  # synthesized speech is saved beside --save
        outputs["--save's audio"] = str(Path(args.save).with_suffix(".wav"))
        _check_audio_beside_save(Path(args.save))
    checks.check_outputs(outputs, {**inputs, "--robot": robot_files(args.robot)})


def _check_audio_beside_save(save: Path) -> None:
    """The ``.wav`` that ``--save X.npz`` writes for synthesized speech may replace only the audio of an earlier
    ``--save X.npz`` (the trajectory ``X.npz`` there names it): an unrelated ``X.wav`` was replaced silently."""
    import os

    from robogest.errors import InputError
    from robogest.trajectory.types import saved_audio_path

    wav = save.with_suffix(".wav")
    if not os.path.lexists(wav) or not os.path.isfile(wav):  # a folder, FIFO...: check_outputs says why
        return
    try:
        named = saved_audio_path(save)
    except InputError:  # no earlier trajectory there, or not a readable one
        named = ""
    if not named or Path(named).name != wav.name:
        raise InputError(
            f"--save {save}: would replace {wav}, which is not the audio of an earlier --save {save}; the "
            "synthesized speech is written beside --save as .wav: move that file or choose another --save name"
        )


def _backend_options(args: argparse.Namespace) -> dict:
    return {"port": args.port, "baudrate": args.baud}


def _report(result_lines: list[str]) -> None:
    for line in result_lines:
        print(line)


def _check_export(args: argparse.Namespace) -> None:
    """A bad --export (name, existing folder, rosbags missing) fails before anything is computed or moves."""
    if args.export:
        from robogest.trajectory.export import check_export

        check_export(args.export)


def _hardware_backend(args: argparse.Namespace, robot: RobotConfig) -> Backend | None:
    """The real backend ``--backend`` names, made before any work (None for the simulator), so an unknown backend,
    a missing port, a robot file the servos cannot keep or a simulator-only flag fails before anything is computed
    or written."""
    if args.backend == "sim":
        return None
    from robogest.backends import get_backend_factory
    from robogest.backends.servos.check import require_hardware_safe
    from robogest.errors import InputError

    sim_only = [flag for flag, on in (("--video", args.video), ("--realtime", args.realtime), ("--view", args.view))
                if on]  # fmt: skip
    if sim_only:
        raise InputError(f"{', '.join(sim_only)}: the simulator's only; leave them out with --backend {args.backend}")
    backend = get_backend_factory(args.backend)(robot, **_backend_options(args))
    require_hardware_safe(robot)
    return backend


def _finish(
    args: argparse.Namespace,
    robot: RobotConfig,
    traj: Trajectory,
    audio: np.ndarray | None,
    sr: int,
    backend: Backend | None = None,
) -> None:
    """Save, export, then play on the chosen backend (``backend``, from :func:`_hardware_backend`; the simulator
    when None), printing each result as soon as it is known."""
    from robogest.cli.progress import progress_bar

    if args.save:
        traj.save(args.save)
        print(f"trajectory: {args.save} ({traj.n_frames} frames at {traj.fps:g} Hz, {traj.duration_s:.2f} s)")
    if args.export:
        from robogest.trajectory.export import export_trajectory

        print(f"exported: {export_trajectory(traj, args.export)}")
    if backend is None:
        _simulate(args, robot, traj, audio, sr)
    else:
        from robogest.backends.player import play

        with progress_bar("playing") as cb:
            rep = play(
                traj, backend, rate_hz=args.fps, audio=audio, audio_sr=sr,
                progress=lambda t, d: cb(round(t, 1), round(d, 1)),
            )  # fmt: skip
        print(
            f"played {rep.n_ticks} ticks; period p50 {rep.p50_period_ms:.2f} ms, p99 {rep.p99_period_ms:.2f} ms, "
            f"late ticks {rep.late_ticks}, bus retries {rep.retries}, missed reads {rep.missed_reads}"
        )


def _tag_units(generator: str, opts: dict) -> dict | None:
    """The units the rhythm generator will use, which TEXT's tags must name (None: another generator, which
    reads no tags)."""
    if generator != "rhythm":
        return None
    from robogest.generators import lexicon as lx

    return (opts.get("repertoire") or lx.default_repertoire()).units


def _simulate(
    args: argparse.Namespace, robot: RobotConfig, traj: Trajectory, audio: np.ndarray | None, sr: int
) -> None:
    """Play on the simulator; with ``--video``, say first at what size and on what renderer, and in the progress
    line how long the rest will take."""
    from robogest.backends.mujoco_sim import simulate
    from robogest.cli.progress import progress_bar

    width = height = None
    if args.video:
        from robogest.backends.render import VIDEO_FPS, video_settings

        v = video_settings(*(args.video_size or (None, None)))
        width, height = v.width, v.height
        soft = " (software)" + ("; --video-size 1280x720 for full size" if not args.video_size else "")
        print(f"video: rendering {v.size} at {VIDEO_FPS} fps on {v.renderer}{soft if v.cheap else ''}", flush=True)
    with progress_bar("simulating" + (" + rendering" if args.video else ""), eta=bool(args.video)) as cb:
        rep = simulate(
            traj, robot, video_path=args.video, audio=audio, audio_sr=sr, realtime=args.realtime,
            view=args.view, progress=lambda t, d: cb(round(t, 1), round(d, 1)), rate_hz=args.fps,
            width=width, height=height,
        )  # fmt: skip
    print(f"sim tracking error: RMS {rep.tracking_rms_deg_overall:.2f} deg, max {rep.max_abs_error_deg:.2f} deg")
    if args.video:
        print(f"video: {args.video} ({rep.n_video_frames} frames, {rep.wall_s:.1f} s)")


def run_speak(args: argparse.Namespace) -> int:
    import numpy as np

    from robogest.pipeline import speak
    from robogest.robot import find_robot
    from robogest.tools.validate import require_followable

    _check_paths(args, {**speech_inputs(args), "--checkpoint": args.checkpoint})
    _check_export(args)
    robot = find_robot(args.robot)
    require_followable(robot)
    opts = generator_options(args)
    backend = _hardware_backend(args, robot)
    speech = speech_from_args(args, _tag_units(args.generator, opts))
    result = speak(speech, robot, args.generator, seed=args.seed, fps=args.fps, generator_options=opts)
    traj = result.trajectory
    if args.save:
        traj.audio_path = ensure_audio_file(speech, Path(args.save))
    lines = [
        f"speech: {speech.duration_s:.2f} s, {len(speech.words)} words, {len(speech.beats_s)} beats, "
        f"{len(speech.silent_spans)} silent spans",
        f"robot: {robot.name} ({len(robot.joints)} joints); generator: {args.generator}, seed {args.seed}",
        f"retargeting: mean direction error {np.degrees(result.retarget.direction_error_rad.mean()):.1f} deg",
    ]
    if args.plot:
        from robogest.viz.plot import plot_motion

        plot_motion(args.plot, result.motion, speech, traj, robot)
        lines.append(f"plot: {args.plot}")
    _report(lines)  # before the (long) playback, so a pipe or log sees it at once
    _finish(args, robot, traj, speech.audio, speech.sr, backend)
    return 0


def run_play(args: argparse.Namespace) -> int:

    from robogest.errors import InputError
    from robogest.fileio import npz_keys
    from robogest.pipeline import motion_to_trajectory
    from robogest.robot import find_robot
    from robogest.safety import check_limits
    from robogest.tools.validate import require_followable
    from robogest.trajectory import Trajectory, check_matches

    path = Path(args.motion)
    if not path.is_file():
        raise InputError(f"{path}: no such motion file")
    _check_paths(args, {"MOTION": args.motion, "--audio": args.audio})
    _check_export(args)
    robot = find_robot(args.robot)
    require_followable(robot)  # before the motion file is read: a robot that cannot follow is refused first
    is_traj = path.suffix == ".npz" and "q_rad" in npz_keys(path)
    audio_file, audio_line = _play_audio(args, path, is_traj)
    if audio_file != args.audio:
        _check_paths(args, {"MOTION": args.motion, "--audio": audio_file})
    backend = _hardware_backend(args, robot)
    audio, sr = None, 16000
    if audio_file:
        from robogest.speech import load_speech

        sp = load_speech(audio_file)
        audio, sr = sp.audio, sp.sr
    if is_traj:
        traj = Trajectory.load(path)
        check_matches(traj, robot, str(path))  # joints, limits and rest pose must be the robot's
        from robogest.errors import SafetyError
        from robogest.safety import JointLimits

        lim = JointLimits.from_robot(robot)
        try:
            check_limits(traj.q_rad, lim, 1.0 / traj.fps, lim.q_min_rad, lim.q_max_rad)
        except SafetyError as e:
            raise SafetyError(f"{path}: refusing to play on {robot.name}: {e}") from None
    else:
        from robogest.motion import load_motion

        motion = load_motion(path)
        traj, _, _ = motion_to_trajectory(motion, robot, fps=args.fps, audio_path=args.audio or "")
    lines = [f"motion: {path} -> {traj.n_frames} commands at {traj.fps:g} Hz for {robot.name}"]
    _report([*lines, *([audio_line] if audio_line else [])])
    _finish(args, robot, traj, audio, sr, backend)
    return 0


def _play_audio(args: argparse.Namespace, motion: Path, is_traj: bool) -> tuple[str | None, str]:
    """The audio file ``play`` uses, and (with ``--video``) a line saying which one or why the video is silent.

    ``--audio`` wins; with ``--video``, else the audio the trajectory names (``speak --save`` records it: first its
    file name beside MOTION, then the name as recorded), else the ``.wav`` of MOTION's name beside it.
    """
    if args.audio or not args.video:
        return args.audio, ""
    from robogest.trajectory.types import saved_audio_path

    named = saved_audio_path(motion) if is_traj else ""
    if named:
        tried = [motion.parent / Path(named).name, Path(named)]  # speak --save writes it beside the trajectory
        found = next((p for p in tried if p.is_file()), None)
        if found is not None:
            return str(found), f"audio: {found} (named in the trajectory)"
    beside = motion.with_suffix(".wav")
    if beside.is_file() and beside != motion:
        return str(beside), f"audio: {beside} (beside {motion.name})"
    why = f"the trajectory names {named}, which is missing," if named else f"{motion.name} names no audio"
    return None, f"video: silent: {why} and there is no {beside}; give --audio FILE"
