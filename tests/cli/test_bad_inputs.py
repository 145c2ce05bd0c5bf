"""Bad inputs, bad outputs and bad option values, one row each: every one ends in exactly one line on stderr, a
documented exit code, no traceback, and the working folder exactly as it was (inputs unchanged, no partial file).

Rows run in-process in a fresh temporary folder (the working directory), after their fixture maker has built the
files they need. Exit codes: 1 an output could not be written, 2 bad input or option (argparse's usage errors too).
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import os
import re
import stat
import subprocess
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from robogest.cli.main import main
from robogest.motion import HumanMotion, save_bvh
from robogest.robot import find_robot
from tests.conftest import REPO, fill_up, mount_tmpfs

ROBOT = "humanoid_xl430"


# ------------------------------------------------------------------------------------------------ fixture makers


def traj(name: str = "t.npz", n: int = 10, **override: object) -> Callable[[Path], None]:
    """A trajectory file for ROBOT (rest pose, 50 Hz) with any array replaced, saved as raw ``np.savez``."""

    def make(d: Path) -> None:
        r = find_robot(ROBOT)
        arrays: dict[str, object] = {
            "t_s": np.arange(n) / 50.0,
            "q_rad": np.tile(r.rest_q_rad, (n, 1)),
            "joint_names": np.array(r.joint_names),
            "q_min_rad": r.q_min_rad,
            "q_max_rad": r.q_max_rad,
            "v_max_rad_s": r.v_max_rad_s,
            "a_max_rad_s2": r.a_max_rad_s2,
            "rest_q_rad": r.rest_q_rad,
            "silent": np.zeros(n, bool),
            "audio_path": np.array(""),
            "robot": np.array(r.name),
        }
        arrays.update(override)
        np.savez(d / name, **arrays)

    return make


def wav(name: str = "a.wav", sr: int = 16000) -> Callable[[Path], None]:
    def make(d: Path) -> None:
        t = np.arange(sr) / sr
        sf.write(d / name, 0.3 * np.sin(2 * np.pi * 220 * t), sr, format="WAV", subtype="PCM_16")

    return make


def bvh(name: str = "m.bvh", frame_time: str | None = None) -> Callable[[Path], None]:
    def make(d: Path) -> None:
        save_bvh(HumanMotion.rest(5, 30.0), d / name)
        if frame_time is not None:
            text = re.sub(r"Frame Time: \S+", f"Frame Time: {frame_time}", (d / name).read_text())
            (d / name).write_text(text)

    return make


def bvh_many_joints(d: Path) -> None:
    """100 000 joints without channels under a 3-channel root, 601 frames: 6e7 frame-joints from a 4 MB file."""
    n = 100_000
    lines = ["HIERARCHY", "ROOT hips", "{", "OFFSET 0 0 0", "CHANNELS 3 Xposition Yposition Zposition"]
    for i in range(n):
        lines += [f"JOINT j{i}", "{", "OFFSET 0 1 0"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * (n + 1)
    lines += ["MOTION", "Frames: 601", "Frame Time: 0.0333333"] + ["0 0 0"] * 601
    (d / "wide.bvh").write_text("\n".join(lines) + "\n")


def bvh_long(d: Path) -> None:
    """One joint, one channel, a million frames of one second: 11 days, from a 2 MB file."""
    head = ["HIERARCHY", "ROOT hips", "{", "OFFSET 0 0 0", "CHANNELS 1 Xposition", "End Site", "{", "OFFSET 0 1 0", "}"]
    lines = [*head, "}", "MOTION", "Frames: 1000000", "Frame Time: 1"] + ["0"] * 1_000_000
    (d / "long.bvh").write_text("\n".join(lines) + "\n")


def text(name: str, content: str) -> Callable[[Path], None]:
    return lambda d: (d / name).write_text(content)


def edit(name: str, old: str, new: str) -> Callable[[Path], None]:
    """Replace ``old`` (which must be there) with ``new`` in the file ``name``."""

    def make(d: Path) -> None:
        text = (d / name).read_text()
        assert old in text, old
        (d / name).write_text(text.replace(old, new))

    return make


def sparse(name: str, size: int) -> Callable[[Path], None]:
    def make(d: Path) -> None:
        with open(d / name, "wb") as f:
            f.truncate(size)

    return make


def npz_declaring(name: str, shape: tuple[int, ...]) -> Callable[[Path], None]:
    """An .npz whose q_rad header declares ``shape`` (float64) but stores 80 bytes of data."""

    def make(d: Path) -> None:
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
        buf.write(b"\0" * 80)
        with zipfile.ZipFile(d / name, "w") as zf:
            zf.writestr("q_rad.npy", buf.getvalue())

    return make


def null_device(d: Path) -> None:
    """A stand-in for /dev/null at ``d/null`` (the real one is never risked: code without the check would replace
    it); skips where device nodes cannot be made (not root)."""
    try:
        os.mknod(d / "null", 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("cannot make a device node here (not root); the FIFO rows cover special files")


def robot_copy(d: Path) -> None:
    """A copy of ROBOT's YAML in ``d/robots`` (its model through ``d/sim``), so no row can touch the repo's files."""
    (d / "robots").mkdir()
    (d / "robots" / f"{ROBOT}.yaml").write_bytes((REPO / "robots" / f"{ROBOT}.yaml").read_bytes())
    (d / "sim").symlink_to(REPO / "sim")


def folder(name: str) -> Callable[[Path], None]:
    return lambda d: (d / name).mkdir()


def fifo(name: str) -> Callable[[Path], None]:
    return lambda d: os.mkfifo(d / name)


def symlink(name: str, target: str) -> Callable[[Path], None]:
    return lambda d: (d / name).symlink_to(target)


def hardlink(name: str, target: str) -> Callable[[Path], None]:
    return lambda d: os.link(d / target, d / name)


def read_only_folder(name: str) -> Callable[[Path], None]:
    def make(d: Path) -> None:
        (d / name).mkdir()
        (d / name).chmod(0o555)
        if os.access(d / name, os.W_OK):
            pytest.skip("running as root: a read-only folder is writable anyway")

    return make


def read_only_file(name: str) -> Callable[[Path], None]:
    def make(d: Path) -> None:
        (d / name).write_text("keep me")
        (d / name).chmod(0o444)  # refused as root too, whom the kernel lets write it

    return make


def read_only_fs(name: str = "ro") -> Callable[[Path], None]:
    """A read-only tmpfs at ``name`` (unwritable even for root; skips where mounting is not allowed)."""
    return lambda d: mount_tmpfs(d / name, "size=64k,ro")


def full_disk(name: str = "full") -> Callable[[Path], None]:
    """A 64 kB tmpfs at ``name``, filled up (skips where mounting is not allowed)."""

    def make(d: Path) -> None:
        mount_tmpfs(d / name, "size=64k")
        fill_up(d / name)

    return make


def renderer(d: Path) -> None:
    """Skip the row where MuJoCo cannot render offscreen (no EGL)."""
    from robogest.backends.mujoco_sim import load_sim_model
    from robogest.backends.render import make_renderer
    from robogest.errors import MissingDependencyError

    try:
        make_renderer(load_sim_model(find_robot(ROBOT)).model, 32, 32).close()
    except MissingDependencyError as e:
        pytest.skip(str(e))


def all_of(*makers: Callable[[Path], None]) -> Callable[[Path], None]:
    def make(d: Path) -> None:
        for m in makers:
            m(d)

    return make


# ------------------------------------------------------------------------------------------------ the table


@dataclass
class Case:
    id: str
    argv: list[str]
    make: Callable[[Path], None] | None = None
    code: int = 2
    line: str = ""  # regex the one stderr line must match (re.search)
    needs: tuple[str, ...] = field(default_factory=tuple)  # importable modules the row needs


A = ["--robot", ROBOT]
CASES = [
    # --- an output that is an input, or another output (refused before any work; the input stays as it was)
    Case("generate-out-is-audio", ["generate", "--audio", "a.wav", "--out", "a.wav"], wav(), 2,
         r"--out a\.wav is the same file as the input --audio a\.wav"),
    Case("generate-plot-is-transcript", ["generate", "--audio", "a.wav", "--transcript", "w.txt", "--out", "m.bvh",
         "--plot", "w.txt"], all_of(wav(), text("w.txt", "hello")), 2,
         r"--plot w\.txt is the same file as .*--transcript"),
    Case("generate-out-equals-plot", ["generate", "--audio", "a.wav", "--out", "x.png", "--plot", "./x.png"], wav(), 2,
         r"--plot \./x\.png and --out x\.png name the same file"),
    Case("speak-save-is-audio", ["speak", "--audio", "a.wav", "--save", "a.wav"], wav(), 2,
         r"--save a\.wav is the same file as the input --audio"),
    Case("speak-save-equals-plot", ["speak", "--audio", "a.wav", "--save", "o.npz", "--plot", "o.npz"], wav(), 2,
         r"--plot o\.npz and --save o\.npz name the same file"),
    Case("speak-text-save-wav-is-plot", ["speak", "Hi", "--save", "o.npz", "--plot", "o.wav"], None, 2,
         r"--save's audio o\.wav and --plot o\.wav name the same file"),
    Case("speak-text-save-beside-unrelated-wav", ["speak", "Hi", "--save", "o.npz"], wav("o.wav"), 2,
         r"--save o\.npz: would replace o\.wav, which is not the audio of an earlier --save o\.npz"),
    Case("speak-video-is-robot-yaml", ["speak", "--audio", "a.wav", "--robot", "r.yaml", "--video", "sub/../r.yaml"],
         all_of(wav(), text("r.yaml", "name: x\n")), 2,
         r"--video sub/\.\./r\.yaml is the same file as the input --robot"),
    Case("speak-save-via-symlink-to-audio", ["speak", "--audio", "a.wav", "--save", "link.npz"],
         all_of(wav(), symlink("link.npz", "a.wav")), 2, r"--save link\.npz is the same file as the input --audio"),
    Case("speak-save-hardlink-of-audio", ["speak", "--audio", "a.wav", "--save", "hard.npz"],
         all_of(wav(), hardlink("hard.npz", "a.wav")), 2, r"--save hard\.npz is the same file as the input --audio"),
    Case("analyze-features-is-audio", ["analyze", "a.wav", "--save-features", "a.wav"], wav(), 2,
         r"--save-features a\.wav is the same file as the input --audio"),
    Case("play-save-is-motion", ["play", "t.npz", *A, "--save", "t.npz"], traj(), 2,
         r"--save t\.npz is the same file as the input MOTION t\.npz"),
    Case("play-plot-equals-video", ["play", "t.npz", *A, "--plot", "o.mp4", "--video", "o.mp4"], traj(), 2,
         r"--plot o\.mp4 and --video o\.mp4 name the same file"),
    Case("eval-json-is-pred", ["eval", "--pred", "t.npz", "--json", "t.npz"], traj(), 2,
         r"--json t\.npz is the same file as the input --pred t\.npz"),
    Case("eval-json-is-file-in-pred-folder", ["eval", "--pred", "d", "--json", "d/t.npz"],
         all_of(folder("d"), traj("d/t.npz")), 2, r"--json d/t\.npz is the same file as the input --pred"),
    Case("train-out-is-data", ["train", "--data", "d", "--out", "d/."], folder("d"), 2,
         r"--out d/\. is the dataset folder --data d"),
    # --- an output path that cannot be written
    Case("generate-out-is-folder", ["generate", "--audio", "a.wav", "--out", "d"], all_of(wav(), folder("d")), 2,
         r"--out d: is a folder"),
    Case("speak-plot-is-folder", ["speak", "--audio", "a.wav", "--plot", "d"], all_of(wav(), folder("d")), 2,
         r"--plot d: is a folder"),
    Case("play-video-is-folder", ["play", "t.npz", *A, "--video", "d"], all_of(traj(), folder("d")), 2,
         r"--video d: is a folder"),
    Case("play-save-parent-is-file", ["play", "t.npz", *A, "--save", "f/x.npz"], all_of(traj(), text("f", "x")), 2,
         r"--save f/x\.npz: .*f is a file, not a folder"),
    Case("play-save-read-only-folder", ["play", "t.npz", *A, "--save", "ro/x.npz"], all_of(traj(),
         read_only_folder("ro")),
         2, r"--save ro/x\.npz: the folder .*ro is not writable"),
    Case("play-save-read-only-file", ["play", "t.npz", *A, "--save", "ro.npz"], all_of(traj(),
         read_only_file("ro.npz")),
         2, r"--save ro\.npz: the file is read-only"),
    Case("play-save-read-only-fs", ["play", "t.npz", *A, "--save", "ro/x.npz"], all_of(traj(), read_only_fs()), 2,
         r"--save ro/x\.npz: the folder .*ro is not writable"),
    Case("play-save-dangling-symlink", ["play", "t.npz", *A, "--save", "x.npz"],
         all_of(traj(), symlink("x.npz", "gone/dir/x.npz")), 2,
         r"--save x\.npz: goes through a symlink to .*gone/dir, which does not exist"),
    Case("play-save-via-dangling-folder-link", ["play", "t.npz", *A, "--save", "out/new/x.npz"],
         all_of(traj(), symlink("out", "gone")), 2, r"--save out/new/x\.npz: goes through a symlink to .*gone/new"),
    Case("play-save-name-too-long", ["play", "t.npz", *A, "--save", "x" * 300 + ".npz"], traj(), 2,
         r"--save x{20}\.\.\.x{8}\.npz: the name is 304 bytes long, more than the 255"),
    Case("play-save-folder-name-too-long", ["play", "t.npz", *A, "--save", "x" * 300 + "/f.npz"], traj(), 2,
         r"--save x{20}\.\.\.x{12}: the name is 300 bytes long"),
    Case("play-motion-name-too-long", ["play", "x" * 300 + ".npz", *A], None, 2,
         r"x{30}\.\.\.x{16}\.npz: the file name is too long for this file system"),
    Case("analyze-transcript-name-too-long", ["analyze", "a.wav", "--transcript", "x" * 300 + ".txt"], wav(), 2,
         r"x\.txt: the file name is too long"),
    Case("play-save-dev-null", ["play", "t.npz", *A, "--save", "null"], all_of(traj(), null_device), 2,
         r"--save null: is a device, FIFO or socket"),
    Case("play-save-fifo", ["play", "t.npz", *A, "--save", "p.npz"], all_of(traj(), fifo("p.npz")), 2,
         r"--save p\.npz: is a device, FIFO or socket"),
    Case("play-save-symlink-to-dev-null", ["play", "t.npz", *A, "--save", "n.npz"],
         all_of(traj(), null_device, symlink("n.npz", "null")), 2,
         r"--save n\.npz: is a device, FIFO or socket \(via the symlink"),
    Case("analyze-features-folder-missing", ["analyze", "a.wav", "--save-features", "no/f.npz"], wav(), 2,
         r"--save-features no/f\.npz: the folder does not exist"),
    Case("analyze-features-dev-null", ["analyze", "a.wav", "--save-features", "null"], all_of(wav(), null_device), 2,
         r"--save-features null: is a device"),
    Case("generate-out-fifo", ["generate", "--audio", "a.wav", "--out", "p.bvh"], all_of(wav(), fifo("p.bvh")), 2,
         r"--out p\.bvh: is a device, FIFO or socket"),
    Case("speak-video-symlink-to-fifo", ["speak", "--audio", "a.wav", "--video", "v.mp4"],
         all_of(wav(), fifo("p"), symlink("v.mp4", "p")), 2, r"--video v\.mp4: is a device, FIFO or socket \(via"),
    Case("eval-json-dev-null", ["eval", "--pred", "t.npz", "--json", "null"], all_of(traj(), null_device), 2,
         r"--json null: is a device"),
    Case("virtual-bus-record-dev-null", ["virtual-bus", "--robot", ROBOT, "--record", "null"], null_device, 2,
         r"--record null: is a device"),
    Case("train-out-parent-is-file", ["train", "--data", "d", "--out", "f/run"], all_of(folder("d"), text("f", "x")),
         2, r"--out f/run: .*f is a file, not a folder"),
    Case("eval-json-is-folder", ["eval", "--pred", "t.npz", "--json", "d"], all_of(traj(), folder("d")), 2,
         r"--json d: is a folder"),
    Case("eval-plots-is-file", ["eval", "--pred", "t.npz", "--plots", "f"], all_of(traj(), text("f", "x")), 2,
         r"--plots f: is a file, not a folder"),
    Case("robots-render-is-folder", ["robots", "show", ROBOT, "--render", "d"], folder("d"), 2,
         r"--render d: is a folder"),
    Case("robots-render-dev-null", ["robots", "show", ROBOT, "--render", "null"], null_device, 2,
         r"--render null: is a device"),
    Case("virtual-bus-record-is-folder", ["virtual-bus", "--robot", ROBOT, "--record", "d"], folder("d"), 2,
         r"--record d: is a folder"),
    Case("import-urdf-out-is-urdf", ["robots", "import-urdf", "a.urdf", "--out", "a.urdf", "--force"],
         text("a.urdf", "<robot name='a'/>"), 2, r"--out a\.urdf is the same file as the input description a\.urdf"),
    Case("lerobot-calibration-out-is-robot-yaml", ["robots", "import-lerobot-calibration", "c.json", "--robot",
         f"robots/{ROBOT}.yaml", "--out", f"robots/{ROBOT}.yaml", "--force"],
         all_of(text("c.json", "{}"), robot_copy), 2,
         r"--out robots/humanoid_xl430\.yaml is the same file as the input --robot"),
    Case("servo-calibrate-out-is-folder", ["servo", "calibrate", "--robot", f"robots/{ROBOT}.yaml", "--port", "nope",
         "--out", "d"], all_of(robot_copy, folder("d")), 2, r"--out d: is a folder"),
    Case("train-out-is-file", ["train", "--data", "d", "--out", "f"], all_of(folder("d"), text("f", "x")), 2,
         r"--out f: is a file, not a folder"),
    # --- a write that fails half-way (disk full): one line, exit 1, nothing left behind
    Case("play-save-disk-full", ["play", "t.npz", *A, "--save", "full/x.npz"], all_of(traj(), full_disk()), 1,
         r"full/x\.npz: cannot write \(No space left on device\); nothing was written"),
    Case("play-video-disk-full", ["play", "t.npz", *A, "--video", "full/v.mp4"], all_of(traj(), full_disk(), renderer),
         1, r"full/v\.mp4: cannot write \(No space left on device\); nothing was written"),
    # --- option values
    Case("fps-inf", ["speak", "Hi", "--fps", "inf"], None, 2,
         r"argument --fps: inf is out of range; expected 1\.\.1000 Hz"),
    Case("fps-1e7", ["play", "t.npz", "--fps", "1e7"], None, 2, r"argument --fps: 1e7 is out of range"),
    Case("stop-within-0", ["serve", "--stop-within", "0"], None, 2, r"argument --stop-within: 0 is out of range"),
    Case("fps-nan", ["play", "t.npz", "--fps", "nan"], None, 2, r"argument --fps: nan is out of range"),
    Case("fps-word", ["speak", "Hi", "--fps", "fast"], None, 2, r"argument --fps: 'fast' is not a number"),
    # a negative seed made every say over the socket fail with a traceback on the server and no reply
    Case("voice-with-audio", ["speak", "--audio", "a.wav", "--wpm", "120"], None, 2,
         r"--voice and --wpm are for TEXT spoken by eSpeak NG; --audio is already spoken"),
    Case("wpm-out-of-range", ["speak", "Hi", "--wpm", "5"], None, 2, r"argument --wpm: 5 is out of range"),
    Case("eval-transcript-alone", ["eval", "--pred", "p.npz", "--transcript", "t.txt"], None, 2,
         r"--transcript goes with --audio"),
    Case("serve-seed-negative", ["serve", "--seed", "-1"], None, 2, r"argument --seed: -1 is out of range"),
    # --checkpoint with the default generator was a traceback in serve; with it, speak ignored --style silently
    Case("serve-checkpoint-rhythm", ["serve", "--checkpoint", "x.pt"], None, 2, r"--checkpoint is for learned gen"),
    Case("speak-checkpoint-style", ["speak", "Hi", "--generator", "gesticulator", "--checkpoint", "x.pt", "--style",
         "lively"], None, 2, r"--amount, --style, --gestures and --semantic are options of the 'rhythm' generator"),
    Case("generate-checkpoint", ["generate", "--text", "Hi", "--out", "g.bvh", "--generator", "gesticulator",
         "--checkpoint", "nothere.pt"], None, 2, r"nothere\.pt: checkpoint not found", needs=("torch",)),
    Case("seed-negative", ["speak", "Hi", "--seed", "-1"], None, 2,
         r"argument --seed: -1 is out of range; expected 0\.\.4294967295"),
    Case("seed-2-32", ["generate", "--text", "Hi", "--out", "m.bvh", "--seed", str(2**32)], None, 2,
         r"argument --seed"),
    Case("train-seed-negative", ["train", "--data", "d", "--out", "o", "--seed", "-5"], None, 2, r"argument --seed"),
    Case("baud-zero", ["speak", "Hi", "--baud", "0"], None, 2, r"argument --baud: 0 is out of range"),
    Case("shifts-one", ["eval", "--pred", "t.npz", "--shifts", "1"], None, 2, r"argument --shifts: 1 is out of range"),
    Case("render-size-huge", ["robots", "show", "--size", "100000x100000"], None, 2, r"argument --size: .*16\.\.4096"),
    Case("render-size-odd", ["robots", "show", "--size", "641x480"], None, 2, r"argument --size: 641x480: .*even"),
    Case("epochs-zero", ["train", "--data", "d", "--out", "o", "--epochs", "0"], None, 2, r"argument --epochs"),
    Case("lr-nan", ["train", "--data", "d", "--out", "o", "--lr", "nan"], None, 2,
         r"argument --lr: nan is out of range"),
    Case("val-fraction-one", ["train", "--data", "d", "--out", "o", "--val-fraction", "1"], None, 2,
         r"argument --val-fraction"),
    Case("unknown-option", ["speak", "Hi", "--colour", "red"], None, 2, r"unrecognized arguments: --colour red"),
    # --- trajectory files
    Case("traj-pickled-object", ["play", "t.npz", *A], traj(q_rad=np.array([{"x": 1}], dtype=object)), 2,
         r"t\.npz: array 'q_rad' holds pickled Python objects"),
    Case("traj-string-array", ["play", "t.npz", *A], traj(q_rad=np.array([["a"] * 11] * 10)), 2,
         r"t\.npz: q_rad holds <U1 values, not numbers"),
    Case("traj-nan-time-stamps", ["play", "t.npz", *A], traj(t_s=np.full(10, np.nan)), 2, r"t_s holds NaN or inf"),
    Case("traj-nan-command", ["eval", "--pred", "t.npz"], traj(q_rad=np.full((10, 11), np.nan)), 2,
         r"q_rad contains NaN or infinite values"),
    Case("traj-nan-command-play", ["play", "t.npz", *A], traj(q_rad=np.full((10, 11), np.nan)), 2,
         r"t\.npz: command q_rad\[0\] of joint torso_yaw is nan"),
    Case("traj-huge-last-stamp", ["play", "t.npz", *A], traj(n=2, t_s=np.array([0.0, 1e12])), 2,
         r"sample rate 1e-12 Hz is outside 1\.\.1000 Hz"),
    Case("traj-24h-plus", ["play", "t.npz", *A], traj(n=86_402, t_s=np.arange(86_402.0)), 2,
         r"lasts 86401 s, longer than the 86400 s"),
    Case("traj-not-increasing", ["play", "t.npz", *A], traj(t_s=np.array([0, 0.02, 0.04, 0.04, 0.06, 0.08, 0.1, 0.12,
         0.14, 0.16])), 2, r"time stamps must increase"),
    Case("traj-uneven", ["play", "t.npz", *A], traj(t_s=np.array([0, 0.02, 0.05, 0.06, 0.08, 0.1, 0.12, 0.14, 0.16,
         0.18])), 2, r"evenly spaced"),
    Case("traj-late-start", ["play", "t.npz", *A], traj(t_s=1e9 + np.arange(10) / 50.0), 2,
         r"time stamps must start at 0 s"),
    Case("traj-shape-mismatch", ["eval", "--pred", "t.npz"], traj(silent=np.zeros(3, bool)), 2,
         r"silent has shape \(3,\), expected \(10,\)"),
    Case("traj-limits-shape", ["play", "t.npz", *A], traj(q_min_rad=np.zeros(3)), 2, r"q_min_rad has shape \(3,\)"),
    Case("npz-crafted-header", ["play", "t.npz", *A], npz_declaring("t.npz", (10**11,)), 2,
         r"array 'q_rad' declares 800000000000 bytes but the file holds"),
    Case("npz-decompression-bomb", ["play", "t.npz", *A],
         lambda d: np.savez_compressed(d / "t.npz", q_rad=np.zeros((2_000_000, 1))), 2,
         r"t\.npz: array 'q_rad' expands from \d+ to 16000128 bytes, more than the 100x"),
    Case("npz-not-a-zip", ["play", "t.npz", *A], text("t.npz", "hello"), 2, r"t\.npz: not a readable \.npz"),
    Case("eval-npz-not-a-zip", ["eval", "--pred", "t.npz"], text("t.npz", "hello"), 2, r"not a readable \.npz"),
    # --- motion files
    Case("bvh-frame-time-1e-9", ["play", "m.bvh", *A], bvh(frame_time="1e-9"), 2, r"Frame Time 1e-09 s is outside"),
    Case("bvh-frame-time-huge", ["play", "m.bvh", *A], bvh(frame_time="1e6"), 2, r"Frame Time 1e\+06 s is outside"),
    Case("bvh-frame-time-nan", ["eval", "--pred", "m.bvh"], bvh(frame_time="nan"), 2, r"Frame Time nan s is outside"),
    Case("bvh-frames-times-joints", ["play", "wide.bvh", *A], bvh_many_joints, 2,
         r"601 frames x 100001 joints is more than"),
    Case("bvh-frames-5000-digits", ["play", "m.bvh", *A],
         all_of(bvh(), edit("m.bvh", "Frames: 5", "Frames: " + "1" * 5000)), 2,
         r"m\.bvh: line \d+: 1111111111\.\.\.\(5000 characters\) is not a count"),
    Case("bvh-frames-fraction", ["play", "m.bvh", *A], all_of(bvh(), edit("m.bvh", "Frames: 5", "Frames: 4.5")),
         2, r"m\.bvh: line \d+: 4\.5 is not a count"),
    Case("robot-yaml-5000-digit-id", ["play", "t.npz", "--robot", f"robots/{ROBOT}.yaml"],
         all_of(traj(), robot_copy, edit(f"robots/{ROBOT}.yaml", "{id: 1,", "{id: " + "1" * 5000 + ",")), 3,
         r"humanoid_xl430\.yaml: not valid YAML: a number too long to read \(Exceeds the limit \(4300 digits\)"),
    Case("bvh-too-large", ["play", "big.bvh", *A], sparse("big.bvh", 3 * 1024**3), 2, r"3\.0 GiB is larger than"),
    Case("bvh-lasts-11-days", ["play", "long.bvh", *A], bvh_long, 2, r"long\.bvh: 1000000 frames at 1 fps last"),
    Case("smplx-fps-1e-9", ["play", "s.npz", *A],
         lambda d: np.savez(d / "s.npz", poses=np.zeros((5, 165)), fps=1e-9), 2,
         r"s\.npz: frame rate 1e-09 fps is outside 1\.\.1000"),
    Case("smplx-pickled", ["play", "s.npz", *A],
         lambda d: np.savez(d / "s.npz", poses=np.array([None], dtype=object)), 2, r"holds pickled Python objects"),
    Case("smplx-string-poses", ["play", "s.npz", *A],
         lambda d: np.savez(d / "s.npz", poses=np.full((5, 165), "x"), fps=30.0), 2,
         r"s\.npz: 'poses' holds <U1 values, not numbers; re-export"),
    Case("smplx-string-trans", ["play", "s.npz", *A],
         lambda d: np.savez(d / "s.npz", poses=np.zeros((5, 165)), trans=np.full((5, 3), "0.1"), fps=30.0), 2,
         r"s\.npz: 'trans' holds <U3 values, not numbers"),
    # --- speech inputs
    Case("transcript-deep-json", ["speak", "--audio", "a.wav", "--transcript", "w.json"],
         all_of(wav(), text("w.json", "[" * 100_000 + "]" * 100_000)), 2, r"w\.json: .*nested too deeply|invalid JSON"),
    Case("transcript-huge", ["analyze", "a.wav", "--transcript", "w.txt"], all_of(wav(), sparse("w.txt", 65 * 1024**2)),
         2, r"transcript w\.txt: 65\.0 MiB, larger than the 64 MiB"),
    # an 8 MB text for 2 s of audio ran past 120 s (400 KB: 36 s); refused once its words are counted
    Case("transcript-too-many-words", ["speak", "--audio", "a.wav", "--transcript", "w.txt"],
         all_of(wav(), text("w.txt", "hello robot " * 50_000)), 2,
         r"transcript w\.txt: 100000 words for 1\.00 s of audio, more than the 15 words/s \(\+20\)"),
    Case("transcript-json-too-many-words", ["analyze", "a.wav", "--transcript", "w.json"],
         all_of(wav(), text("w.json", "[" + ",".join(['{"word": "hi", "start": 0.5, "end": 0.5}'] * 40) + "]")), 2,
         r"transcript w\.json: 40 words for 1\.00 s of audio"),
    Case("transcript-5000-digit-number", ["analyze", "a.wav", "--transcript", "w.json"],
         all_of(wav(), text("w.json", '[{"word": "hi", "start": 0, "end": ' + "1" * 5000 + "}]")), 2,
         r"transcript w\.json: invalid JSON \(Exceeds the limit \(4300 digits\)"),
    Case("transcript-fifo", ["analyze", "a.wav", "--transcript", "w.txt"], all_of(wav(), fifo("w.txt")), 2,
         r"transcript w\.txt: not a regular file"),
    Case("generate-transcript-deep-json", ["generate", "--audio", "a.wav", "--transcript", "w.json", "--out", "m.bvh"],
         all_of(wav(), text("w.json", '{"words":' * 50_000 + "[]" + "}" * 50_000)), 2,
         r"w\.json: .*(nested too deeply|invalid JSON)"),
    Case("eval-audio-rate-absurd", ["eval", "--pred", "t.npz", "--audio", "a.wav"], all_of(traj(), wav(sr=1000)), 2,
         r"a\.wav: sample rate 1000 Hz is outside"),
    Case("robot-yaml-deep", ["play", "t.npz", "--robot", "r.yaml"], all_of(traj(), text("r.yaml", "[" * 100_000)),
         3, r"r\.yaml: (YAML nested too deeply|not valid YAML)"),
    Case("lerobot-calibration-deep-json", ["robots", "import-lerobot-calibration", "c.json", "--robot", ROBOT],
         text("c.json", "[" * 100_000 + "]" * 100_000), 2, r"c\.json: JSON nested too deeply"),
    Case("lerobot-calibration-of-so101-for-xl430", ["robots", "import-lerobot-calibration", "c.json", "--robot", ROBOT,
         "--out", "x.yaml"], text("c.json", '{"shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": -1470, '
         '"range_min": 758, "range_max": 3292}}'), 2,
         r"c\.json: motors \['shoulder_pan'\] are not joints of humanoid_xl430"),
    Case("lerobot-calibration-5000-digits", ["robots", "import-lerobot-calibration", "c.json", "--robot", ROBOT],
         text("c.json", '{"torso_yaw": {"id": ' + "1" * 5000 + "}}"), 2,
         r"c\.json: not a LeRobot calibration file \(Exceeds the limit"),
    Case("lerobot-calibration-3GB-sparse", ["robots", "import-lerobot-calibration", "c.json", "--robot", ROBOT],
         sparse("c.json", 3 * 1024**3), 2, r"calibration c\.json: 3072\.0 MiB, larger than the 1 MiB"),
    Case("lerobot-calibration-dev-zero", ["robots", "import-lerobot-calibration", "/dev/zero", "--robot", ROBOT], None,
         2, r"calibration /dev/zero: not a regular file"),
    Case("play-gear-ratio-1e-300", ["play", "t.npz", "--robot", f"robots/{ROBOT}.yaml"],
         all_of(traj(), robot_copy, edit(f"robots/{ROBOT}.yaml", "model: XL430-W250, direction: -1}",
                                 "model: XL430-W250, direction: -1, gear_ratio: 1.0e-300}")), 3,
         r"key bus\.servos\.r_elbow: .*gear_ratio = 1e-300 is outside \[0\.01, 100\]"),
    Case("robot-yaml-dev-zero", ["play", "t.npz", "--robot", "r.yaml"], all_of(traj(), symlink("r.yaml", "/dev/zero")),
         3, r"robot file r\.yaml: not a regular file"),
    Case("gesture-file-too-large", ["speak", "Hi", "--gestures", "g.yaml"], sparse("g.yaml", 5 * 1024**2), 3,
         r"gesture file g\.yaml: 5\.0 MiB, larger than the 4 MiB"),
    Case("audio-rate-absurd", ["analyze", "a.wav"], wav(sr=1000), 2, r"audio a\.wav: sample rate 1000 Hz is outside"),
    # --- checkpoints
    Case("checkpoint-legacy-format", ["speak", "Hi", "--generator", "gesticulator", "--checkpoint", "c.pt"],
         lambda d: _legacy_checkpoint(d / "c.pt"), 2, r"c\.pt: not a readable checkpoint \(not PyTorch's zip format",
         needs=("torch",)),
    Case("checkpoint-declares-160GB", ["speak", "Hi", "--generator", "gesticulator", "--checkpoint", "c.pt"],
         lambda d: _crafted_checkpoint(d / "c.pt", 40_000_000_000), 2,
         r"c\.pt: not a readable checkpoint .*160000000000 bytes", needs=("torch",)),
    Case("checkpoint-config-asks-for-more", ["speak", "Hi", "--generator", "gesticulator", "--checkpoint", "c.pt"],
         lambda d: _config_mismatch_checkpoint(d / "c.pt"), 2,
         r"c\.pt: the stored weights do not match the model config",
         needs=("torch",)),
    Case("checkpoint-too-large", ["speak", "Hi", "--generator", "gesticulator", "--checkpoint", "c.pt"],
         sparse("c.pt", 5 * 1024**3), 2, r"c\.pt: 5\.0 GiB is larger than", needs=("torch",)),
]  # fmt: skip


def _legacy_checkpoint(path: Path) -> None:
    import torch

    torch.save({"format": "robogest-checkpoint", "w": torch.zeros(3)}, path, _use_new_zipfile_serialization=False)


def _crafted_checkpoint(path: Path, numel: int) -> None:
    """A zip-format checkpoint whose one tensor declares ``numel`` float32 values and stores 10."""
    import pickle

    import torch

    torch.save({"format": "robogest-checkpoint", "version": 1, "w": torch.zeros(10)}, path)
    with zipfile.ZipFile(path) as zf:
        records = {n.split("/", 1)[1]: zf.read(n) for n in zf.namelist()}

    class Rebuild:  # stands in for torch's tensor rebuild call so its arguments can be edited
        def __init__(self, *args: object) -> None:
            self.args = args

        def __reduce__(self):
            return (torch._utils._rebuild_tensor_v2, self.args)

    class Reader(pickle.Unpickler):
        def persistent_load(self, pid):
            return ("PID", pid)

        def find_class(self, module, name):
            return Rebuild if name == "_rebuild_tensor_v2" else super().find_class(module, name)

    class Writer(pickle.Pickler):
        def persistent_id(self, obj):
            return obj[1] if isinstance(obj, tuple) and len(obj) == 2 and obj[0] == "PID" else None

    obj = Reader(io.BytesIO(records["data.pkl"])).load()
    storage, *rest = obj["w"].args
    pid = list(storage[1])
    pid[4] = numel
    obj["w"].args = (("PID", tuple(pid)), rest[0], (numel,), (1,), *rest[3:])
    buf = io.BytesIO()
    Writer(buf, protocol=2).dump(obj)
    records["data.pkl"] = buf.getvalue()
    writer = torch._C.PyTorchFileWriter(str(path))
    for name, data in records.items():
        if name not in ("version", ".data/serialization_id", "byteorder", ".format_version", ".storage_alignment"):
            writer.write_record(name, data, len(data))
    writer.write_end_of_file()


def _config_mismatch_checkpoint(path: Path) -> None:
    """A gesticulator checkpoint whose config asks for 100 000-wide layers while its weights are the small ones."""
    from robogest.generators.learned.gesticulator import GesticulatorConfig, GesticulatorNet
    from robogest.learn.checkpoint import make_checkpoint, save_checkpoint

    cfg = GesticulatorConfig(n_acoustic=4, n_text=4, n_pose=6)
    net = GesticulatorNet(cfg)
    big = {**dataclasses.asdict(cfg), "hidden": [100_000, 100_000]}
    save_checkpoint(make_checkpoint("gesticulator", big, {}, {}, net.state_dict()), path)


def _tree(d: Path) -> dict[str, str]:
    """Every entry under ``d``: file content hashes, link targets, folders and special files."""
    out = {}
    for root, dirs, files in os.walk(d):
        for name in dirs + files:
            p = Path(root) / name
            rel = str(p.relative_to(d))
            if p.is_symlink():
                out[rel] = "-> " + os.readlink(p)
            elif p.is_dir():
                out[rel] = "dir"
            elif p.is_file():
                st = p.stat()
                if st.st_blocks * 512 < st.st_size:  # sparse stand-ins for huge files: size is enough
                    out[rel] = f"sparse {st.st_size}"
                else:
                    out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
            else:
                out[rel] = "special"
    return out


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input_is_one_line(case: Case, tmp_path: Path, monkeypatch, capsys) -> None:
    for mod in case.needs:
        pytest.importorskip(mod)
    monkeypatch.chdir(tmp_path)
    try:
        if case.make is not None:
            case.make(tmp_path)
        before = _tree(tmp_path)
        capsys.readouterr()
        try:
            code = main(case.argv)
        except SystemExit as e:  # argparse's usage errors
            code = e.code
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert "Traceback" not in err
        assert len(lines) == 1, err
        assert re.search(case.line, lines[0]), lines[0]
        assert code == case.code, (code, lines[0])
        assert _tree(tmp_path) == before  # inputs unchanged, no partial or temporary file left
    finally:
        for m in tmp_path.iterdir():
            if m.is_dir() and os.path.ismount(m):
                subprocess.run(["umount", "-l", str(m)], check=False)


def test_out_of_memory_is_one_line(monkeypatch, capsys) -> None:
    """A MemoryError that no cap caught still ends in one line and exit code 1, not a traceback."""
    import robogest.cli.speech_cmds as cmds

    def run(args):
        raise MemoryError

    monkeypatch.setattr(cmds, "run_analyze", run)
    assert main(["analyze", "--text", "Hi"]) == 1
    err = capsys.readouterr().err
    assert err.splitlines() == ["robogest: error: out of memory; the input is too large for this machine"]


def test_backend_flags_fail_before_any_work_or_output(tmp_path, capsys):
    """An unknown backend, a missing port or a simulator-only flag on hardware failed only after the speech was
    generated and --save / --export written (a 58 MB export in one case)."""
    save, csv = tmp_path / "t.npz", tmp_path / "t.csv"
    for argv, code, line in (
        (["--backend", "nosuch"], 2, "unknown backend"),
        (["--backend", "dynamixel"], 3, "serial port"),
        (["--backend", "dynamixel", "--port", "/dev/null", "--video", str(tmp_path / "v.mp4")], 2,
         "--video: the simulator's only"),
    ):  # fmt: skip
        assert main(["speak", "Hello there.", "--save", str(save), "--export", str(csv), *argv]) == code
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and line in err[0], err
        assert list(tmp_path.iterdir()) == []


def test_speak_save_twice_replaces_its_own_audio(tmp_path, monkeypatch, capsys):
    """The .wav beside --save is refused only when it is not the audio of an earlier --save to the same name."""
    monkeypatch.chdir(tmp_path)
    for text in ("Hello.", "Hello there, robot."):
        assert main(["speak", text, "--save", "o.npz"]) == 0, capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.npz", "o.wav"]
    assert sf.info(tmp_path / "o.wav").duration > 1.0  # the second sentence's audio


def test_robots_validate_refuses_an_implausible_gear_ratio(tmp_path, monkeypatch, capsys):
    """`gear_ratio: 1.0e-300` passed `robots validate` and the joint never moved (every goal was the zero tick)."""
    monkeypatch.chdir(tmp_path)
    robot_copy(tmp_path)
    edit(f"robots/{ROBOT}.yaml", "model: XL430-W250, direction: -1}",
         "model: XL430-W250, direction: -1, gear_ratio: 1.0e-300}")(tmp_path)  # fmt: skip
    assert main(["robots", "validate", f"robots/{ROBOT}.yaml"]) == 3
    assert "gear_ratio = 1e-300 is outside [0.01, 100]" in capsys.readouterr().out


def test_speak_video_on_a_full_disk_is_one_line_not_a_crash(tmp_path):
    """`speak --video` on a full disk ended in SIGSEGV: after the first failed write dropped the file, the glide to
    rest still rendered frames into PyAV's closed container. Run apart: the old code killed the process."""
    import sys

    mount_tmpfs(tmp_path / "full", "size=64k")
    try:
        fill_up(tmp_path / "full")
        renderer(tmp_path)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
        proc = subprocess.run(
            [sys.executable, "-m", "robogest", "speak", "Hello there, I am a robot.", "--video", "full/v.mp4"],
            capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300,
        )  # fmt: skip
        errors = [ln for ln in proc.stderr.splitlines() if "error" in ln or "Traceback" in ln or "Fatal" in ln]
        assert proc.returncode == 1, proc.stderr
        assert errors == [
            "robogest: error: full/v.mp4: cannot write (No space left on device); nothing was written, free space "
            "or choose another path"
        ]
        assert sorted(p.name for p in (tmp_path / "full").iterdir()) == ["filler"]
    finally:
        subprocess.run(["umount", "-l", str(tmp_path / "full")], check=False)


def test_a_map_file_that_is_not_a_mapping_is_one_line(tmp_path: Path, capsys) -> None:
    """``robots import --map`` with a YAML list: the message names the file, what it holds and what to write."""
    from tests.robots.humanoids import Options, write_urdf

    desc = write_urdf(tmp_path, Options(arm_dof=3))
    m = tmp_path / "map.yaml"
    m.write_text("- head\n- neck_pitch\n")
    assert main(["robots", "import", str(desc), "--out", str(tmp_path / "robots" / "m.yaml"), "--map", str(m)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"robogest: error: --map {m}: a list, not a mapping; write arms/head/hold/forward as in the "
                   "import: section of an imported robot"]  # fmt: skip
    assert not (tmp_path / "robots").exists()
