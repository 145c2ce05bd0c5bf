"""``robogest eval``: objective metrics of generated motion or robot trajectories.

Inputs are files or folders (paired by file stem): BVH, SMPL-X ``.npz``, or trajectory ``.npz`` (recognised by
its ``q_rad`` key). Loaders are imported lazily so that ``robogest --help`` stays fast.
"""

from __future__ import annotations

import argparse
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.cli import checks
from robogest.errors import InputError, MissingDependencyError, RobogestError
from robogest.fileio import npz_keys

if TYPE_CHECKING:
    import numpy as np

    from robogest.eval.fgd import FGDEvaluator
    from robogest.motion.human_motion import HumanMotion
    from robogest.speech.types import Speech
    from robogest.trajectory.types import Trajectory

MOTION_SUFFIXES = (".bvh", ".npz")
AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
TRANSCRIPT_SUFFIXES = (".textgrid", ".json", ".txt", ".tsv", ".csv")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "eval",
        help="objective metrics of generated gestures or robot trajectories",
        description="Compare generated motion (--pred) with ground truth (--gt) and/or speech (--audio): "
        "acceleration/jerk, wrist-speed histograms, MAJE/MAD, Fréchet feature distances, chance-corrected "
        "beat sync (PMB, BeatAlign on onset beats; stroke sync: wrist-speed peaks on audio onsets), silence "
        "behaviour; for trajectories limit violations, jerk, time to rest and stroke sync of the robot's wrist sites."
        " With --fgd-weights, FGD with the BEAT2/EMAGE evaluator network. Folders are paired by file stem.",
    )
    p.add_argument("--pred", required=True, metavar="PATH", help="generated motion/trajectory file or folder")
    p.add_argument("--gt", metavar="PATH", help="ground-truth file or folder (same stems as --pred)")
    p.add_argument("--audio", metavar="PATH", help="speech audio file or folder (for beat sync and silences)")
    p.add_argument("--transcript", metavar="PATH", help="transcript file or folder for --audio")
    p.add_argument("--json", metavar="FILE", help="write all metrics as JSON (atomically)")
    p.add_argument(
        "--plots", metavar="DIR", help="write velocity histograms, PMB curves, trajectory plots (needs the plot extra)"
    )
    checks.needs_extra(p, "--plots", "plot")
    p.add_argument(
        "--shifts",
        type=checks.number(2, 100_000, integer=True),
        default=100,
        help="circular shifts for chance-corrected beat scores, 2..100000 (default 100)",
    )
    p.add_argument(
        "--fgd-weights",
        metavar="FILE",
        help="BEAT2/EMAGE evaluator AESKConv_240_100.bin (huggingface.co/H-Liu1997/emage_evaltools): report FGD "
        "of SMPL-X .npz pairs (poses (T, 165) at 30 fps), per file and pooled over all files; needs torch",
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


def load_input(path: Path) -> tuple[str, Trajectory | HumanMotion]:
    """``("trajectory", Trajectory)`` or ``("motion", HumanMotion)``; InputError naming the file otherwise."""

    try:
        if path.suffix.lower() == ".npz" and "q_rad" in npz_keys(path):
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


def load_speech_for(audio: Path, transcript: Path | None) -> Speech:
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


def _robot_wrists(traj: Trajectory, achieved_q_rad: np.ndarray | None) -> np.ndarray | None:
    """Wrist-site positions ``(T, W, 3)`` m of the robot a trajectory names (its achieved motion when simulated),
    or None when the robot is not known here: stroke sync is then left out, the other metrics still run."""
    from robogest.backends.mujoco_sim import wrist_site_positions
    from robogest.robot import find_robot

    if not traj.robot:
        return None
    try:
        robot = find_robot(traj.robot)
    except RobogestError:
        return None
    order = [list(traj.joint_names).index(n) for n in robot.joint_names]
    q = achieved_q_rad if achieved_q_rad is not None else traj.q_rad[:, order]  # robot's joint order
    return wrist_site_positions(robot, q)


def smplx_poses(path: Path) -> tuple[np.ndarray, float] | None:
    """Raw SMPL-X axis-angle ``poses`` ``(T, 165)`` and frame rate of an ``.npz``, or None if it has none."""
    import numpy as np

    from robogest.fileio import read_npz

    if path.suffix.lower() != ".npz" or "poses" not in npz_keys(path):
        return None
    rate_keys = ("mocap_frame_rate", "mocap_framerate", "fps")
    data = read_npz(path, what="SMPL-X", keys=("poses", *rate_keys))
    poses = np.asarray(data["poses"])
    rate = next((data[k] for k in rate_keys if k in data), None)
    if poses.ndim != 2 or poses.shape[1] != 165 or rate is None:
        return None
    return poses.astype(np.float64), float(np.asarray(rate).reshape(-1)[0])


def fgd_of_pair(evaluator: FGDEvaluator, pred_path: Path, gt_path: Path | None) -> dict:
    """FGD of one SMPL-X pair and its real-vs-real floor (gt's first half against its second half).

    ``_features`` (pred, gt latent features) is kept for the pooled FGD and dropped from JSON.
    """
    from robogest.eval.features import frechet_distance

    if gt_path is None:
        raise InputError(f"{pred_path}: --fgd-weights compares with ground truth; pass --gt")
    sides = {}
    for flag, path in (("--pred", pred_path), ("--gt", gt_path)):
        got = smplx_poses(path)
        if got is None:
            raise InputError(
                f"{path}: --fgd-weights needs SMPL-X .npz files with 'poses' (T, 165) and 'mocap_frame_rate' for "
                f"{flag}; the evaluator reads all 55 SMPL-X joints, which BVH/canonical motion does not have"
            )
        sides[flag] = evaluator.features(got[0], str(path), got[1])
    fp, fg = sides["--pred"], sides["--gt"]
    half = len(fg) // 2
    floor = frechet_distance(fg[:half], fg[half:]) if half >= 2 else float("nan")
    return {"fgd": frechet_distance(fp, fg), "real_vs_real": floor, "n_latent_pred": len(fp),
            "n_latent_gt": len(fg), "_features": (fp, fg)}  # fmt: skip


def evaluate_files(
    pred_path: Path,
    gt_path: Path | None,
    audio_path: Path | None = None,
    transcript_path: Path | None = None,
    n_shifts: int = 100,
    sim: bool = False,
    fgd_evaluator: FGDEvaluator | None = None,
) -> dict:
    """Metrics of one pred file (with its gt/audio files, any may be None) as a nested dict; FGD with
    ``fgd_evaluator`` (:class:`robogest.eval.fgd.FGDEvaluator`)."""
    import numpy as np

    from robogest.eval.report import evaluate_motion, evaluate_trajectory
    from robogest.motion.human_motion import HumanMotion
    from robogest.trajectory.types import Trajectory

    kind, pred = load_input(pred_path)
    gt_kind, gt = load_input(gt_path) if gt_path else (None, None)
    if gt is not None and gt_kind != kind:
        raise InputError(f"{gt_path}: is a {gt_kind} but {pred_path} is a {kind}; compare like with like")
    beats = spans = onsets = None
    events = ""
    if audio_path is not None:
        from robogest.eval.beats import stroke_sync_events

        speech = load_speech_for(audio_path, transcript_path)
        beats = np.asarray(speech.beats_s, dtype=np.float64)[~np.asarray(speech.beat_is_pseudo, dtype=bool)]
        spans = [(float(a), float(b)) for a, b in speech.silent_spans]
        # stressed vowels when the transcript is a forced alignment with phones, else librosa onsets (unvalidated)
        onsets, events = stroke_sync_events(speech.audio, speech.sr, transcript_path)
    res: dict
    if isinstance(pred, Trajectory):  # kind "trajectory"
        gt_q = None
        if isinstance(gt, Trajectory):  # gt None or of pred's kind (checked above)
            if list(gt.joint_names) != list(pred.joint_names):
                raise InputError(f"{gt_path}: joints {gt.joint_names} differ from {pred_path}'s {pred.joint_names}")
            t = pred.t_s[pred.t_s <= gt.duration_s + 1e-9]
            gt_q = np.array([gt.sample(x) for x in t]).reshape(len(t), -1)  # pred's rate, gt's span
        achieved = wrists = None
        if sim:
            from robogest.backends.mujoco_sim import simulate
            from robogest.robot import find_robot

            if not pred.robot:
                raise InputError(f"{pred_path}: the trajectory names no robot, so --sim cannot simulate it")
            achieved = simulate(pred, find_robot(pred.robot)).q_achieved_rad
        if onsets is not None:
            wrists = _robot_wrists(pred, achieved)
        res = evaluate_trajectory(
            pred, gt_q, beats, spans, n_shifts=n_shifts, achieved_q_rad=achieved, onsets_s=onsets, wrist_pos_m=wrists
        )
    else:
        gt_motion = gt if isinstance(gt, HumanMotion) else None  # gt is None or of pred's kind (checked above)
        if gt_motion is not None and gt_motion.skeleton.names != pred.skeleton.names:
            raise InputError(f"{gt_path}: skeleton differs from {pred_path}'s")
        gt_pos = None
        if gt_motion is not None:
            res_gt = gt_motion.resample(pred.fps) if gt_motion.fps != pred.fps else gt_motion
            gt_pos = res_gt.positions()
        res = evaluate_motion(
            pred.positions(), pred.fps, pred.skeleton.names, gt_pos, beats, spans, n_shifts, onsets_s=onsets
        )
        if gt_motion is not None and gt_motion.fps != pred.fps:
            res["gt_resampled_from_fps"] = float(gt_motion.fps)
    if fgd_evaluator is not None:
        res["fgd"] = fgd_of_pair(fgd_evaluator, pred_path, gt_path)
    for key in ("beat_sync", "gt_beat_sync"):
        if "stroke_sync" in res.get(key, {}):
            res[key]["stroke_sync"]["events"] = events
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
    from rich.markup import escape

    from robogest.cli.common import TextTable, print_table
    from robogest.eval.report import summary_rows

    for stem, r in results.items():
        title = escape(f"{stem} ({r['kind']}, {r['n_frames']} frames at {r['fps']:g} fps)")
        rows: list[Sequence[str]] = [[escape(name), value] for name, value in summary_rows(r)]
        print_table(TextTable(title, ["metric", "value"], rows, right_aligned=["value"]))


def _drop_private(obj: dict) -> dict:
    """``obj`` without dict keys starting with ``_``, at any depth (objects and arrays kept for plots and pooling)."""
    return {k: _drop_private(v) if isinstance(v, dict) else v for k, v in obj.items() if not str(k).startswith("_")}


def _pooled_fgd(results: dict[str, dict]) -> dict | None:
    """FGD over the latent frames of all files together (how papers report it over a test set)."""
    import numpy as np

    from robogest.eval.features import frechet_distance

    feats = [r["fgd"]["_features"] for r in results.values() if "fgd" in r]
    if not feats:
        return None
    fp = np.concatenate([p for p, _ in feats])
    fg = np.concatenate([g for _, g in feats])
    return {"fgd": frechet_distance(fp, fg), "n_files": len(feats), "n_latent_pred": len(fp), "n_latent_gt": len(fg)}


def run_eval(args: argparse.Namespace) -> int:
    if args.transcript and not args.audio:
        raise InputError("--transcript goes with --audio (the speech it transcribes); add --audio")
    pred_files = _files(Path(args.pred), MOTION_SUFFIXES, "motion/trajectory")
    single = Path(args.pred).is_file()
    gt_files = _files(Path(args.gt), MOTION_SUFFIXES, "ground truth") if args.gt else None
    audio_files = _files(Path(args.audio), AUDIO_SUFFIXES, "audio") if args.audio else None
    tr_files = _files(Path(args.transcript), TRANSCRIPT_SUFFIXES, "transcript") if args.transcript else None
    checks.check_outputs(
        {"--json": args.json},
        {"--pred": pred_files, "--gt": gt_files, "--audio": audio_files, "--transcript": tr_files},
        folders={"--plots": args.plots},
    )
    evaluator = None
    if args.fgd_weights:
        from robogest.eval.fgd import load_evaluator

        evaluator = load_evaluator(args.fgd_weights)
    results: dict[str, dict] = {}
    for pf in pred_files:
        gf = _match(pf, gt_files, single, "ground truth")
        af = _match(pf, audio_files, single, "audio")
        tf = _match(pf, tr_files, single, "transcript")
        key = pf.stem if pf.stem not in results else str(pf)
        results[key] = evaluate_files(pf, gf, af, tf, args.shifts, sim=args.sim, fgd_evaluator=evaluator)
    _print_table(results)
    pooled = _pooled_fgd(results) if evaluator is not None else None
    if pooled is not None:
        print(
            f"FGD pooled over {pooled['n_files']} files: {pooled['fgd']:.4f} (latent frames {pooled['n_latent_pred']}"
            f" generated, {pooled['n_latent_gt']} real)"
        )
    if args.plots:
        for path in _plots(results, Path(args.plots)):
            print(f"wrote {path}")
    if args.json:
        from robogest.eval.report import write_json_atomic

        out: dict = {"results": results}
        if pooled is not None:
            out["fgd_pooled"] = pooled
        write_json_atomic(_drop_private(out), args.json)
        print(f"wrote {args.json}")
    return 0
