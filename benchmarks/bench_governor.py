"""Benchmark the health governor on the simulated bus (not a test): the same monologue with and without it,
servos heating time-scaled; prints the final and peak temperatures and what the governor did.

    .venv/bin/python benchmarks/bench_governor.py [--seconds 24] [--rise 400] [--thermal-scale 80]
"""

from __future__ import annotations

import argparse
import tempfile

import robogest.backends.servos.feetech  # noqa: F401 - registers "feetech"
from robogest.backends.base import get_backend_factory
from robogest.backends.player import play
from robogest.virtualbus import ThermalModel, VirtualBus
from robogest.virtualbus.testing import make_robot, monologue


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=24.0, help="monologue length (trajectory seconds)")
    ap.add_argument("--rise", type=float, default=400.0, help="°C above ambient at full load")
    ap.add_argument("--thermal-scale", type=float, default=80.0, help="thermal clock speed-up")
    ap.add_argument("--time-scale", type=float, default=4.0, help="playback speed-up")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        robot = make_robot(d, family="feetech", protocol=0.0, n_joints=2)
        thermal = ThermalModel(rise_c_at_full_load=args.rise, tau_s=120.0, time_scale=args.thermal_scale)
        for governed in (False, True):
            with VirtualBus(robot, thermal=thermal) as bus:
                backend = get_backend_factory("feetech")(
                    robot, port=bus.port, governor=governed, warn_temperature_c=45.0, max_temperature_c=80.0,
                    health_hz=4,
                )  # fmt: skip
                report = play(monologue(robot, args.seconds), backend, time_scale=args.time_scale)
                final = max(s.motion.temp_c for s in bus.servos)
                st = backend.governor_state()
            print(
                f"governor {'on ' if governed else 'off'}: completed {report.completed}, final {final:.1f} °C, "
                f"hottest reading {st['max_temperature_c']:.0f} °C, lowest factor {st['lowest_factor']:.2f}, "
                f"lengthened rests {st['lengthened_rests']:.0f}"
            )


if __name__ == "__main__":
    main()
