"""`robogest robots validate`: each kind of mistake in a user's robot is found and named with file, key and fix.

Every case starts from a copy of the shipped desk arm (YAML + MJCF) with one thing broken.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
import yaml

from robogest.cli.main import main
from robogest.robot.registry import list_robots
from robogest.tools.validate import validate


def _desk_arm_copy(tmp_path: Path, mutate_yaml=None, mutate_xml=None) -> Path:
    src = list_robots()["desk_arm_sts3215"]
    sim = tmp_path / "sim"
    shutil.copytree(src.parent.parent / "sim" / "desk_arm", sim)
    if mutate_xml is not None:
        xml = sim / "desk_arm_sts3215.xml"
        text = xml.read_text()
        new = mutate_xml(text)
        assert new != text, "the mutation changed nothing"
        xml.write_text(new)
    raw = yaml.safe_load(src.read_text())
    raw["model"] = "sim/scene.xml"
    if mutate_yaml is not None:
        mutate_yaml(raw)
    out = tmp_path / "arm.yaml"
    out.write_text(yaml.safe_dump(raw, sort_keys=False))
    return out


def _problems(path: Path) -> list[str]:
    return [str(p) for p in validate(path)]


def test_unbroken_copy_is_valid(tmp_path):
    assert _problems(_desk_arm_copy(tmp_path)) == []


def _rename_joint(raw, new="elbw", rename_servo=True):
    raw["joints"][2]["name"] = new
    if rename_servo:
        raw["bus"]["servos"][new] = raw["bus"]["servos"].pop("elbow")


@pytest.mark.parametrize(
    ("mutate", "patterns"),
    [
        (lambda r: r["joints"][1].update(upper_rad=2.0),
         [r"key joints\[1\]\.upper_rad: 2\.0 lies above the model's range \[-1\.6, 1\.7\]; fix: set upper_rad <= 1\.7",
          r'key <actuator> for joint "shoulder_pitch": ctrlrange \[-1\.6, 1\.7\] does not cover']),
        (lambda r: r["bus"]["servos"]["elbow"].update(model="STS3216"),
         [r"arm\.yaml: key bus\.servos\.elbow\.model: unknown Feetech model 'STS3216'; known: STS3215"]),
        (_rename_joint, [r"key joints\[2\]\.name: 'elbw' is not a joint in .*did you mean 'elbow'\?"]),
        (lambda r: _rename_joint(r, rename_servo=False),
         [r"key joints\[2\]\.name: 'elbw' is not a joint in .*did you mean 'elbow'\?",
          r"key \(top level\): bus\.servos has no entry for joints \['elbw'\] but names \['elbow'\].*a typo"]),
        (lambda r: r["joints"][4].update(max_velocity_rad_s=4.0),
         [r"key joints\[4\]\.max_velocity_rad_s: 4\.0 rad/s is more than 75% of the STS3215's no-load speed"
          r".*fix: set it to 3\.54 or less"]),
        (lambda r: r["bus"]["servos"]["wrist_roll"].update(zero_offset_rad=1.0),
         [r"key bus\.servos\.wrist_roll\.zero_offset_rad: joint limits \[-2\.8, 2\.8\] rad fall on ticks 875\.\.4525, "
          r"outside the STS3215's 0\.\.4095"]),
        (lambda r: r["joints"][3].update(rest_rad=-0.4),
         [r'key <key name="home"> joint "wrist_pitch": qpos -0\.5 / ctrl -0\.5 differ from the YAML rest_rad -0\.4']),
        (lambda r: r["retarget"][1].update(robot=["elbow_site", "wrist_sit"]),
         [r"key retarget\[1\]\.robot: 'wrist_sit' is not a site in .*did you mean 'wrist_site'\?"]),
        (lambda r: r["retarget"][0].update(robot=["elbow_site", "shoulder_site"]),
         [r"key retarget\[0\]: the robot link elbow_site->shoulder_site points \d+ deg away from the human bone"]),
    ],
    ids=["limit-wider-than-model", "servo-model-typo", "joint-name-typo", "joint-typo-breaks-bus", "too-fast-for-servo",
         "past-servo-ticks", "keyframe-not-rest", "site-typo", "swapped-sites-unreachable"],
)  # fmt: skip
def test_yaml_mistakes_found(tmp_path, mutate, patterns):
    problems = _problems(_desk_arm_copy(tmp_path, mutate_yaml=mutate))
    for pat in patterns:
        assert any(re.search(pat, p) for p in problems), (pat, problems)
    assert all("arm.yaml" in p or "desk_arm_sts3215.xml" in p or "scene.xml" in p for p in problems)


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (lambda t: t.replace(' forcerange="-2.94 2.94"', ""),
         r'key <actuator> for joint "base_yaw": no force limit.*fix: set forcerange'),
        (lambda t: t.replace('<position name="elbow" joint="elbow"', '<position name="elbow" joint="wrist_pitch"'),
         r'key <actuator> for joint "elbow": 0 actuators drive this joint'),  # and 2 drive wrist_pitch
        (lambda t: t.replace('<key name="home"', '<key name="start"'), r"key <keyframe>: no keyframe named 'home'"),
        (lambda t: t.replace('timestep="0.002"', 'timestep="0.01"'), r"key <option timestep>: physics step 0\.01 s"),
        (lambda t: t.replace('damping="0.62" armature="0.006"', ""),
         r'key <joint name="base_yaw">: needs damping and armature'),
    ],
    ids=["no-forcerange", "missing-actuator", "no-home-key", "coarse-timestep", "no-damping"],
)  # fmt: skip
def test_mjcf_mistakes_found(tmp_path, mutate, pattern):
    problems = _problems(_desk_arm_copy(tmp_path, mutate_xml=mutate))
    assert any(re.search(pattern, p) for p in problems), problems


_ELBOW = '<position name="elbow" joint="elbow" class="sts3215"/>'


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (lambda t: t.replace(_ELBOW, '<position name="elbow" joint="elbow" class="sts3215" gear="2"/>'),
         r'key <actuator> for joint "elbow": gear 2: the joint would settle at ctrl / 2'),
        (lambda t: t.replace(_ELBOW, '<motor name="elbow" joint="elbow" gear="1" ctrlrange="-1 1"/>'),
         r'key <actuator> for joint "elbow": not a position servo'),
        (lambda t: t.replace(_ELBOW, _ELBOW + '<motor name="elbow_m" joint="elbow" ctrlrange="-1 1"/>'),
         r'key <actuator> for joint "elbow": 2 actuators drive this joint'),
        (lambda t: t.replace(_ELBOW, '<position name="elbow" joint="elbow" class="sts3215" inheritrange="0" '
                                     'ctrlrange="-0.2 0.2"/>'),
         r'key <actuator> for joint "elbow": ctrlrange \[-0\.2, 0\.2\] does not cover the YAML limits'),
    ],
    ids=["gear-2", "motor-not-position", "two-actuators", "narrow-ctrlrange"],
)  # fmt: skip
def test_the_simulator_refuses_a_model_that_would_not_do_what_the_yaml_commands(tmp_path, mutate, pattern):
    """``robots validate`` lists it, and ``speak``/``play`` on the sim refuse the robot with the same problem, on
    one line (they used to drive the first actuator found, of any kind, or let a geared one reach half the goal)."""
    from robogest.backends.mujoco_sim import load_sim_model
    from robogest.errors import ConfigError
    from robogest.robot.config import load_robot_config

    path = _desk_arm_copy(tmp_path, mutate_xml=mutate)
    assert any(re.search(pattern, p) for p in _problems(path)), _problems(path)
    with pytest.raises(ConfigError, match=r"arm\.yaml: the MuJoCo model does not match the robot YAML: .*" + pattern):
        load_sim_model(load_robot_config(path))


def test_a_tendon_actuator_is_not_taken_for_a_joint_one(tmp_path):
    """A tendon transmission's id counts tendons, not joints: tendon 0 must not be read as joint 0."""
    from robogest.backends.mujoco_sim import load_sim_model
    from robogest.robot.config import load_robot_config

    def tendon_first(t: str) -> str:
        t = t.replace("<actuator>", '<tendon><fixed name="t0"><joint joint="elbow" coef="1"/></fixed></tendon>'
                                    '<actuator><motor name="tmot" tendon="t0" ctrlrange="-1 1"/>', 1)  # fmt: skip
        return t

    path = _desk_arm_copy(tmp_path, mutate_xml=tendon_first)
    sim = load_sim_model(load_robot_config(path))
    m = sim.model
    assert [m.actuator(int(a)).name for a in sim.act_idx] == ["base_yaw", "shoulder_pitch", "elbow", "wrist_pitch",
                                                              "wrist_roll"]  # fmt: skip


def test_load_problems_of_a_file_that_does_not_load_are_listed_one_per_key(tmp_path):
    def two(raw):
        raw["joints"][0]["max_velocity_rad_s"] = True
        raw["joints"][1]["upper_rad"] = "1.5"

    problems = _problems(_desk_arm_copy(tmp_path, mutate_yaml=two))
    assert any(re.search(r"key joints\[0\]\.max_velocity_rad_s: True is not a number", p) for p in problems)
    assert any(re.search(r"key joints\[1\]\.upper_rad: '1\.5' is not a number", p) for p in problems)
    bad = tmp_path / "syntax.yaml"
    bad.write_text("name: [unclosed\n  a: b\n")
    (p,) = _problems(bad)
    assert "not valid YAML: while parsing a flow sequence" in p and "\n" not in p


def test_cli_valid_and_invalid(tmp_path, capsys):
    assert main(["robots", "validate", "desk_arm_sts3215"]) == 0
    assert "desk_arm_sts3215: valid" in capsys.readouterr().out
    bad = _desk_arm_copy(tmp_path, mutate_yaml=lambda r: r["bus"]["servos"]["elbow"].update(model="STS3216"))
    assert main(["robots", "validate", str(bad)]) == 3
    cap = capsys.readouterr()
    assert "bus.servos.elbow.model: unknown Feetech model 'STS3216'" in cap.out
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and "1 problem(s)" in err[0]
    assert main(["robots", "validate", "no_such_robot"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown robot 'no_such_robot'; known robots:" in err[0]


def test_every_problem_is_listed_not_just_the_first(tmp_path):
    def two_mistakes(raw):
        raw["joints"][4]["max_velocity_rad_s"] = 4.0
        raw["joints"][3]["rest_rad"] = -0.4

    problems = _problems(_desk_arm_copy(tmp_path, mutate_yaml=two_mistakes))
    assert any("max_velocity_rad_s" in p for p in problems) and any('<key name="home">' in p for p in problems)
