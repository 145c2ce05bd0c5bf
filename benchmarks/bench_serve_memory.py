"""Resident memory of ``robogest serve`` before, during and after long streams (issue 36: 218 -> 816 MB over four
300 s streams, not given back).

Starts ``robogest serve`` (sim backend, no idle motion) in its own process, streams ``--streams`` utterances of
``--length-s`` seconds of synthesized speech to it over the WebSocket, one after the other, each fed at the
session's own pace (``--time-scale`` times real time, which the server plays that much faster), and prints the
server's resident memory (VmRSS) once the session is warm, the peak while each stream plays, and after each stream
has ended, side by side with the growth over the start.

    python benchmarks/bench_serve_memory.py --streams 4 --length-s 300 --time-scale 4
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SR = 16000
FRAME = SR // 10  # 100 ms of int16 PCM per binary frame


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _speech_pcm(length_s: float) -> bytes:
    from robogest import synthesize

    sp = synthesize(
        "Thanks for coming in today. I wanted to walk you through the plan, step by step, so that nothing surprises "
        "you later. First we look at the numbers, then at what they mean for each of the teams, and finally at what "
        "we will do differently next quarter. Does that sound good? Great, let us begin."
    )
    a = sp.audio if sp.sr == SR else np.interp(np.arange(0, len(sp.audio), sp.sr / SR), np.arange(len(sp.audio)),
                                                sp.audio)  # fmt: skip
    reps = int(np.ceil(length_s * SR / len(a)))
    a = np.tile(a, reps)[: int(length_s * SR)]
    return np.round(np.clip(a, -1, 1) * 32767).astype("<i2").tobytes()


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--streams", type=int, default=4)
    ap.add_argument("--length-s", type=float, default=300.0, help="seconds of speech per stream")
    ap.add_argument("--time-scale", type=float, default=4.0, help="the session plays this many times real time")
    ap.add_argument("--kill-above-mb", type=float, default=4000.0, help="kill the server if it grows past this")
    ap.add_argument("--server-log", help="write the server's stderr here (default: discarded)")
    ap.add_argument("--trace", action="store_true", help="print the server's memory every 10 s")
    args = ap.parse_args(argv)

    with open(args.server_log or os.devnull, "w") as log_file:
        return _run(args, log_file)


def _run(args: argparse.Namespace, log_file: Any) -> int:
    from websockets.sync.client import connect

    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-m", "robogest", "serve", "--listen", "127.0.0.1:0", "--no-idle", "--time-scale",
           str(args.time_scale), "--log-level", "warning"]  # fmt: skip
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=log_file,
        text=True,
        env=env,
        cwd=ROOT,
    )
    try:
        line = proc.stdout.readline()
        if "ready on" not in line:
            print(f"serve did not start: {line!r}")
            return 1
        url = line.split("ready on ")[1].split()[0]
        pcm = _speech_pcm(args.length_s)
        time.sleep(10.0)  # the session's warm-up runs in the background
        start = rss_mb(proc.pid)
        print(f"serve: {args.streams} streams of {args.length_s:g} s, played at {args.time_scale:g}x real time")
        print(f"{'':>12} {'RSS MB':>8} {'vs start':>9}")
        print(f"{'start':>12} {start:8.0f} {0:+9.0f}")
        rows = []
        with connect(url, open_timeout=60, max_size=None, ping_interval=None) as ws:
            json.loads(ws.recv())
            inbox: queue.Queue = queue.Queue()

            def read() -> None:  # a client that stops reading stalls the server's sends, then its keepalive
                with contextlib.suppress(Exception):
                    for raw in ws:
                        inbox.put(json.loads(raw))

            threading.Thread(target=read, daemon=True).start()
            for k in range(args.streams):
                peak = [0.0]
                stop = threading.Event()

                def sample(peak: list = peak, stop: threading.Event = stop) -> None:
                    n = 0
                    while not stop.wait(0.25):
                        now = rss_mb(proc.pid)
                        peak[0] = max(peak[0], now)
                        n += 1
                        if args.trace and n % 40 == 0:
                            print(f"  {n / 4:5.0f} s: {now:6.0f} MB", flush=True)
                        if peak[0] > args.kill_above_mb:  # a shared machine: never let it reach the OOM killer
                            print(f"  server over {args.kill_above_mb} MB: killed", flush=True)
                            proc.kill()
                            return

                th = threading.Thread(target=sample, daemon=True)
                th.start()
                ws.send(json.dumps({"type": "stream_start", "sample_rate": SR, "format": "int16"}))
                utt = None
                while utt is None:
                    m = inbox.get(timeout=120)
                    if m["type"] == "accepted":
                        utt = m["utterance"]
                    elif m["type"] == "error":
                        raise RuntimeError(m["message"])
                t0 = time.monotonic()
                frame_s = FRAME / SR / args.time_scale
                for i, off in enumerate(range(0, len(pcm), 2 * FRAME)):
                    ws.send(pcm[off : off + 2 * FRAME])
                    delay = t0 + (i + 1) * frame_s - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                ws.send(json.dumps({"type": "stream_end"}))
                while True:
                    m = inbox.get(timeout=args.length_s + 120)
                    if m["type"] == "error":
                        print(f"  stream {k + 1}: error {m['message']}")
                    if m.get("utterance") == utt and m.get("event") in ("done", "interrupted"):
                        break
                stop.set()
                th.join()
                time.sleep(2.0)
                after = rss_mb(proc.pid)
                rows.append((peak[0], after))
                print(f"{f'stream {k + 1} peak':>12} {peak[0]:8.0f} {peak[0] - start:+9.0f}")
                print(f"{f'stream {k + 1} after':>12} {after:8.0f} {after - start:+9.0f}", flush=True)
        for wait_s in (3.0, 30.0):  # after the client left
            time.sleep(wait_s)
            end = rss_mb(proc.pid)
            print(f"{f'end +{wait_s:g} s':>12} {end:8.0f} {end - start:+9.0f}   (goal: within +50 MB of start)")
    finally:
        proc.terminate()
        proc.wait(60)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
