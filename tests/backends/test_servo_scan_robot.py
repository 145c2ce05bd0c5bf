"""`servo scan --robot`: per joint, the id and model the YAML expects against what answers on the (simulated) bus,
so a humanoid's servos can be wired and numbered with the YAML in hand."""

from __future__ import annotations

import json

import yaml

from robogest.cli.main import main
from robogest.robot.config import load_robot_config
from robogest.virtualbus import VirtualBus
from tests.robots.humanoid_fixture import JOINTS, robot_yaml, write_humanoid


def test_a_bus_wired_as_the_yaml_says_is_all_ok(tmp_path, capsys):
    path = write_humanoid(tmp_path)
    with VirtualBus(load_robot_config(path)) as bus:
        assert main(["servo", "scan", "--robot", str(path), "--port", bus.port, "--max-id", "30"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"minihuman: sts at 1000000 baud on {bus.port}"
    assert len(out) == 2 + len(JOINTS) and all(line.endswith(" ok") for line in out[1:-1])
    assert out[1].split() == ["l_hip_pitch", "id", "1", "expected", "STS3215", "found", "STS3215", "ok"]
    assert out[-1] == f"all {len(JOINTS)} servos answer with the ids and models the YAML expects"


def test_missing_misnumbered_and_wrong_model_servos_are_each_named(tmp_path, capsys):
    path = write_humanoid(tmp_path)
    raw = robot_yaml()
    raw["bus"]["servos"]["l_knee"]["model"] = "STS3250"  # the YAML expects a bigger knee servo than is fitted
    path.write_text(yaml.safe_dump(raw))
    wired = robot_yaml()  # the robot as actually wired: r_ankle's servo absent, the last one numbered 30
    k = next(i for i, j in enumerate(wired["joints"]) if j["name"] == "r_ankle")
    del wired["joints"][k], wired["bus"]["servos"]["r_ankle"]
    wired["bus"]["servos"]["r_wrist_roll"]["id"] = 30
    (tmp_path / "wired.yaml").write_text(yaml.safe_dump(wired))
    with VirtualBus(load_robot_config(tmp_path / "wired.yaml")) as bus:
        rc = main(["servo", "scan", "--robot", str(path), "--port", bus.port, "--max-id", "40", "--json"])
    assert rc == 5
    rows = json.loads(capsys.readouterr().out)
    bad = {(r["joint"], r["id"], r["expected_model"], r["found_model"], r["status"]) for r in rows if not r["ok"]}
    assert bad == {
        ("l_knee", 3, "STS3250", "STS3215", "wrong"),
        ("r_ankle", 8, "STS3215", None, "missing"),
        ("r_wrist_roll", 21, "STS3215", None, "missing"),
        (None, 30, None, "STS3215", "unexpected"),
    }
    assert len(rows) == len(JOINTS) + 1


def test_nothing_answering_says_what_to_check_in_one_line(tmp_path, capsys):
    path = write_humanoid(tmp_path)
    raw = robot_yaml()
    raw["bus"]["baudrate"] = 500_000  # the servos run at 1 Mbaud: none answers at the YAML's rate
    path.write_text(yaml.safe_dump(raw))
    with VirtualBus(load_robot_config(write_humanoid(tmp_path / "hw")), check_baud=True) as bus:
        assert main(["servo", "scan", "--robot", str(path), "--port", bus.port, "--max-id", "25"]) == 5
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"{len(JOINTS)} of {len(JOINTS)} rows differ from {path} (none answered: check power, wiring and "
                   "the baud rate; `robogest servo scan --port` tries all)"]  # fmt: skip


def test_scan_without_port_or_robot_is_one_line_exit_2(capsys, monkeypatch):
    monkeypatch.setattr("robogest.backends.servos.setup.list_ports", lambda: [])  # no port plugged in
    assert main(["servo", "scan"]) == 2
    assert "servo scan needs --port PATH: no USB serial port is plugged in" in capsys.readouterr().err


def test_a_reply_lost_on_a_busy_bus_does_not_read_as_a_missing_servo(tmp_path, capsys):
    """Replies dropped at random (seeded): the broadcast scan alone hears 18 of the 21 servos; every id the YAML
    expects and the scan missed is asked again on its own, so all 21 rows are ok."""
    from robogest.backends.servos.bringup import scan
    from robogest.backends.servos.protocol import ServoProtocol

    path = write_humanoid(tmp_path)
    robot = load_robot_config(path)
    faults = "noreply=0.1,seed=2"
    with VirtualBus(robot, faults) as bus:
        assert len(scan(bus.port, [ServoProtocol.STS], [1_000_000], max_id=25)) == 18
    with VirtualBus(robot, faults) as bus:
        assert main(["servo", "scan", "--robot", str(path), "--port", bus.port, "--max-id", "25"]) == 0
    assert capsys.readouterr().out.count(" ok\n") == len(JOINTS)
