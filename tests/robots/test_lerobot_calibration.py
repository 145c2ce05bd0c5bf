"""`robogest robots import-lerobot-calibration`: a calibration file in LeRobot's format becomes servo zero offsets,
directions and limits in a copy of the robot YAML, with numbers checked against hand computation."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from robogest.backends import get_backend_factory
from robogest.cli.main import main
from robogest.errors import ConfigError, InputError
from robogest.robot.config import load_robot_config
from robogest.robot.registry import find_robot
from robogest.tools.lerobot_calibration import import_lerobot_calibration, read_calibration
from robogest.tools.validate import validate

TICK = 2 * math.pi / 4096  # STS3215: rad per tick
#: As `lerobot-calibrate` writes it for an SO-101 follower (elbow_flex with drive_mode 1 to test the sign).
CALIB = {
    "shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": -1470, "range_min": 758, "range_max": 3292},
    "shoulder_lift": {"id": 2, "drive_mode": 0, "homing_offset": 153, "range_min": 1000, "range_max": 3000},
    "elbow_flex": {"id": 3, "drive_mode": 1, "homing_offset": -1183, "range_min": 900, "range_max": 3100},
    "wrist_flex": {"id": 4, "drive_mode": 0, "homing_offset": 1220, "range_min": 1500, "range_max": 2600},
    "wrist_roll": {"id": 5, "drive_mode": 0, "homing_offset": 240, "range_min": 0, "range_max": 4095},
    "gripper": {"id": 6, "drive_mode": 0, "homing_offset": 1417, "range_min": 2000, "range_max": 3400},
}


@pytest.fixture
def so101_copy(tmp_path):
    """The shipped SO-101 YAML copied into tmp_path (so the test never writes beside the shipped one)."""
    src = find_robot("so101_sts3215")
    text = src.path.read_text().replace("model: ../sim/so101/scene.xml", f"model: {src.model_path}")
    (tmp_path / "so101.yaml").write_text(text)
    return load_robot_config(tmp_path / "so101.yaml")


def _write(tmp_path, calib, name="follower.json"):
    (tmp_path / name).write_text(json.dumps(calib, indent=4))
    return tmp_path / name


def test_numbers_by_hand(tmp_path, so101_copy):
    original = so101_copy.path.read_bytes()
    res = import_lerobot_calibration(_write(tmp_path, CALIB), so101_copy)
    assert res.path == tmp_path / "so101_calibrated.yaml" and so101_copy.path.read_bytes() == original
    r = load_robot_config(res.path)
    assert r.name == "so101_calibrated"
    s = r.bus.servos
    # zero offset = (middle of the recorded range - 2048) ticks
    assert s["shoulder_pan"].zero_offset_rad == pytest.approx((2025 - 2048) * TICK, abs=1e-6)  # -0.035282
    assert s["shoulder_lift"].zero_offset_rad == pytest.approx(-48 * TICK, abs=1e-6)  # -0.073631
    assert s["wrist_roll"].zero_offset_rad == pytest.approx(-0.5 * TICK, abs=1e-6)
    assert s["gripper"].zero_offset_rad == pytest.approx(652 * TICK, abs=1e-6)  # 1.000155
    assert [s[n].direction for n in r.joint_names] == [1, 1, -1, 1, 1, 1]  # drive_mode 1 on elbow_flex
    lim = {j.name: (j.lower_rad, j.upper_rad) for j in r.joints}
    assert lim["shoulder_lift"] == pytest.approx((-1000 * TICK, 1000 * TICK), abs=1e-6)  # +-1.533981: narrowed
    assert lim["wrist_flex"] == pytest.approx((-550 * TICK, 550 * TICK), abs=1e-6)  # +-0.843689
    assert lim["shoulder_pan"] == (-1.9, 1.9)  # recorded +-1267 ticks = +-1.94 rad: the model's +-1.9 stays
    assert lim["elbow_flex"] == (-1.65, 1.65)
    assert any("shoulder_lift" in c and "narrowed" in c for c in res.changes)
    assert [str(p) for p in validate(res.path)] == []


def test_servo_ticks_match_lerobot_degrees(tmp_path, so101_copy):
    """The calibrated backend sends the tick LeRobot would for the same angle: mid + deg * 4095 / 360."""
    r = load_robot_config(import_lerobot_calibration(_write(tmp_path, CALIB), so101_copy).path)
    backend = get_backend_factory("feetech")(r, port="/dev/null")  # no port is opened by the constructor
    q = np.array([0.5, -0.3, 0.0, 0.4, 1.0, 0.2])  # rad, inside every limit
    ticks = backend.rad_to_ticks(q)
    for k, name in enumerate(r.joint_names):
        c = CALIB[name]
        if c["drive_mode"]:
            continue  # LeRobot's degree mode ignores drive_mode; robogest turns the joint the other way
        mid = 0.5 * (c["range_min"] + c["range_max"])
        assert abs(ticks[k] - (mid + math.degrees(q[k]) * 4095 / 360)) <= 1.0, name
    assert ticks[2] == 2000  # elbow_flex at 0: the middle of its recorded range


def test_a_calibration_of_another_robot_is_refused(tmp_path, so101_copy):
    """An SO-101 (Feetech) calibration imported for humanoid_xl430 (Dynamixel) was matched by servo id: six joints
    got foreign zero offsets, exit 0, "valid". Motors must be named after the joints, have their servo ids, and a
    LeRobot folder of the other servo family is refused."""
    xl430 = find_robot("humanoid_xl430")
    for calib, path, pattern in (
        (CALIB, "follower.json", r"motors \['shoulder_pan', .*'gripper'\] are not joints of humanoid_xl430 \(its "
         r"joints: torso_yaw, "),
        ({f"motor{c['id']}": c for c in CALIB.values()}, "follower.json", r"motors \['motor1', "),
        ({"torso_yaw": CALIB["shoulder_pan"]}, "so101_follower/arm.json",
         r"so101_follower/arm\.json: a calibration of a so101_follower \(feetech servos\), not of humanoid_xl430 "
         r"\(dynamixel servos\)"),
    ):  # fmt: skip
        (tmp_path / path).parent.mkdir(exist_ok=True)
        with pytest.raises(InputError, match=pattern):
            import_lerobot_calibration(_write(tmp_path, calib, path), xl430, out=tmp_path / "x.yaml")
    assert not (tmp_path / "x.yaml").exists()
    moved = {**CALIB, "wrist_roll": {**CALIB["wrist_roll"], "id": 9}}
    with pytest.raises(InputError, match=r"motors wrist_roll \(id 9; so101_sts3215: id 5\) have other servo ids"):
        import_lerobot_calibration(_write(tmp_path, moved), so101_copy)
    assert not (tmp_path / "so101_calibrated.yaml").exists()


def test_rest_outside_recorded_range_refused(tmp_path, so101_copy):
    calib = json.loads(json.dumps(CALIB))
    calib["elbow_flex"].update(range_min=1800, range_max=2200)  # +-0.31 rad; rest is 1.45
    with pytest.raises(ConfigError, match=r"motor 'elbow_flex': the calibrated range .* rest pose 1\.45"):
        import_lerobot_calibration(_write(tmp_path, calib), so101_copy)
    assert not (tmp_path / "so101_calibrated.yaml").exists()


@pytest.mark.parametrize(
    ("calib", "pattern"),
    [
        ({"shoulder_pan": {"id": 1}}, r"motor 'shoulder_pan' lacks \['drive_mode'"),
        ({"shoulder_pan": {**CALIB["shoulder_pan"], "range_min": 4000}}, r"range_min 4000 must be .* below range_max"),
        ({"shoulder_pan": {**CALIB["shoulder_pan"], "range_max": 5000}}, r"range_max 5000 is past the STS3215"),
        ([1, 2], r"expected \{motor name"),
    ],
    ids=["missing-field", "min>max", "past-last-tick", "not-a-mapping"],
)
def test_bad_calibration_files(tmp_path, so101_copy, calib, pattern):
    with pytest.raises(InputError, match=pattern):
        import_lerobot_calibration(_write(tmp_path, calib), so101_copy)


def test_a_refused_calibration_keeps_a_good_copy(tmp_path, so101_copy):
    """A refused calibration replaces nothing, even with --force."""
    good = import_lerobot_calibration(_write(tmp_path, CALIB), so101_copy).path
    before = good.read_text()
    twice = {**CALIB, "shoulder_pan": {**CALIB["shoulder_pan"], "id": 2}}  # both joints' servos on id 2
    with pytest.raises(InputError, match=r"follower\.json: motors shoulder_pan \(id 2; so101_sts3215: id 1\)"):
        import_lerobot_calibration(_write(tmp_path, twice), so101_copy, overwrite=True)
    assert good.read_text() == before


def test_a_copy_that_would_not_load_is_named_as_the_copy_not_a_temporary_file(tmp_path, so101_copy, monkeypatch):
    import robogest.robot.yaml_edit as ye

    def refuse(path):
        raise ConfigError(f"{path}: key joints[0]: made up")

    monkeypatch.setattr(ye, "load_robot_config", refuse)
    out = tmp_path / "copy.yaml"
    with pytest.raises(ConfigError, match=r"follower\.json: the calibrated copy would not load: .*copy\.yaml: key "
                                          r"joints\[0\]: made up; nothing written") as e:  # fmt: skip
        import_lerobot_calibration(_write(tmp_path, CALIB), so101_copy, out=out)
    assert ".tmp" not in str(e.value) and not out.exists()


def test_never_over_the_original(tmp_path, so101_copy):
    calib = _write(tmp_path, CALIB)
    with pytest.raises(InputError, match="is the robot's own YAML"):
        import_lerobot_calibration(calib, so101_copy, out=so101_copy.path, overwrite=True)
    import_lerobot_calibration(calib, so101_copy)
    with pytest.raises(InputError, match="exists; choose another --out or pass --force"):
        import_lerobot_calibration(calib, so101_copy)


def test_read_calibration_not_json(tmp_path):
    (tmp_path / "c.json").write_text("{")
    with pytest.raises(InputError, match=r"c\.json: not JSON"):
        read_calibration(tmp_path / "c.json")


def test_cli(tmp_path, so101_copy, capsys):
    out = tmp_path / "mine.yaml"
    rc = main(
        [
            "robots",
            "import-lerobot-calibration",
            str(_write(tmp_path, CALIB)),
            "--robot",
            str(so101_copy.path),
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "the original is unchanged" in text and "elbow_flex" in text and f"{out}: valid" in text


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_calibrated_limits_stay_inside_the_recorded_range(tmp_path, so101_copy, data):
    """Safety invariant: whatever the file says, the calibrated robot's joint limits map to ticks inside the range
    LeRobot recorded (and wrote into the servo's position limits), for either drive mode."""
    calib = {}
    for j in so101_copy.joints:
        rest_tick = 2048 + round(j.rest_rad / TICK)  # where the rest pose falls with a centred range
        lo = data.draw(st.integers(0, rest_tick - 40), label=f"{j.name} min")
        hi = data.draw(st.integers(rest_tick + 40, 4095), label=f"{j.name} max")
        calib[j.name] = {"id": so101_copy.bus.servos[j.name].id, "drive_mode": data.draw(st.sampled_from([0, 1])),
                         "homing_offset": 0, "range_min": lo, "range_max": hi}  # fmt: skip
    try:
        res = import_lerobot_calibration(_write(tmp_path, calib), so101_copy, overwrite=True)
    except ConfigError as e:  # the recorded range leaves no room around the rest pose: refused, nothing written
        assert "rest pose" in str(e)
        event("refused")
        return
    event("imported")
    r = load_robot_config(res.path)
    backend = get_backend_factory("feetech")(r, port="/dev/null")
    for q in (r.q_min_rad, r.q_max_rad, r.rest_q_rad):
        ticks = backend.rad_to_ticks(q)
        for k, name in enumerate(r.joint_names):
            assert calib[name]["range_min"] - 1 <= ticks[k] <= calib[name]["range_max"] + 1, name


def test_the_copy_names_its_base_and_survives_a_move(tmp_path, capsys):
    """The copy said `model: ../../v/lib/python3.11/site-packages/...`: moving it or reinstalling broke it. It now
    holds `base: so101_sts3215` and only the calibrated values, and loads from anywhere."""
    out = tmp_path / "a" / "so101_mine.yaml"
    argv = ["robots", "import-lerobot-calibration", str(_write(tmp_path, CALIB)), "--robot", "so101_sts3215"]
    assert main([*argv, "--out", str(out)]) == 0
    capsys.readouterr()
    doc = yaml.safe_load(out.read_text())
    assert doc["base"] == "so101_sts3215" and "model" not in doc and "retarget" not in doc
    assert doc["joints"][1] == {"name": "shoulder_lift", "lower_rad": -1.533981, "upper_rad": 1.533981}
    assert doc["bus"] == {"servos": {n: {"zero_offset_rad": pytest.approx(v, abs=1e-6), "direction": d} for n, v, d in (
        ("shoulder_pan", -23 * TICK, 1), ("shoulder_lift", -48 * TICK, 1), ("elbow_flex", -48 * TICK, -1),
        ("wrist_flex", 2 * TICK, 1), ("wrist_roll", -0.5 * TICK, 1), ("gripper", 652 * TICK, 1))}}  # fmt: skip
    moved = tmp_path / "elsewhere" / "deeper" / "so101_mine.yaml"
    moved.parent.mkdir(parents=True)
    out.rename(moved)
    r = load_robot_config(moved)
    shipped = find_robot("so101_sts3215")
    assert r.model_path == shipped.model_path and r.retarget == shipped.retarget
    assert r.bus.servos["gripper"].zero_offset_rad == pytest.approx(652 * TICK, abs=1e-6)
    assert [str(p) for p in validate(moved)] == []


def test_recalibrating_a_calibrated_copy_keeps_its_base_and_edits(tmp_path, so101_copy):
    first = import_lerobot_calibration(_write(tmp_path, CALIB), so101_copy, out=tmp_path / "mine.yaml").path
    doc = yaml.safe_load(first.read_text())
    doc["joints"][-1]["max_velocity_rad_s"] = 1.0  # the user's own edit to the gripper
    first.write_text(yaml.safe_dump(doc))
    again = {**CALIB, "gripper": {**CALIB["gripper"], "range_min": 2100}}
    res = import_lerobot_calibration(_write(tmp_path, again, "again.json"), load_robot_config(first),
                                     out=tmp_path / "mine2.yaml")  # fmt: skip
    doc2 = yaml.safe_load(res.path.read_text())
    assert doc2["base"] == "so101" and doc2["description"].endswith("(calibrated from again.json)")
    assert "follower.json" not in doc2["description"]
    r = load_robot_config(res.path)
    assert r.joints[-1].max_velocity_rad_s == 1.0
    assert r.bus.servos["gripper"].zero_offset_rad == pytest.approx(702 * TICK, abs=1e-6)


def test_a_copy_whose_base_name_would_find_another_robot_is_refused(tmp_path, so101_copy):
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "so101.yaml").write_text(so101_copy.path.read_text())  # same name, another file
    pattern = (
        r"--out .*other/mine\.yaml: the copy names its base robot 'so101' \(.*so101\.yaml\), but from .*other "
        r"that name finds .*other/so101\.yaml"
    )
    with pytest.raises(InputError, match=pattern):
        import_lerobot_calibration(_write(tmp_path, CALIB), so101_copy, out=tmp_path / "other" / "mine.yaml")
    assert not (tmp_path / "other" / "mine.yaml").exists()


def test_cli_refuses_an_so101_calibration_for_another_feetech_robot(tmp_path, capsys):
    """Same servo family, other joints: `--robot humanoid_sts3215` mapped the SO-101's motors by servo id onto the
    humanoid's ids 1-6 (exit 0). Refused naming the motors, exit 2, nothing written."""
    out = tmp_path / "h.yaml"
    rc = main(["robots", "import-lerobot-calibration", str(_write(tmp_path, CALIB)), "--robot", "humanoid_sts3215",
               "--out", str(out)])  # fmt: skip
    assert rc == 2 and not out.exists()
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert re.search(r"follower\.json: motors \['shoulder_pan', 'shoulder_lift', 'elbow_flex', 'wrist_flex', "
                     r"'wrist_roll', 'gripper'\] are not joints of humanoid_sts3215 \(its joints: torso_yaw, .*\); a "
                     r"calibration of another robot\? .*nothing written", err)  # fmt: skip
