"""Video benchmark (not a test): ``robogest speak --video`` of the demo sentence (the Makefile's DEMO_TEXT) at the
default size and at the old 1280x720, wall and CPU time over the speech's duration (target on the 2-core machine's
software renderer: wall <= 3x); then where a render's time goes (first seconds of the demo, in process, per stage).
Run: ``MUJOCO_GL=egl .venv/bin/python benchmarks/bench_video.py`` (``--quick``: the CLI rows only).

Wall time depends on the machine's load: the CPU columns (user + system of the process and its threads) say what
the work costs; on an idle machine wall is at most CPU (llvmpipe and the encoder use both cores) and at least the
simulation thread's own CPU time ("its thread": what llvmpipe's and the encoder's threads cannot take over).
"""

from __future__ import annotations

import cProfile
import os
import pstats
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: Seconds of the demo rendered in process for the per-stage split (the CLI rows render all of it).
STAGE_SECONDS = 4.0


def demo_text() -> str:
    for line in (REPO / "Makefile").read_text().splitlines():
        if line.startswith("DEMO_TEXT ?="):
            return line.split("?=", 1)[1].strip()
    raise SystemExit("Makefile has no DEMO_TEXT")


def cli_row(label: str, extra: list[str], out: Path) -> None:
    """One ``speak --video`` run in its own process: wall and CPU over the speech's duration."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "PYTHONPATH": str(REPO)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "robogest", "speak", demo_text(), "--video", str(out), *extra],
        capture_output=True, text=True, env=env,
    )  # fmt: skip
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        raise SystemExit(f"speak --video failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    speech_s = float(re.search(r"speech: ([\d.]+) s", proc.stdout).group(1))
    size = re.search(r"video: rendering (\d+x\d+)", proc.stdout).group(1)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    print(f"speak --video {label:<22} {size:>9}  speech {speech_s:5.2f} s  wall {wall:6.1f} s = {wall / speech_s:4.2f}x"
          f"  cpu {cpu:6.1f} s = {cpu / speech_s:4.2f}x")  # fmt: skip


def stage_rows(traj, robot, audio, sr: int, label: str, size: tuple[int, int], cheap: bool | None) -> None:
    """Render the first STAGE_SECONDS in process: per-stage wall times (cProfile of the simulation's thread, the
    encoder thread's own clock), per frame. ``cheap=None``: the options the renderer calls for."""
    from robogest.backends import render
    from robogest.backends.mujoco_sim import simulate

    real = render.video_settings
    if cheap is not None:  # the scene's own options (multisampling, its shadow map) as before, for comparison
        render.video_settings = lambda w, h: render.VideoSettings(w, h, cheap, real(w, h).renderer)
    prof = cProfile.Profile()
    c0, m0, t0 = time.process_time(), time.thread_time(), time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        prof.enable()
        rep = simulate(traj, robot, video_path=Path(tmp) / "v.mp4", audio=audio, audio_sr=sr, width=size[0],
                       height=size[1])  # fmt: skip
        prof.disable()
    wall, cpu, main = time.perf_counter() - t0, time.process_time() - c0, time.thread_time() - m0
    render.video_settings = real
    st = pstats.Stats(prof).stats  # {(file, line, name): (cc, nc, tt, ct, callers)}

    def total(name: str) -> float:
        return sum(v[2] for k, v in st.items() if k[2].rstrip(">").endswith("." + name))

    v, n = rep.extra["video"], rep.n_video_frames
    stages = {
        "physics": total("mj_step"), "scene": v.scene_s, "mjr_render": total("mjr_render"),
        "readPixels": total("mjr_readPixels"), "encode (thread)": v.encode_s, "wait for encoder": v.wait_s,
    }  # fmt: skip
    parts = "  ".join(f"{k} {1000 * s / n:5.1f}" for k, s in stages.items())
    dur = rep.t_s[-1] if len(rep.t_s) else STAGE_SECONDS
    print(f"{label:<36} {n:3d} frames  wall {wall / dur:4.2f}x  cpu {cpu / dur:4.2f}x (its thread {main / dur:4.2f}x)"
          f"  ms/frame: {parts}")  # fmt: skip


def main(argv: list[str]) -> int:
    from robogest.backends.render import gl_renderer_name

    print(f"renderer: {gl_renderer_name()}; {os.cpu_count()} cores; load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        cli_row("(default size)", [], Path(tmp) / "a.mp4")
        cli_row("--video-size 1280x720", ["--video-size", "1280x720"], Path(tmp) / "b.mp4")
    if "--quick" in argv:
        return 0
    import numpy as np

    from robogest.pipeline import speak
    from robogest.robot import find_robot
    from robogest.speech import synthesize
    from robogest.trajectory import Trajectory

    robot = find_robot("humanoid_xl430")
    speech = synthesize(demo_text())
    full = speak(speech, robot, "rhythm", seed=0).trajectory
    keep = full.t_s <= STAGE_SECONDS
    traj = Trajectory(
        t_s=full.t_s[keep], q_rad=full.q_rad[keep], joint_names=full.joint_names, q_min_rad=full.q_min_rad,
        q_max_rad=full.q_max_rad, v_max_rad_s=full.v_max_rad_s, a_max_rad_s2=full.a_max_rad_s2,
        rest_q_rad=full.rest_q_rad, silent=full.silent[keep], robot=full.robot,
    )  # fmt: skip
    audio = np.asarray(speech.audio)[: int(STAGE_SECONDS * speech.sr)]
    print(f"per stage, first {STAGE_SECONDS:g} s of the demo (x = over the simulated duration):")
    stage_rows(traj, robot, audio, speech.sr, "640x360, renderer's options", (640, 360), None)
    stage_rows(traj, robot, audio, speech.sr, "1280x720, renderer's options", (1280, 720), None)
    stage_rows(traj, robot, audio, speech.sr, "1280x720, scene's options (before)", (1280, 720), False)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
