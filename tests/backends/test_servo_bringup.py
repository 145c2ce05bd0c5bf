"""Bring-up CLI on the simulated bus: servo scan (fast, --json), doctor (--fix), calibrate (scripted), jog."""

from __future__ import annotations

import json
import os
import threading
import time

import numpy as np
import pytest
import yaml

from robogest.cli.main import main
from robogest.robot.config import load_robot_config
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot
from tests.backends.conftest import move_by_hand


@pytest.fixture
def robots(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    return tmp_path


def test_scan_finds_servos_of_two_protocols_with_details_as_json(robots, capsys):
    robot = make_robot(robots, family="feetech", protocol=0.0, n_joints=2, ids=[7, 3], name="ftbot")
    with VirtualBus(robot) as bus:
        t0 = time.monotonic()
        rc = main(["servo", "scan", "--port", bus.port, "--protocol", "dxl2", "--protocol", "sts", "--max-id", "20",
                   "--json"])  # fmt: skip
        elapsed = time.monotonic() - t0
    assert rc == 0
    found = json.loads(capsys.readouterr().out)
    assert [(f["protocol"], f["baud"], f["id"], f["model"]) for f in found] == [
        ("sts", 1_000_000, 3, "STS3215"),
        ("sts", 1_000_000, 7, "STS3215"),
    ]
    assert found[0]["return_delay_us"] == 0 and found[0]["firmware"] == 3
    assert (found[0]["min_position_tick"], found[0]["max_position_tick"]) == (0, 4095)
    print(f"scan of 15 protocol/baud pairs took {elapsed:.1f} s")


def test_scan_reports_nothing_found_in_one_line(robots, capsys):
    robot = make_robot(robots, n_joints=1, name="xbot")
    with VirtualBus(robot) as bus:
        assert main(["servo", "scan", "--port", bus.port, "--protocol", "sts", "--baud", "500000"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"no servo answered on {bus.port} (check power and wiring; try --per-id)"]


def test_doctor_finds_return_delay_and_loose_limits_then_fixes_them(robots, capsys):
    robot = make_robot(robots, n_joints=3, name="docbot")
    with VirtualBus(robot, return_delay_time=None) as bus:  # XL430 as shipped: return delay 250 (500 us)
        args = ["servo", "doctor", "--port", bus.port, "--robot", "docbot"]
        assert main(args) == 1
        out = capsys.readouterr().out
        assert out.count("return delay 500 us") == 3 and "position limits in the servo [0, 4095]" in out
        assert "latency timer" in out.splitlines()[0]
        assert main([*args, "--fix"]) == 0
        assert "fixed servo id 1 (joint j0): return delay 500 us -> 0" in capsys.readouterr().out
        assert main(args) == 0
        assert "0 problem(s)" in capsys.readouterr().out
        lo, hi = bus.servo(2).get("min"), bus.servo(2).get("max")
        assert all(s.get("Return_Delay_Time") == 0 for s in bus.servos)
    assert 0 < lo < 2048 < hi < 4095


def test_doctor_moves_a_servo_found_at_another_baud_to_the_yamls(robots, capsys):
    robot = make_robot(robots, n_joints=2, name="docbot")
    with VirtualBus(robot) as bus:
        with bus._lock:
            s2 = bus.servo(2)
            s2._store(s2.spec.reg("baud"), 1)  # 57600 baud, as an XL430 leaves the factory
        args = ["servo", "doctor", "--port", bus.port, "--robot", "docbot"]
        assert main(args) == 1
        assert "servo id 2 (joint j1): no answer at 1000000 baud; it answers at 57600 baud" in capsys.readouterr().out
        main([*args, "--fix"])
        assert "moved to 1000000 baud" in capsys.readouterr().out
        assert s2.baudrate == 1_000_000


class _Hand:
    """stdin for ``servo calibrate``: at each prompt, move the next joint as a person would, then press Enter."""

    def __init__(self, bus: VirtualBus, moves: list[tuple[int, int]]) -> None:
        self.bus, self.moves = bus, list(moves)

    def readline(self) -> str:
        if not self.moves:
            return ""
        sid, tick = self.moves.pop(0)
        move_by_hand(self.bus, sid, tick)
        time.sleep(0.02)
        return "\n"


def test_calibrate_writes_offsets_directions_and_limits_to_a_copy(robots, capsys, monkeypatch):
    robot = make_robot(robots, n_joints=2, name="calbot")
    original = (robots / "calbot.yaml").read_text()
    with VirtualBus(robot) as bus:
        with bus._lock:  # servo limits the uncalibrated YAML does not fit in: connect alone would refuse
            for r, v in (("min", 1500), ("max", 2600)):
                bus.servo(1)._store(bus.servo(1).spec.reg(r), v)
        # j0: zero at tick 2100, upper end at 1300 (the servo turns the other way), lower end at 2800
        # j1: zero at 2048, upper at 2700, lower at 1500
        moves = [(1, 2100), (1, 1300), (1, 2800), (2, 2048), (2, 2700), (2, 1500)]
        monkeypatch.setattr("sys.stdin", _Hand(bus, moves))
        assert main(["servo", "calibrate", "--robot", "calbot", "--port", bus.port]) == 0
        assert not any(s.torque_on for s in bus.servos)
    assert (robots / "calbot.yaml").read_text() == original
    out = robots / "calbot.calibrated.yaml"
    doc = yaml.safe_load(out.read_text())
    per_rad = 4096 / (2 * np.pi)
    j0, s0 = doc["joints"][0], doc["bus"]["servos"]["j0"]
    assert s0["direction"] == -1 and s0["zero_offset_rad"] == pytest.approx(52 / per_rad, abs=1e-4)
    assert j0["upper_rad"] == pytest.approx(800 / per_rad - 0.05, abs=1e-3)
    assert j0["lower_rad"] == pytest.approx(-700 / per_rad + 0.05, abs=1e-3)
    assert doc["bus"]["servos"]["j1"]["direction"] == 1
    assert doc["joints"][1]["upper_rad"] == pytest.approx(652 / per_rad - 0.05, abs=1e-3)
    calibrated = load_robot_config(out)
    assert calibrated.joint_names == robot.joint_names
    printed = capsys.readouterr().out
    assert "wrote" in printed
    lines = {x.split(":")[0]: x for x in printed.splitlines() if x.startswith("j")}
    assert "WIDER than the original's [" in lines["j0"]  # 1.18 rad measured, 1.0 in the YAML: said, not hidden
    assert "WIDER" not in lines["j1"]


@pytest.mark.parametrize(("lower", "says"), [(3846, "crosses"), (10, "reaches")])
def test_calibrate_refuses_a_travel_across_the_encoders_wrap(robots, capsys, monkeypatch, lower, says):
    """Zero at tick 150, upper end at 550, lower end 400 ticks below zero: the reading wraps 0 -> 4095 (3846).
    Taken as measured, the limits spanned nearly a turn, and a jog within them drove into the mechanical stop."""
    robot = make_robot(robots, family="feetech", protocol=0.0, n_joints=1, name="wrapbot")
    with VirtualBus(robot) as bus:
        monkeypatch.setattr("sys.stdin", _Hand(bus, [(1, 150), (1, 550), (1, lower)]))
        assert main(["servo", "calibrate", "--robot", "wrapbot", "--port", bus.port]) == 2
        assert not any(s.torque_on for s in bus.servos)
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"joint j0: its travel {says} the end of the servo's encoder range (0 or 4095 ticks)" in err
    assert not (robots / "wrapbot.calibrated.yaml").exists()


def test_calibrate_never_writes_over_the_original(robots):
    make_robot(robots, n_joints=1, name="calbot")
    with VirtualBus(load_robot_config(robots / "calbot.yaml")) as bus:
        rc = main(["servo", "calibrate", "--robot", "calbot", "--port", bus.port, "--out", str(robots / "calbot.yaml")])
    assert rc == 2


def test_jog_moves_one_joint_gently_then_rests_with_torque_off(robots, capsys):
    robot = make_robot(robots, n_joints=3, name="jogbot")
    with VirtualBus(robot) as bus:
        assert main(["servo", "jog", "--robot", "jogbot", "--port", bus.port, "j1", "0.6", "--hold", "0.2"]) == 0
        time.sleep(0.05)
        rec = bus.record()
    assert "j1: at +0.6" in capsys.readouterr().out
    k = list(rec["servo_ids"]).index(2)
    goal_j1 = rec["goal_ticks"][:, k]
    target = 2048 + (-1 * 0.6 + 0.02) * 4096 / (2 * np.pi)  # direction -1, zero offset 0.02 rad
    assert np.min(np.abs(goal_j1 - target)) <= 2  # got there
    others = np.delete(rec["goal_ticks"], k, axis=1)
    assert np.ptp(others, axis=0).max() <= 2  # nothing else moved
    assert rec["torque_on"].any() and not rec["torque_on"][-1].any()
    start, reached = int(np.argmax(goal_j1 != goal_j1[0])), int(np.argmax(np.abs(goal_j1 - target) <= 2))
    # gentle: never faster than a quarter of the 4 rad/s limit, so 0.6 rad takes at least 0.6 s (full speed: 0.15 s)
    assert rec["t_s"][reached] - rec["t_s"][start] >= 0.9 * 0.6 / (0.25 * 4.0)


def test_jog_to_a_limit_stops_at_the_loops_margin_inside_it(robots, capsys):
    """The control loop keeps 0.02 rad inside the limits: a jog to the limit itself waited for a pose the loop
    never reaches (120 s) before going back to rest."""
    robot = make_robot(robots, n_joints=3, name="jogbot")
    hi = float(robot.q_max_rad[1])
    with VirtualBus(robot) as bus:
        argv = ["servo", "jog", "--robot", "jogbot", "--port", bus.port, "j1", f"{hi}", "--hold", "0", "--speed", "1"]
        assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"j1: at {hi - 0.02:+.3f} rad (goal {hi:+.3f} rad, kept 0.020 rad inside the limit)" in out


@pytest.mark.parametrize(("argv", "needle"), [(["j1", "1.5"], "outside its limits"), (["nope", "0.1"], "no joint")])
def test_jog_refuses_bad_requests_in_one_line(robots, capsys, argv, needle):
    robot = make_robot(robots, n_joints=3, name="jogbot")
    with VirtualBus(robot) as bus:
        assert main(["servo", "jog", "--robot", "jogbot", "--port", bus.port, *argv]) == 2
        assert not any(s.torque_on for s in bus.servos)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]


def test_feetech_ping_with_late_replies_is_one_line_not_a_traceback(robots, capsys):
    robot = make_robot(robots, family="feetech", protocol=0.0, n_joints=1, name="ftbot")
    with VirtualBus(robot, "delay=0.2") as bus:  # every reply far after the deadline of all 3 attempts
        assert main(["servo", "ping", "--port", bus.port, "--protocol", "sts", "--id", "1"]) == 5
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "servo id 1: reading MODEL_NUMBER" in err[0]
    with VirtualBus(robot) as bus:
        assert main(["servo", "ping", "--port", bus.port, "--protocol", "sts", "--id", "1"]) == 0
    assert "id 1: model 777 (STS3215)" in capsys.readouterr().out


class _Console:
    """stderr that tells a test thread when ``servo calibrate`` asks for the next step."""

    def __init__(self) -> None:
        self.prompts = 0
        self.cond = threading.Condition()

    def write(self, text: str) -> int:
        if "press Enter" in text:
            with self.cond:
                self.prompts += 1
                self.cond.notify_all()
        return len(text)

    def flush(self) -> None:
        pass

    def wait_for(self, n: int) -> None:
        with self.cond:
            assert self.cond.wait_for(lambda: self.prompts >= n, timeout=30)


def test_calibrate_takes_the_furthest_reading_on_the_way_as_the_end(robots, monkeypatch):
    """With a real stdin the joint is sampled while it travels: overshooting an end before pressing Enter
    counts (the limit is the furthest point reached, not where Enter was pressed)."""
    robot = make_robot(robots, n_joints=1, name="calbot")
    r, w = os.pipe()
    console = _Console()
    monkeypatch.setattr("sys.stdin", os.fdopen(r, "r"))
    monkeypatch.setattr("sys.stderr", console)
    with VirtualBus(robot) as bus:

        def settle_at(tick: int) -> None:
            move_by_hand(bus, 1, tick)
            seen = bus.stats["packets_in"]
            t_end = time.monotonic() + 10
            while bus.stats["packets_in"] < seen + 3 and time.monotonic() < t_end:  # sampled since
                time.sleep(0.01)

        def hand() -> None:
            for k, stops in enumerate(([2108], [2948, 2748], [1248, 1448]), start=1):
                console.wait_for(k)
                for tick in stops:
                    settle_at(tick)
                os.write(w, b"\n")

        t = threading.Thread(target=hand, daemon=True)
        t.start()
        assert main(["servo", "calibrate", "--robot", "calbot", "--port", bus.port]) == 0
        t.join(timeout=10)
    os.close(w)
    doc = yaml.safe_load((robots / "calbot.calibrated.yaml").read_text())
    per_rad = 4096 / (2 * np.pi)
    assert doc["joints"][0]["upper_rad"] == pytest.approx(840 / per_rad - 0.05, abs=2e-3)  # 2948, not 2748
    assert doc["joints"][0]["lower_rad"] == pytest.approx(-860 / per_rad + 0.05, abs=2e-3)  # 1248, not 1448


@pytest.mark.parametrize(("lower", "upper", "zero"), [(-3.1, 0.5, -0.1), (-0.5, 3.1, 0.1)])
def test_doctor_fix_does_not_write_limits_outside_the_servos_range(robots, capsys, lower, upper, zero):
    """A zero offset that puts an end below tick 0 or past 4095: the write raised a traceback, or stopped
    half-way with one limit written."""
    make_robot(robots, n_joints=1, name="dbot")
    path = robots / "dbot.yaml"
    doc = yaml.safe_load(path.read_text())
    doc["joints"][0].update(lower_rad=lower, upper_rad=upper)
    doc["bus"]["servos"]["j0"]["zero_offset_rad"] = zero
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with VirtualBus(load_robot_config(path)) as bus:
        before = bus.servo(1).get("min"), bus.servo(1).get("max")
        assert main(["servo", "doctor", "--port", bus.port, "--robot", "dbot", "--fix"]) == 1
        assert (bus.servo(1).get("min"), bus.servo(1).get("max")) == before
    assert "outside the servo's range [0, 4095]" in capsys.readouterr().out


def test_doctor_refuses_to_fix_a_servo_of_another_model_than_the_yamls(robots, capsys):
    real = make_robot(robots, family="dynamixel", protocol=1.0, model="MX-28", n_joints=1, name="mxbot")
    make_robot(robots, family="dynamixel", protocol=1.0, model="AX-12A", n_joints=1, name="axbot")
    with VirtualBus(real) as bus:
        before = bus.servo(1).get("min"), bus.servo(1).get("max")
        assert main(["servo", "doctor", "--port", bus.port, "--robot", "axbot", "--fix"]) == 1
        assert (bus.servo(1).get("min"), bus.servo(1).get("max")) == before
    assert "the bus has a MX-28 (29) where the YAML says AX-12A (12)" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("setup", "flag", "summary"),
    [
        (lambda s: setattr(s.motion, "temp_c", 72.0), "TOO HOT (limit 65 °C)", "1 servo(s) too hot"),
        (lambda s: s._store(s.spec.reg("Min_Voltage_Limit"), 130), "SUPPLY OUTSIDE [13.0, ",
         "1 servo(s) with the supply outside their range"),
    ],
    ids=["hot", "voltage"],
)  # fmt: skip
def test_robots_check_says_which_servo_is_unhealthy_and_why(robots, capsys, setup, flag, summary):
    """It exited 5 for a hot servo while every line said ok, and exit 0 with the supply below a servo's limit."""
    robot = make_robot(robots, n_joints=2, name="chkbot")
    with VirtualBus(robot) as bus:
        with bus._lock:
            setup(bus.servo(1))
            bus.servo(1)._sync_feedback()
        assert main(["robots", "check", "chkbot", "--port", bus.port]) == 5
    lines = capsys.readouterr().out.strip().splitlines()
    assert flag in next(x for x in lines if x.startswith("id   1")) and lines[-1].endswith(summary)


def test_doctor_says_a_locked_servo_refused_its_baud_rate(robots, capsys):
    """An AX with Lock = 1 refuses EEPROM writes: doctor said 'no status packet' at the new rate instead."""
    robot = make_robot(robots, family="dynamixel", protocol=1.0, n_joints=2, name="axbot")
    with VirtualBus(robot) as bus:
        with bus._lock:
            s2 = bus.servo(2)
            s2._store(s2.spec.reg("baud"), 34)  # 57143 baud
            s2._store(s2.spec.reg("lock"), 1)
        assert main(["servo", "doctor", "--port", bus.port, "--robot", "axbot", "--fix"]) == 5
        assert s2.baudrate == 57143
    assert "servo id 2: refused the Baud Rate write (status error 0x40)" in capsys.readouterr().err


def test_calibrate_a_robot_with_a_base_writes_every_value(robots, monkeypatch):
    """A robot file of changes to its base (base: NAME) has no bus section of its own: the copy read it as the whole
    robot (KeyError on bus). The calibrated copy now holds every value, measured ones replaced."""
    make_robot(robots, n_joints=1, name="calbot")
    (robots / "mybot.yaml").write_text("base: calbot\njoints: [{name: j0, max_velocity_rad_s: 2.0}]\n")
    robot = load_robot_config(robots / "mybot.yaml")
    with VirtualBus(robot) as bus:
        monkeypatch.setattr("sys.stdin", _Hand(bus, [(1, 2048), (1, 2600), (1, 1500)]))
        assert main(["servo", "calibrate", "--robot", "mybot", "--port", bus.port, "--margin-rad", "0.0"]) == 0
    copy = load_robot_config(robots / "mybot.calibrated.yaml")
    assert copy.base is None and copy.joints[0].max_velocity_rad_s == 2.0 and copy.model_path == robot.model_path
    assert copy.bus.servos["j0"].direction == 1
    assert copy.joints[0].upper_rad == pytest.approx(552 * 2 * np.pi / 4096, abs=1e-3)
