"""Benchmark the servo stack on the simulated bus (not a test): control rate, jitter, bytes per tick,
what the torque read-back costs a paced loop (late ticks and bytes per tick with and without it), and how
often a client that flushes its port right after a write loses the packet on a pty.

    .venv/bin/python benchmarks/bench_bus.py [--family dynamixel|feetech] [--ticks 500] [--rate 100]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import dynamixel_sdk as dxl
import numpy as np

import robogest.backends.servos.dynamixel
import robogest.backends.servos.feetech  # noqa: F401
from robogest.backends.base import get_backend_factory
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot


def protocol_minimum(family: str, n: int) -> int:
    """Bytes of one sync write of positions + one sync read of positions (request + n replies)."""
    if family == "dynamixel":  # P2: header(4) id(1) len(2) inst(1) ... crc(2); 4-byte positions
        write = 10 + 4 + n * (1 + 4)
        read_req = 10 + 4 + n
        read_rep = n * (11 + 4)
    else:  # Feetech: FF FF id len inst ... chk; 2-byte positions
        write = 6 + 2 + n * (1 + 2)
        read_req = 6 + 2 + n
        read_rep = n * (6 + 2)
    return write + read_req + read_rep


def flush_loss(folder: str, n: int = 1000) -> dict[str, float]:
    """Send ``n`` P2 sync writes through the SDK; count how many the bus received, with and without a
    ``reset_output_buffer()`` (tcflush TCOFLUSH) straight after each write."""
    out = {}
    robot = make_robot(folder, n_joints=11)
    for mode in ("plain", "flush_after_write"):
        with VirtualBus(robot) as bus:
            port = dxl.PortHandler(bus.port)
            port.openPort()
            port.setBaudRate(1_000_000)
            ph = dxl.PacketHandler(2.0)
            gsw = dxl.GroupSyncWrite(port, ph, 116, 4)
            for k in range(n):
                gsw.clearParam()
                for sid in range(1, 12):
                    gsw.addParam(sid, list((1000 + k % 2000).to_bytes(4, "little")))
                gsw.txPacket()
                if mode == "flush_after_write":
                    port.ser.reset_output_buffer()
            time.sleep(0.2)
            received = bus.stats["packets_in"]
            last = [bus.servo(i).get("goal") for i in range(1, 12)]
            port.closePort()
        out[mode] = 1.0 - received / n
        out[mode + "_last_goal_ok"] = float(all(v == 1000 + (n - 1) % 2000 for v in last))
    return out


def control_loop(
    folder: str, family: str, ticks: int, rate_hz: float | None, torque_check_s: float = 0.1
) -> dict[str, float]:
    protocol = 2.0 if family == "dynamixel" else 0.0
    robot = make_robot(folder, family=family, protocol=protocol, n_joints=11, limit_rad=1.0)
    with VirtualBus(robot) as bus:
        # a starved bus thread (a loaded machine) must not end the run: losing servos is not what is measured
        be = get_backend_factory(family)(robot, port=bus.port, torque_check_s=torque_check_s, lost_after_s=2.0)
        be.set_control_rate(rate_hz or 100.0)
        be.connect()
        be.set_torque(True)
        b0 = bus.stats["bytes_in"] + bus.stats["bytes_out"]
        starts, work = [], []
        t0 = time.monotonic()
        for k in range(ticks):
            if rate_hz:
                due = t0 + k / rate_hz
                time.sleep(max(0.0, due - time.monotonic()))
            starts.append(time.monotonic())
            be.write_goal(0.3 * np.sin(2 * np.pi * 0.5 * k / 100.0) * np.ones(11))
            be.read_positions()
            work.append(time.monotonic() - starts[-1])
        elapsed = time.monotonic() - starts[0]
        wire = bus.stats["bytes_in"] + bus.stats["bytes_out"] - b0
        be.shutdown()
    p = np.diff(starts) * 1000
    nominal = 1000 / rate_hz if rate_hz else float(np.median(p))
    late = np.asarray(starts) - (starts[0] + np.arange(ticks) / rate_hz) if rate_hz else np.zeros(ticks)
    return {
        "late_ticks": int(np.sum(late > 0.5 / (rate_hz or 1.0))),
        "work_mean_ms": 1000 * float(np.mean(work)),  # time a tick spends writing and reading
        "work_p99_ms": 1000 * float(np.percentile(work, 99)),
        "rate_hz": (ticks - 1) / elapsed,
        "p50_ms": float(np.percentile(p, 50)),
        "p99_ms": float(np.percentile(p, 99)),
        "jitter_ms": float(np.mean(np.abs(p - nominal))),
        "bytes_per_tick": wire / ticks,
        "min_bytes_per_tick": protocol_minimum(family, 11),
    }


def read_back_cost(folder: str, family: str, n: int = 150) -> dict[str, float]:
    """Median time of one read of every servo's present position and of their Torque Enable (11 servos,
    alternating, so both see the same load on the machine), ms."""
    robot = make_robot(folder, family=family, protocol=2.0 if family == "dynamixel" else 0.0, n_joints=11)
    with VirtualBus(robot) as bus:
        be = get_backend_factory(family)(robot, port=bus.port)
        be.connect()
        ids = [int(i) for i in be.ids]
        times: dict[str, list[float]] = {"present": [], "torque": []}
        for _ in range(n):
            for role, spent in times.items():
                t0 = time.perf_counter()
                be._sync_read_group(be.REG[role], ids)
                spent.append(time.perf_counter() - t0)
        be.shutdown()
    return {role: 1000 * float(np.median(spent)) for role, spent in times.items()}


def torque_lost_latency(folder: str, family: str, rate_hz: float, runs: int = 12) -> np.ndarray:
    """Seconds from one servo's torque switched off (at a random tick) to the error that stops the loop (11
    servos, a paced stepped control loop)."""
    from robogest.backends.control import ControlLoop
    from robogest.errors import BackendError

    rng = np.random.default_rng(0)
    robot = make_robot(folder, family=family, protocol=2.0 if family == "dynamixel" else 0.0, n_joints=11)
    found = []
    with VirtualBus(robot) as bus:
        be = get_backend_factory(family)(robot, port=bus.port, health_hz=0, lost_after_s=2.0)
        loop = ControlLoop(be, rate_hz, threaded=False).start()
        for _ in range(runs):
            be.set_torque(True)
            loop.run_for(rng.integers(0, 20) / rate_hz)
            t0 = time.monotonic()
            bus.inject_now("torqueoff", int(rng.choice(be.ids)))
            try:
                loop.run_for(1.0)
            except BackendError:
                found.append(time.monotonic() - t0)
        loop.close()
    return np.array(found)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", choices=("dynamixel", "feetech"), action="append")
    ap.add_argument("--ticks", type=int, default=500)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--flush-packets", type=int, default=1000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        for fam in args.family or ("dynamixel", "feetech"):
            for rate in (None, args.rate):
                r = control_loop(f"{d}/{fam}{rate}", fam, args.ticks, rate)
                label = "free-running" if rate is None else f"paced {rate:g} Hz"
                print(
                    f"{fam:9s} 11 servos {label:14s}: {r['rate_hz']:7.1f} Hz  period p50 {r['p50_ms']:.2f} ms "
                    f"p99 {r['p99_ms']:.2f} ms  jitter {r['jitter_ms']:.2f} ms  "
                    f"{r['bytes_per_tick']:.0f} B/tick (protocol minimum {r['min_bytes_per_tick']})"
                )
        for fam in args.family or ("dynamixel", "feetech"):
            cost = read_back_cost(f"{d}/{fam}cost", fam)
            print(
                f"{fam:9s} 11 servos: one sync read of Torque Enable {cost['torque']:.2f} ms, of Present Position "
                f"{cost['present']:.2f} ms (medians); read back every 0.1 s: +{cost['torque'] / 5:.2f} ms per tick "
                f"at 50 Hz, +{cost['torque'] / 10:.2f} ms at 100 Hz on average"
            )
            for rate in (50.0, 100.0):
                lat = torque_lost_latency(f"{d}/{fam}{rate}lat", fam, rate)
                print(
                    f"{fam:9s} 11 servos paced {rate:g} Hz: torque switched off found after {np.median(lat):.3f} s "
                    f"median, {lat.max():.3f} s max ({len(lat)} of 12 runs found)"
                )
                runs: dict[float, list[dict[str, float]]] = {0.0: [], 0.1: []}
                for k in range(3):  # alternating, so that both see the same load on the machine
                    for c, rs in runs.items():
                        rs.append(control_loop(f"{d}/{fam}{rate}{c}{k}", fam, args.ticks // 2, rate, c))
                off, on = ({key: float(np.median([r[key] for r in rs])) for key in rs[0]} for rs in runs.values())
                print(
                    f"{fam:9s} 11 servos paced {rate:g} Hz, torque read-back off / every 0.1 s: tick work mean "
                    f"{off['work_mean_ms']:.2f} / {on['work_mean_ms']:.2f} ms, p99 {off['work_p99_ms']:.2f} / "
                    f"{on['work_p99_ms']:.2f} ms, late ticks {off['late_ticks']:.0f} / {on['late_ticks']:.0f} of "
                    f"{args.ticks // 2} (medians of 3), {off['bytes_per_tick']:.0f} / {on['bytes_per_tick']:.0f} B/tick"
                )
        loss = flush_loss(f"{d}/flush", args.flush_packets)
        print(
            f"pty packet loss over {args.flush_packets} sync writes: plain {loss['plain']:.1%}, "
            f"flush right after write {loss['flush_after_write']:.1%} "
            f"(last goal intact: {bool(loss['plain_last_goal_ok'])}/{bool(loss['flush_after_write_last_goal_ok'])})"
        )


if __name__ == "__main__":
    main()
