"""CLI: ``robogest virtual-bus`` in a subprocess, then ``servo scan|ping|read|write|check`` against it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import numpy as np

from robogest.cli.main import main
from robogest.virtualbus.testing import make_robot


def test_virtual_bus_cli_then_servo_commands(tmp_path, capsys, monkeypatch):
    make_robot(tmp_path, name="clibot")
    env = {**os.environ, "ROBOGEST_ROBOTS": str(tmp_path)}
    rec = tmp_path / "rec.npz"
    proc = subprocess.Popen(
        [sys.executable, "-m", "robogest.cli.main", "virtual-bus", "--robot", "clibot", "--record", str(rec)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/")
        monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
        assert main(["servo", "scan", "--port", port, "--protocol", "dxl2", "--baud", "1000000"]) == 0
        out = capsys.readouterr().out
        assert out.count("XL430-W250") == 3 and "id   1" in out
        assert main(["servo", "ping", "--port", port, "--id", "2"]) == 0
        assert main(["servo", "write", "--port", port, "--id", "2", "--register", "led", "--value", "1"]) == 0
        assert main(["servo", "read", "--port", port, "--id", "2", "--register", "LED"]) == 0
        assert "LED = 1" in capsys.readouterr().out
        assert main(["servo", "read", "--port", port, "--id", "2", "--register", "nope"]) == 2
        assert main(["servo", "check", "clibot", "--port", port]) == 0
        assert "models match" in capsys.readouterr().out
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)
    assert proc.returncode == 0
    with np.load(rec) as z:
        assert z["goal_ticks"].shape[1] == 3


def test_bad_fault_spec_is_an_input_error(tmp_path, monkeypatch, capsys):
    make_robot(tmp_path, name="clibot")
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    assert main(["virtual-bus", "--robot", "clibot", "--faults", "noreply=7"]) == 2
    assert "noreply=P" in capsys.readouterr().err


def test_scan_all_lists_each_feetech_servo_once(tmp_path, capsys):
    """A Feetech STS servo answers STS, SCS and Dynamixel 1.0 pings (one packet format): `servo scan --all` listed
    each servo three times, twice with an unknown model."""
    from robogest.robot.config import load_robot_config
    from robogest.virtualbus import VirtualBus

    make_robot(tmp_path, family="feetech", protocol=0.0, n_joints=2, name="ftbot")
    with VirtualBus(load_robot_config(tmp_path / "ftbot.yaml")) as bus:
        assert main(["servo", "scan", "--port", bus.port, "--all", "--baud", "1000000", "--max-id", "5"]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if " id " in ln]
    assert len(lines) == 2, lines
    assert all(ln.startswith("sts ") and "STS3215 (777)" in ln for ln in lines), lines
