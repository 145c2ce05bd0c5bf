"""``robogest eval``: objective metrics of generated motion or robot trajectories.

Inputs are files or folders (paired by file stem): BVH, SMPL-X ``.npz``, or trajectory ``.npz`` (recognised by
its ``q_rad`` key). Loaders are imported lazily so that ``robogest --help`` stays fast.
"""

from __future__ import annotations

import argparse
import zipfile
from pathlib import Path

from robogest.errors import InputError, MissingDependencyError, RobogestError

MOTION_SUFFIXES = (".bvh", ".npz")
AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
TRANSCRIPT_SUFFIXES = (".textgrid", ".json", ".txt", ".tsv", ".csv")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "eval",
        help="objective metrics of generated gestures or robot trajectories",
        description="Compare generated motion (--pred) with ground truth (--gt) and/or speech (--audio): "
        "acceleration/jerk, wrist-speed histograms, MAJE/MAD, Fréchet feature distances, chance-corrected "
        "beat sync (PMB, BeatAlign), silence behaviour; for trajectories limit violations, jerk and time to "
        "rest. Folders are paired by file stem.",
    )
    p.add_argument("--pred", required=True, metavar="PATH", help="generated motion/trajectory file or folder")
    p.add_argument("--gt", metavar="PATH", help="ground-truth file or folder (same stems as --pred)")
    p.add_argument("--audio", metavar="PATH", help="speech audio file or folder (for beat sync and silences)")
    p.add_argument("--transcript", metavar="PATH", help="transcript file or folder for --audio")
    p.add_argument("--json", metavar="FILE", help="write all metrics as JSON (atomically)")
    p.add_argument("--plots", metavar="DIR", help="write velocity histograms, PMB curves, trajectory plots")
    p.add_argument(
        "--shifts", type=int, default=100, help="circular shifts for chance-corrected beat scores (default 100)"
    )
    p.add_argument(
        "--sim",
        action="store_true",
        help="trajectories only: play each in MuJoCo on the robot it was made for and report the tracking error",
    )
    p.set_defaults(func=run_eval)


# ----------------------------------------------------------------------------------------------- inputs


def _files(path: Path, suffixes: tuple[str, ...], what: str) -> list[Path]:
    if not path.exists():
        raise InputError(f"{path}: {what} not found")
    if path.is_file():
        return [path]
    files = sorted(f for f in path.iterdir() if f.is_file() and f.suffix.lower() in suffixes)
    if not files:
        raise InputError(f"{path}: folder has no {what} files ({', '.join(suffixes)})")
    return files


def _match(pred: Path, others: list[Path] | None, single: bool, what: str) -> Path | None:
    """The file among ``others`` that goes with ``pred``: the only one, or the one with the same stem."""
    if others is None:
        return None
    if single and len(others) == 1:
        return others[0]
    for f in others:
        if f.stem == pred.stem:
            return f
    raise InputError(f"{pred}: no {what} with stem {pred.stem!r} to pair with")


def load_input(path: Path):
    """``("trajectory", Trajectory)`` or ``("motion", HumanMotion)``; InputError naming the file otherwise."""
    import numpy as np

    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as z:
                is_traj = "q_rad" in z.files
            if is_traj:
                from robogest.trajectory.types import Trajectory

                return "trajectory", Trajectory.load(path)
        try:
            from robogest.motion import load_motion
        except ImportError:
            raise MissingDependencyError(
                f"{path}: reading motion files needs robogest.motion.load_motion, not in this build"
            ) from None
        return "motion", load_motion(path)
    except RobogestError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        raise InputError(f"{path}: cannot read ({type(e).__name__}: {e})") from None


def load_speech_for(audio: Path, transcript: Path | None):
    try:
        from robogest.speech import load_speech
    except ImportError:
        raise MissingDependencyError(
            "--audio needs robogest.speech.load_speech, not in this build; run without --audio"
        ) from None
    try:
        return load_speech(str(audio), str(transcript) if transcript else None)
    except RobogestError:
        raise
    except (OSError, ValueError, EOFError) as e:
        raise InputError(f"{audio}: cannot read speech ({type(e).__name__}: {e})") from None


# ----------------------------------------------------------------------------------------------- core


def evaluate_files(
    pred_path: Path,
    gt_path: Path | None,
    audio_path: Path | None = None,
    transcript_path: Path | None = None,
    n_shifts: int = 100,
    sim: bool = False,
) -> dict:
    """Metrics of one pred file (with its gt/audio files, any may be None) as a nested dict."""
    import numpy as np

    from robogest.eval.report import evaluate_motion, evaluate_trajectory

    kind, pred = load_input(pred_path)
    gt_kind, gt = load_input(gt_path) if gt_path else (None, None)
    if gt is not None and gt_kind != kind:
        raise InputError(f"{gt_path}: is a {gt_kind} but {pred_path} is a {kind}; compare like with like")
    beats = spans = None
    if audio_path is not None:
        speech = load_speech_for(audio_path, transcript_path)
        beats = np.asarray(speech.beats_s, dtype=np.float64)
        spans = [tuple(map(float, s)) for s in speech.silent_spans]
    res: dict
    if kind == "trajectory":
        gt_q = None
        if gt is not None:
            if list(gt.joint_names) != list(pred.joint_names):
                raise InputError(f"{gt_path}: joints {gt.joint_names} differ from {pred_path}'s {pred.joint_names}")
            t = pred.t_s[pred.t_s <= gt.duration_s + 1e-9]
            gt_q = np.array([gt.sample(x) for x in t]).reshape(len(t), -1)  # pred's rate, gt's span
        achieved = None
        if sim:
            from robogest.backends.mujoco_sim import simulate
            from robogest.robot import find_robot

            if not pred.robot:
                raise InputError(f"{pred_path}: the trajectory names no robot, so --sim cannot simulate it")
            achieved = simulate(pred, find_robot(pred.robot)).q_achieved_rad
        res = evaluate_trajectory(pred, gt_q, beats, spans, n_shifts=n_shifts, achieved_q_rad=achieved)
    else:
        if gt is not None and gt.skeleton.names != pred.skeleton.names:
            raise InputError(f"{gt_path}: skeleton differs from {pred_path}'s")
        gt_pos = None
        if gt is not None:
            res_gt = gt.resample(pred.fps) if gt.fps != pred.fps else gt
            gt_pos = res_gt.positions()
        res = evaluate_motion(pred.positions(), pred.fps, pred.skeleton.names, gt_pos, beats, spans, n_shifts)
        if gt is not None and gt.fps != pred.fps:
            res["gt_resampled_from_fps"] = float(gt.fps)
    res["files"] = {
        "pred": str(pred_path),
        "gt": str(gt_path) if gt_path else None,
        "audio": str(audio_path) if audio_path else None,
    }
    res["_object"] = pred  # for plots; dropped before JSON
    return res


def _plots(results: dict[str, dict], out_dir: Path) -> list[Path]:
    from robogest.eval.plots import plot_pmb_curves, plot_trajectory, plot_wrist_histogram

    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{out_dir}: cannot create plot folder ({e})") from None
    written = []
    for stem, r in results.items():
        if "wrist_speed" in r:
            written.append(plot_wrist_histogram(r["wrist_speed"], out_dir / f"{stem}_wrist_speed.png", stem))
        if "beat_sync" in r:
            curves = {"generated": r["beat_sync"]["pmb_curve"]}
            if "gt_beat_sync" in r:
                curves["ground truth"] = r["gt_beat_sync"]["pmb_curve"]
            written.append(plot_pmb_curves(curves, out_dir / f"{stem}_pmb.png", stem))
        if r["kind"] == "trajectory":
            written.append(plot_trajectory(r["_object"], out_dir / f"{stem}_trajectory.png", stem))
    return written


def _print_table(results: dict[str, dict]) -> None:
    from rich.console import Console
    from rich.table import Table

    from robogest.eval.report import summary_rows

    console = Console()
    for stem, r in results.items():
        table = Table(title=f"{stem} ({r['kind']}, {r['n_frames']} frames at {r['fps']:g} fps)")
        table.add_column("metric")
        table.add_column("value", justify="right")
        for name, value in summary_rows(r):
            table.add_row(name, value)
        console.print(table)


def run_eval(args: argparse.Namespace) -> int:
    pred_files = _files(Path(args.pred), MOTION_SUFFIXES, "motion/trajectory")
    single = Path(args.pred).is_file()
    gt_files = _files(Path(args.gt), MOTION_SUFFIXES, "ground truth") if args.gt else None
    audio_files = _files(Path(args.audio), AUDIO_SUFFIXES, "audio") if args.audio else None
    tr_files = _files(Path(args.transcript), TRANSCRIPT_SUFFIXES, "transcript") if args.transcript else None
    if args.shifts < 2:
        raise InputError(f"--shifts must be at least 2, got {args.shifts}")
    results: dict[str, dict] = {}
    for pf in pred_files:
        gf = _match(pf, gt_files, single, "ground truth")
        af = _match(pf, audio_files, single, "audio")
        tf = _match(pf, tr_files, single, "transcript")
        key = pf.stem if pf.stem not in results else str(pf)
        results[key] = evaluate_files(pf, gf, af, tf, args.shifts, sim=args.sim)
    _print_table(results)
    if args.plots:
        for path in _plots(results, Path(args.plots)):
            print(f"wrote {path}")
    if args.json:
        from robogest.eval.report import write_json_atomic

        clean = {k: {kk: vv for kk, vv in v.items() if not kk.startswith("_")} for k, v in results.items()}
        write_json_atomic({"results": clean}, args.json)
        print(f"wrote {args.json}")
    return 0
