"""Benchmark the servos' own acceleration limit on the simulated bus (not a test): with 5 % of the instructions lost
(goal sync writes among them), how fast each simulated servo accelerates, as a ratio to the robot YAML's
``max_acceleration_rad_s2``, without its own limit (``off``: as before it was set at connect) and with it (``on``),
over trajectories made at 10-60 fps played at 20-200 Hz, Dynamixel X (XL430-W250) and Feetech STS (STS3215).
Also the tracking lag: how far the servo is behind the goal it holds (max, degrees).

    .venv/bin/python benchmarks/bench_servo_profile.py [--seconds 2] [--faults drop=0.05]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

import robogest.backends.servos.dynamixel
import robogest.backends.servos.feetech  # noqa: F401 - registers "feetech"
from robogest.backends.base import get_backend_factory
from robogest.backends.player import play
from robogest.errors import BackendError
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot, monologue, servo_acceleration_ratio

FPS = (10, 20, 30, 60)
RATES_HZ = (20, 50, 100, 200)
CHAINS = (("dynamixel", 2.0), ("feetech", 0.0))


def run(folder: str, family: str, protocol: float, fps: float, rate_hz: float, own_limit: bool, faults: str,
        seconds: float, seed: int) -> tuple[float, float]:  # fmt: skip
    """(largest acceleration / YAML limit over the servos, largest lag behind the held goal in degrees), or NaNs
    when the play did not complete (a servo declared lost on the lossy bus)."""
    robot = make_robot(folder, family=family, protocol=protocol, name=f"{family}bot")
    with VirtualBus(robot, f"{faults},seed={seed}") as bus:
        backend = get_backend_factory(family)(robot, port=bus.port, health_hz=0, lost_after_s=1.0)  # motion, not loss
        if not own_limit:  # as before the servos' acceleration registers were written at connect
            backend.accel_cap_units = lambda: np.zeros(len(backend.ids), dtype=np.int64)
        try:
            report = play(monologue(robot, seconds, fps=fps), backend, rate_hz=rate_hz)
        except BackendError:
            return float("nan"), float("nan")
        time.sleep(0.05)
        rec = bus.record()
    if not report.completed:
        return float("nan"), float("nan")
    on = rec["torque_on"].all(axis=1)
    tpr = 4096 / 360.0  # both models: 4096 ticks per turn, gear ratio 1
    lag_deg = np.abs(rec["goal_ticks"][on] - rec["position_ticks"][on]).max() / tpr
    return float(servo_acceleration_ratio(rec, robot).max()), float(lag_deg)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=2.0, help="trajectory length per cell")
    ap.add_argument("--faults", default="drop=0.05")
    args = ap.parse_args()
    t0 = time.perf_counter()
    worst = {False: 0.0, True: 0.0}
    with tempfile.TemporaryDirectory() as folder:
        print(
            f"servo's own acceleration / YAML limit, {args.faults}, {args.seconds:g} s monologue; off -> on "
            "(max lag behind the held goal, deg)"
        )
        for family, protocol in CHAINS:
            print(f"{family:9s} fps\\Hz " + " ".join(f"{r:>26d}" for r in RATES_HZ))
            for k, fps in enumerate(FPS):
                cells = []
                for j, rate in enumerate(RATES_HZ):
                    seed = 1 + k * len(RATES_HZ) + j
                    off = run(folder, family, protocol, fps, rate, False, args.faults, args.seconds, seed)
                    on = run(folder, family, protocol, fps, rate, True, args.faults, args.seconds, seed)
                    for own, r in ((False, off), (True, on)):
                        worst[own] = max(worst[own], r[0]) if np.isfinite(r[0]) else worst[own]
                    cells.append(f"{off[0]:4.2f} -> {on[0]:4.2f} ({off[1]:4.1f}/{on[1]:4.1f})")
                print(f"{'':9s} {fps:6d} " + " ".join(f"{c:>26s}" for c in cells))
    print(f"worst cell: {worst[False]:.2f}x without the servos' own limit, {worst[True]:.2f}x with it "
          f"({time.perf_counter() - t0:.0f} s)")  # fmt: skip


if __name__ == "__main__":
    main()
