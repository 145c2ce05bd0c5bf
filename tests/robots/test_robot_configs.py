"""Every shipped robot: YAML valid, MJCF consistent with it, rest pose safe; broken YAMLs give clear errors."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from robogest.backends.servos.check import NO_LOAD_RAD_S
from robogest.errors import ConfigError
from robogest.robot.config import load_robot_config
from robogest.robot.registry import DEFAULT_ROBOT, find_robot, list_robots
from robogest.tools.validate import validate_robot

ROBOTS = sorted(list_robots())
EXPECTED = {"humanoid_xl430", "humanoid_sts3215", "desk_arm_sts3215", "so101_sts3215"}


def _model(robot):
    return mujoco.MjModel.from_xml_path(str(robot.model_path))


def test_shipped_robots_present():
    assert set(ROBOTS) >= EXPECTED
    assert DEFAULT_ROBOT in ROBOTS


@pytest.mark.parametrize("name", ROBOTS)
def test_shipped_robot_validates(name):
    """The same checks `robogest robots validate` runs on a user's robot: limits inside the model's ranges,
    position actuators with ctrlrange and force limits, home keyframe = rest, no self-contact at rest, servo
    models known and fast enough, retargeting followed."""
    assert [str(p) for p in validate_robot(find_robot(name))] == []


@pytest.mark.parametrize("name", ROBOTS)
def test_shipped_mjcf_equals_yaml_exactly(name):
    """Shipped robots go further than validate asks: YAML limits are the model's ranges, torques servo-sized."""
    robot = find_robot(name)
    m = _model(robot)
    for j in robot.joints:
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)
        np.testing.assert_allclose(m.jnt_range[jid], [j.lower_rad, j.upper_rad], atol=1e-9, err_msg=j.name)
        a = next(a for a in range(m.nu) if m.actuator_trnid[a, 0] == jid)
        np.testing.assert_allclose(m.actuator_ctrlrange[a], [j.lower_rad, j.upper_rad], atol=1e-9)
        assert 0.5 < m.actuator_forcerange[a, 1] < 10, "servo-like torque limit"


@pytest.mark.parametrize("name", ROBOTS)
def test_mass_and_size_plausible(name):
    m = _model(find_robot(name))
    robot_mass = m.body_subtreemass[1]
    assert 0.5 < robot_mass < 5.0
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    reach = np.linalg.norm(d.site_xpos - d.xpos[1], axis=1).max()  # farthest site from the robot's root, joints at 0
    assert 0.25 < reach < 0.6, "a desk-sized robot"


def _site(m, d, name):
    return d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)]


def _rest_data(robot):
    m = _model(robot)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home"))
    mujoco.mj_forward(m, d)
    return m, d


@pytest.mark.parametrize("name", [n for n in ROBOTS if n.startswith("humanoid")])
def test_humanoid_rest_arms_down_head_forward(name):
    m, d = _rest_data(find_robot(name))
    for side in "lr":
        shoulder, elbow = _site(m, d, f"{side}_shoulder_site"), _site(m, d, f"{side}_elbow_site")
        wrist = _site(m, d, f"{side}_wrist_site")
        assert wrist[2] < elbow[2] < shoulder[2] - 0.05, "arm hangs down"
        assert abs(wrist[1]) > 0.09, "hand beside the torso, not in it"
    # conventions: +Y is the robot's left, the face looks along +X
    assert _site(m, d, "l_shoulder_site")[1] > 0 > _site(m, d, "r_shoulder_site")[1]
    head, nose = _site(m, d, "head_site"), _site(m, d, "nose_site")
    assert nose[0] - head[0] > 0.03 and abs(nose[1] - head[1]) < 1e-9
    # head->nose elevation equals the canonical human's (0.10 forward, 0.08 up) so a neutral head maps to 0
    assert math.atan2(nose[2] - head[2], nose[0] - head[0]) == pytest.approx(math.atan2(0.08, 0.10), abs=1e-6)


def test_desk_arm_rest_is_folded_above_desk():
    m, d = _rest_data(find_robot("desk_arm_sts3215"))
    hand, shoulder = _site(m, d, "hand_site"), _site(m, d, "shoulder_site")
    assert hand[2] > 0.05 and hand[0] > shoulder[0], "hand in front of the arm, clear of the desk"


def test_humanoid_variants_share_the_body():
    a, b = find_robot("humanoid_xl430"), find_robot("humanoid_sts3215")
    assert a.joint_names == b.joint_names
    np.testing.assert_array_equal(a.q_min_rad, b.q_min_rad)
    ma, mb = _model(a), _model(b)
    np.testing.assert_allclose(ma.body_pos, mb.body_pos)
    np.testing.assert_allclose(ma.body_mass, mb.body_mass)
    assert not np.allclose(ma.actuator_forcerange, mb.actuator_forcerange), "servo dynamics differ"


@pytest.mark.parametrize("name", ROBOTS)
def test_limits_are_conservative_for_the_servo(name):
    robot = find_robot(name)  # velocity vs the servo's no-load speed: test_shipped_robot_validates
    assert robot.bus is not None
    assert all(robot.bus.servos[j.name].model in NO_LOAD_RAD_S for j in robot.joints), "speed check applies"
    for j in robot.joints:
        assert 5 <= j.max_acceleration_rad_s2 <= 40, j.name
    ids = sorted(s.id for s in robot.bus.servos.values())
    assert ids == list(range(1, len(robot.joints) + 1))


# --- broken YAMLs ------------------------------------------------------------------------------


def _write_variant(tmp_path: Path, mutate) -> Path:
    src = list_robots()["humanoid_xl430"]
    raw = yaml.safe_load(src.read_text())
    raw["model"] = str((src.parent / raw["model"]).resolve())
    mutate(raw)
    out = tmp_path / "broken.yaml"
    out.write_text(yaml.safe_dump(raw))
    return out


def test_valid_copy_loads(tmp_path):
    assert load_robot_config(_write_variant(tmp_path, lambda raw: None)).name == "humanoid_xl430"


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (lambda r: r.update(colour="red"), r"key colour: Extra inputs"),
        (lambda r: r["joints"][2].update(speed=1), r"key joints\[2\]\.speed"),
        (lambda r: r["joints"][1].update(lower_rad=2.0), r"key joints\[1\].*lower_rad \(2\.0\) must be below"),
        (lambda r: r.update(model="nowhere/scene.xml"), r"key model: MuJoCo file .*nowhere/scene\.xml does not exist"),
        (lambda r: r["bus"]["servos"]["head_pan"].update(id=1), r"key bus: .*servo ids \[1\]"),
        (lambda r: r["bus"]["servos"].pop("l_elbow"), r"bus\.servos has no entry for joints \['l_elbow'\]"),
        (lambda r: r["retarget"][0].update(human=["l_shoulder", "l_knee"]), r"key retarget\[0\]: human point .l_knee."),
        (lambda r: r["bus"]["servos"]["head_pan"].update(zero_offset_rad=float("nan")),
         r"key bus\.servos\.head_pan\.zero_offset_rad: nan is not a finite number"),
        (lambda r: r["bus"]["servos"]["l_elbow"].update(gear_ratio=float("inf")),
         r"key bus\.servos\.l_elbow\.gear_ratio: inf is not a finite number"),
        (lambda r: r["bus"]["servos"]["l_elbow"].update(gear_ratio=0.0),
         r"key bus\.servos\.l_elbow\.gear_ratio: .*greater than 0"),
        (lambda r: r["bus"]["servos"]["l_elbow"].update(gear_ratio=1.0e-300),
         r"key bus\.servos\.l_elbow: .*gear_ratio = 1e-300 is outside \[0\.01, 100\]"),
        (lambda r: r["bus"]["servos"]["l_elbow"].update(gear_ratio=1.0e6), r"gear_ratio = 1e\+06 is outside"),
        (lambda r: r["bus"]["servos"]["head_pan"].update(zero_offset_rad=90.0),
         r"key bus\.servos\.head_pan: .*zero_offset_rad = 90 is more than one turn"),
        (lambda r: r["bus"].update(baudrate=10**12), r"key bus\.baudrate: .*less than or equal to 20000000"),
        (lambda r: r["bus"].update(baudrate=1), r"key bus\.baudrate: .*greater than or equal to 300"),
        (lambda r: r["joints"][3].update(lower_rad=float("nan")),
         r"key joints\[3\]\.lower_rad: nan is not a finite number"),
        (lambda r: r["joints"][0].update(max_velocity_rad_s=float("inf")),
         r"key joints\[0\]\.max_velocity_rad_s: inf is not a finite number"),
        (lambda r: r["joints"][0].update(rest_rad=float("-inf")), r"key joints\[0\]\.rest_rad: -inf is not a finite"),
        (lambda r: r["retarget"][1].update(weight=float("inf")), r"key retarget\[1\]\.weight: inf is not a finite"),
        (lambda r: r.update(retarget_frame_rpy_rad=[0.0, float("nan"), 0.0]),
         r"key retarget_frame_rpy_rad\[1\]: nan is not a finite number"),
        (lambda r: r["joints"][0].update(max_velocity_rad_s=True),
         r"key joints\[0\]\.max_velocity_rad_s: True is not a number; write the value unquoted"),
        (lambda r: r["joints"][2].update(upper_rad="1.5"), r"key joints\[2\]\.upper_rad: '1\.5' is not a number"),
        (lambda r: r["bus"]["servos"]["l_elbow"].update(id=True), r"key bus\.servos\.l_elbow\.id: True is not a"),
        # `direction: true` read as 1 would silently leave a servo meant to be reversed unreversed
        (lambda r: r["bus"]["servos"]["r_elbow"].update(direction=True),
         r"key bus\.servos\.r_elbow\.direction: True is not a number"),
        (lambda r: r.update(retarget_frame_rpy_rad=[True, 0.0, 0.0]), r"key retarget_frame_rpy_rad: True is not a"),
        (lambda r: r["joints"][0].update(max_velocity_rad_s="2e0"),
         r"key joints\[0\]\.max_velocity_rad_s: '2e0' is read as text.*decimal point \(e\.g\. 1\.0e-6\)"),
        (lambda r: r["joints"][0].update(max_velocity_rad_s=1.0e9),
         r"key joints\[0\]: .*max_velocity_rad_s = 1e\+09 rad/s is outside \[0\.01, 100\].*check the units"),
        (lambda r: r["joints"][1].update(max_acceleration_rad_s2=1.0e-6),
         r"key joints\[1\]: .*max_acceleration_rad_s2 = 1e-06 rad/s² is outside \[0\.05, 10000\]"),
        (lambda r: r["joints"][2].update(max_jerk_rad_s3=1.0e308), r"key joints\[2\]: .*max_jerk_rad_s3 = 1e\+308"),
    ],
    ids=["unknown-key", "unknown-joint-key", "lower>upper", "missing-model", "duplicate-id", "bus-missing-joint",
         "bad-human-point", "nan-zero-offset", "inf-gear-ratio", "zero-gear-ratio", "tiny-gear-ratio",
         "huge-gear-ratio", "zero-offset-90-rad", "baud-1e12", "baud-1", "nan-limit", "inf-velocity",
         "inf-rest", "inf-weight", "nan-frame-rpy", "bool-velocity", "quoted-limit", "bool-id", "bool-direction",
         "bool-in-tuple", "exponent-text", "huge-velocity", "tiny-acceleration", "huge-jerk"],
)  # fmt: skip
def test_broken_yaml_names_file_and_key(tmp_path, mutate, pattern):
    path = _write_variant(tmp_path, mutate)
    with pytest.raises(ConfigError, match=pattern) as exc:
        load_robot_config(path)
    assert str(path) in str(exc.value)


@pytest.mark.parametrize(
    ("old", "new", "pattern"),
    [
        ("upper_rad: 1.2,", "upper_rad: 1.2, upper_rad: 0.5,", r"key 'upper_rad' given twice in one mapping"),
        (
            "    r_elbow:          {id: 11, model: XL430-W250, direction: -1}",
            "    r_elbow:          {id: 11, model: XL430-W250, direction: -1}\n    r_elbow: {id: 11, model: XL430}",
            r"key 'r_elbow' given twice .*keep one",
        ),
    ],
    ids=["limit", "servo-entry"],
)
def test_a_key_given_twice_is_refused_not_overwritten(tmp_path, old, new, pattern):
    """PyYAML keeps the last of two equal keys: a second limit, or a servo entry repeated without its
    ``direction: -1``, would take effect unseen."""
    src = list_robots()["humanoid_xl430"]
    text = src.read_text().replace("../sim/", str(src.parent.parent / "sim") + "/")
    assert old in text
    path = tmp_path / "twice.yaml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError, match=pattern) as exc:
        load_robot_config(path)
    assert str(path) in str(exc.value)


def test_exponent_without_a_dot_is_text_in_yaml_and_the_message_says_so(tmp_path):
    src = list_robots()["humanoid_xl430"]
    text = src.read_text().replace("../sim/", str(src.parent.parent / "sim") + "/")
    path = tmp_path / "exp.yaml"
    path.write_text(text.replace("max_velocity_rad_s: 2.5,", "max_velocity_rad_s: 25e-1,", 1))
    with pytest.raises(ConfigError, match=r"max_velocity_rad_s: '25e-1' is read as text.*decimal point"):
        load_robot_config(path)
    path.write_text(text.replace("max_velocity_rad_s: 2.5,", "max_velocity_rad_s: 25.0e-1,", 1))
    assert load_robot_config(path).joints[0].max_velocity_rad_s == 2.5


def test_not_utf8_is_config_error(tmp_path):
    bad = tmp_path / "latin.yaml"
    bad.write_bytes("name: caf\xe9\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin\.yaml: not UTF-8 text.*save it as UTF-8"):
        load_robot_config(bad)


def test_not_yaml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed")
    with pytest.raises(ConfigError, match=r"bad\.yaml: not valid YAML"):
        load_robot_config(bad)
    with pytest.raises(ConfigError, match=r"nothere\.yaml: cannot read"):
        load_robot_config(tmp_path / "nothere.yaml")


def test_yaml_joint_missing_in_mjcf_is_config_error(tmp_path):
    from robogest.backends.mujoco_sim import load_sim_model

    def rename(raw):
        raw["joints"][0]["name"] = "waist_yaw"
        raw["bus"]["servos"]["waist_yaw"] = raw["bus"]["servos"].pop("torso_yaw")

    path = _write_variant(tmp_path, rename)
    pattern = r"broken\.yaml: the MuJoCo model does not match the robot YAML: key joints\[0\]\.name: 'waist_yaw' is"
    with pytest.raises(ConfigError, match=pattern):
        load_sim_model(load_robot_config(path))


def test_env_search_path_wins(tmp_path, monkeypatch):
    path = _write_variant(tmp_path, lambda raw: raw.update(description="override"))
    path.rename(tmp_path / "humanoid_xl430.yaml")
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    assert find_robot("humanoid_xl430").description == "override"
