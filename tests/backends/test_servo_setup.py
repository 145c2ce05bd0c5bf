"""`servo find-port` (injected port lister, scripted answers), `servo scan` without --port, and `servo setup`: one
servo connected at a time on the simulated bus, each found at its factory id and baud rate and given the YAML's."""

from __future__ import annotations

import os
import re
import signal

import pytest

from robogest.backends.servos import setup as servo_setup
from robogest.backends.servos.setup import SerialPort
from robogest.cli.main import main
from robogest.virtualbus import VirtualBus
from robogest.virtualbus.testing import make_robot

ADAPTER = SerialPort("/dev/ttyACM0", "USB Single Serial", True)
BUILTIN = SerialPort("/dev/ttyS0", "n/a", False)


class Answers:
    """input() for the CLI: runs ``on_prompt(prompt)`` (a hand plugging cables), records prompts."""

    def __init__(self, on_prompt=None, limit=20):
        self.prompts: list[str] = []
        self.on_prompt, self.limit = on_prompt, limit

    def __call__(self, prompt=""):
        self.prompts.append(prompt)
        if len(self.prompts) > self.limit:
            raise EOFError
        if self.on_prompt is not None:
            self.on_prompt(prompt)
        return ""


@pytest.fixture
def robots(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    return tmp_path


# --- find-port ---------------------------------------------------------------------------------------------
def test_find_port_reports_the_port_that_vanished(monkeypatch, capsys):
    listings = iter([[BUILTIN, ADAPTER], [BUILTIN]])
    monkeypatch.setattr(servo_setup, "list_ports", lambda: next(listings))
    answers = Answers()
    monkeypatch.setattr("builtins.input", answers)
    monkeypatch.setattr(servo_setup.time, "sleep", lambda s: None)
    assert main(["servo", "find-port"]) == 0
    out = capsys.readouterr().out
    assert "/dev/ttyACM0  USB Single Serial" in out and "/dev/ttyS0  n/a  (not USB)" in out
    assert "the robot's port is /dev/ttyACM0; plug the cable back in" in out
    assert len(answers.prompts) == 1 and answers.prompts[0].startswith("Unplug the USB cable")


@pytest.mark.parametrize(
    ("listings", "says"),
    [
        ([[ADAPTER], [ADAPTER]], r"no port vanished: was the adapter's USB cable unplugged"),
        ([[BUILTIN, ADAPTER], []], r"2 ports vanished \(/dev/ttyS0, /dev/ttyACM0\): unplug only the robot's adapter"),
        ([[]], r"no serial port found; plug in the servo adapter's USB cable"),
    ],
    ids=["none-vanished", "two-vanished", "no-port"],
)
def test_find_port_says_why_not_in_one_line(monkeypatch, capsys, listings, says):
    it = iter(listings)
    monkeypatch.setattr(servo_setup, "list_ports", lambda: next(it))
    monkeypatch.setattr("builtins.input", Answers())
    monkeypatch.setattr(servo_setup.time, "sleep", lambda s: None)
    assert main(["servo", "find-port"]) == 5
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert re.search(says, err[0])


def test_find_port_list_and_a_closed_stdin(monkeypatch, capsys):
    monkeypatch.setattr(servo_setup, "list_ports", lambda: [BUILTIN, ADAPTER])
    assert main(["servo", "find-port", "--list"]) == 0
    assert capsys.readouterr().out.splitlines() == ["/dev/ttyS0  n/a  (not USB)", "/dev/ttyACM0  USB Single Serial"]
    monkeypatch.setattr("builtins.input", Answers(limit=0))
    assert main(["servo", "find-port"]) == 2
    assert "this command asks questions: run it in a terminal (stdin was closed)" in capsys.readouterr().err


def test_the_real_lister_runs():
    assert all(isinstance(p, SerialPort) for p in servo_setup.list_ports())


# --- scan without --port -----------------------------------------------------------------------------------
def test_scan_without_port_uses_the_one_usb_port(robots, monkeypatch, capsys):
    robot = make_robot(robots, family="feetech", protocol=0.0, n_joints=2, name="ftbot")
    with VirtualBus(robot) as bus:
        monkeypatch.setattr(servo_setup, "list_ports", lambda: [BUILTIN, SerialPort(bus.port, "USB adapter", True)])
        assert main(["servo", "scan", "--protocol", "sts", "--baud", "1000000", "--max-id", "5"]) == 0
        out, err = capsys.readouterr()
        assert out.count("STS3215") == 2 and f"using {bus.port}, the one USB serial port plugged in" in err
        assert main(["servo", "scan", "--robot", "ftbot", "--max-id", "5"]) == 0
        assert "all 2 servos answer" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("ports", "says"),
    [([BUILTIN], "no USB serial port is plugged in"), ([ADAPTER, SerialPort("/dev/ttyUSB0", "FTDI", True)],
                                                       "2 USB serial ports are plugged in")],
)  # fmt: skip
def test_scan_without_port_lists_them_and_asks_for_port(monkeypatch, capsys, ports, says):
    monkeypatch.setattr(servo_setup, "list_ports", lambda: ports)
    assert main(["servo", "scan"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"robogest: error: servo scan needs --port PATH: {says} (serial ports: {ports[0].line()}")
    assert err.endswith("`robogest servo find-port` tells which is the robot's") and len(err.splitlines()) == 1


# --- setup -------------------------------------------------------------------------------------------------
FACTORY_ID, FACTORY_BAUD = 1, {"STS3215": 1_000_000, "XL430-W250": 57_600}  # out of the box


def _factory_bus(bus):
    """Every servo back to the factory id and baud rate, and unplugged."""
    with bus._lock:
        for s in bus.servos:
            s._store(s.spec.reg("id"), FACTORY_ID)
            rate = FACTORY_BAUD[s.spec.name]
            s._store(s.spec.reg("baud"), next(v for v, b in s.spec.baud_table.items() if b == rate))
            s.flash = bytes(s.mem[: s.spec.eeprom_end])
            s.vanished = True


def _plug(bus, robot, joints):
    """Only the servos of ``joints`` connected (the bus's servos are in the YAML's id order)."""
    order = sorted(robot.joint_names, key=lambda j: robot.bus.servos[j].id)
    with bus._lock:
        for s, j in zip(bus.servos, order, strict=True):
            s.vanished = j not in joints


def _hand(bus, robot, plug=None):
    """Plugs in the servo each prompt names (or what ``plug(joint, prompt)`` returns)."""
    state = {"joint": None}

    def on_prompt(prompt):
        if "Connect ONLY the servo of joint " in prompt:
            state["joint"] = prompt.split("joint ")[1].split(" ")[0]
        joints = plug(state["joint"], prompt) if plug else [state["joint"]]
        _plug(bus, robot, joints)

    return Answers(on_prompt)


def _setup_robot(robots, family="feetech"):
    protocol, baud = (0.0, 500_000) if family == "feetech" else (2.0, 1_000_000)
    return make_robot(robots, family=family, protocol=protocol, n_joints=3, ids=[5, 6, 7], baudrate=baud,
                      name="newbot")  # fmt: skip


@pytest.mark.parametrize(("family", "factory", "baud"), [("feetech", 1_000_000, 500_000),
                                                          ("dynamixel", 57_600, 1_000_000)])  # fmt: skip
def test_setup_gives_each_servo_its_id_and_baud_one_at_a_time(robots, monkeypatch, capsys, family, factory, baud):
    robot = _setup_robot(robots, family)
    with VirtualBus(robot) as bus:
        _factory_bus(bus)
        answers = _hand(bus, robot)
        monkeypatch.setattr("builtins.input", answers)
        assert main(["servo", "setup", "--robot", "newbot", "--port", bus.port, "--max-id", "10"]) == 0
        out = capsys.readouterr().out
        for j, sid in (("j0", 5), ("j1", 6), ("j2", 7)):
            assert f"{j}: id 1 -> {sid}, {factory} -> {baud} baud; checked, torque off" in out
        asked = [p.split(" (")[0] for p in answers.prompts]
        assert asked == [f"Connect ONLY the servo of joint j{k}" for k in range(3)]
        _plug(bus, robot, robot.joint_names)
        with bus._lock:
            for s in bus.servos:
                s.power_cycle()  # the settings are in EEPROM, not only in RAM
        assert sorted(s.id for s in bus.servos) == [5, 6, 7] and {s.baudrate for s in bus.servos} == {baud}
        assert not any(s.torque_on for s in bus.servos)
        assert main(["servo", "scan", "--robot", "newbot", "--port", bus.port, "--max-id", "10"]) == 0


def test_setup_asks_again_while_two_servos_or_another_model_answer(robots, monkeypatch, capsys):
    robot = _setup_robot(robots)
    with VirtualBus(robot) as bus:
        _factory_bus(bus)
        with bus._lock:
            bus.servos[2]._store(bus.servos[2].spec.reg("id"), 9)  # a used servo, id 9: two answer, each its own id
        calls = []

        def plug(joint, prompt):
            calls.append(prompt)
            return ["j0", "j2"] if len(calls) == 1 else [joint]  # first both plugged in, then only j0's

        monkeypatch.setattr("builtins.input", _hand(bus, robot, plug))
        assert main(["servo", "setup", "--robot", "newbot", "--port", bus.port, "--max-id", "10", "--joint", "j0"]) == 0
    out = capsys.readouterr().out
    assert "2 servos answer (id 1 at 1000000 baud, id 9 at 1000000 baud); connect only joint j0's servo" in out
    assert calls[1].startswith("Press Enter to look again") and "j0: id 1 -> 5" in out and "j1:" not in out


def test_setup_writes_nothing_to_a_servo_of_another_model(robots, monkeypatch, capsys):
    import yaml

    robot = _setup_robot(robots)
    doc = yaml.safe_load((robots / "newbot.yaml").read_text())
    doc["bus"]["servos"]["j0"]["model"] = "STS3250"
    (robots / "newbot.yaml").write_text(yaml.safe_dump(doc))
    with VirtualBus(robot) as bus:
        _factory_bus(bus)
        monkeypatch.setattr("builtins.input", Answers(lambda p: _plug(bus, robot, ["j0"]), limit=2))
        assert main(["servo", "setup", "--robot", "newbot", "--port", bus.port, "--max-id", "10"]) == 2
        assert [s.id for s in bus.servos] == [1, 1, 1] and {s.baudrate for s in bus.servos} == {1_000_000}
    out = capsys.readouterr().out
    assert "the servo connected is a STS3215 (777) where joint j0's YAML entry says STS3250" in out


def test_ctrl_c_during_a_write_finishes_that_servo_and_says_so(robots, monkeypatch, capsys):
    """Ctrl-C between the id and the baud-rate write left a servo at the new id and the old baud rate; it now waits
    until the servo has both, checked, then stops (exit 130) naming the joints not set up."""
    from robogest.backends.servos.transport import Transport

    robot = _setup_robot(robots)
    write = Transport.write

    def write_then_ctrl_c(self, sid, reg, value, attempts=3):
        if reg.name == "BAUD_RATE":
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C after the id was written, before the baud rate
        return write(self, sid, reg, value, attempts)

    monkeypatch.setattr(Transport, "write", write_then_ctrl_c)
    with VirtualBus(robot) as bus:
        _factory_bus(bus)
        monkeypatch.setattr("builtins.input", _hand(bus, robot))
        assert main(["servo", "setup", "--robot", "newbot", "--port", bus.port, "--max-id", "10"]) == 130
        s = bus.servos[0]
        assert (s.id, s.baudrate, s.torque_on) == (5, 500_000, False)
        assert [x.id for x in bus.servos[1:]] == [1, 1]
    err = capsys.readouterr().err.strip()
    assert err == ("robogest: stopped after joint j0's servo got its new settings (id 5 at 500000 baud, checked); "
                   "not set up: j1, j2")  # fmt: skip


def test_ctrl_c_at_a_question_leaves_that_servo_unchanged(robots, monkeypatch, capsys):
    robot = _setup_robot(robots)
    with VirtualBus(robot) as bus:
        _factory_bus(bus)
        hand = _hand(bus, robot)

        def answer(prompt=""):
            if "joint j1" in prompt:
                raise KeyboardInterrupt
            return hand(prompt)

        monkeypatch.setattr("builtins.input", answer)
        assert main(["servo", "setup", "--robot", "newbot", "--port", bus.port, "--max-id", "10"]) == 130
    err = capsys.readouterr().err.strip()
    assert err == "robogest: stopped before writing joint j1's servo: it is unchanged; not set up: j1, j2"


def test_setup_refuses_bad_requests_before_any_question(robots, monkeypatch, capsys):
    _setup_robot(robots)
    monkeypatch.setattr("builtins.input", Answers(limit=0))
    assert main(["servo", "setup", "--robot", "newbot", "--port", "/dev/null", "--joint", "elbow"]) == 2
    assert "robot newbot has no joints ['elbow']; its joints: j0, j1, j2" in capsys.readouterr().err
    make_robot(robots, family="feetech", protocol=0.0, n_joints=1, baudrate=9600, name="slowbot")
    assert main(["servo", "setup", "--robot", "slowbot", "--port", "/dev/null"]) == 2
    assert "sts servos cannot be set to 9600 baud" in capsys.readouterr().err


def test_a_failed_write_says_which_settings_the_servo_answers_with(robots, monkeypatch, capsys):
    from robogest.backends.servos.transport import Transport
    from robogest.errors import BackendError

    robot = _setup_robot(robots)
    write = Transport.write

    def baud_write_lost(self, sid, reg, value, attempts=3):
        if reg.name == "BAUD_RATE":
            raise BackendError(f"servo id {sid}: writing BAUD_RATE: [TxRxResult] There is no status packet!")
        return write(self, sid, reg, value, attempts)

    monkeypatch.setattr(Transport, "write", baud_write_lost)
    with VirtualBus(robot) as bus:
        _factory_bus(bus)
        monkeypatch.setattr("builtins.input", _hand(bus, robot))
        assert main(["servo", "setup", "--robot", "newbot", "--port", bus.port, "--max-id", "10"]) == 5
    err = capsys.readouterr().err.strip()
    assert err.startswith("robogest: error: joint j0's servo: servo id 5: reading ID: ")
    assert err.endswith("; it answers with the new id but its old baud rate (id 5 at 1000000 baud); set up: none")
