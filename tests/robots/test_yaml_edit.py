"""The one robot-YAML writer: one dump style, and a file is published only once the validated loader accepts it."""

from __future__ import annotations

import shutil

import pytest
import yaml

from robogest.errors import ConfigError
from robogest.robot.registry import list_robots
from robogest.robot.yaml_edit import dump_robot_yaml, write_robot_yaml


@pytest.fixture
def arm_doc(tmp_path):
    """The shipped desk arm as plain data, its MJCF copied beside ``tmp_path`` (``model:`` relative to it)."""
    src = list_robots()["desk_arm_sts3215"]
    shutil.copytree(src.parent.parent / "sim" / "desk_arm", tmp_path / "sim")
    doc = yaml.safe_load(src.read_text())
    doc["model"] = "sim/scene.xml"
    return doc


def test_writes_a_copy_that_loads_with_its_header(tmp_path, arm_doc):
    out = tmp_path / "arm.yaml"
    arm_doc["name"] = "arm"
    robot = write_robot_yaml(out, arm_doc, header="# a header line\n")
    assert robot.name == "arm" and robot.path == out
    text = out.read_text()
    assert text.startswith("# a header line\n") and text == dump_robot_yaml(arm_doc, "# a header line\n")
    assert yaml.safe_load(text) == arm_doc
    assert not [p for p in tmp_path.iterdir() if p.name not in ("arm.yaml", "sim")]  # no temporary left


def test_a_copy_that_would_not_load_replaces_nothing(tmp_path, arm_doc):
    out = tmp_path / "arm.yaml"
    out.write_text("# what was there\n")
    arm_doc["joints"][0]["lower_rad"] = 5.0  # above upper_rad
    with pytest.raises(ConfigError, match=r"arm\.yaml: .*joints.*; nothing written") as e:
        write_robot_yaml(out, arm_doc)
    assert ".arm.yaml." not in str(e.value)  # the file it would have been, not the temporary one
    assert out.read_text() == "# what was there\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["arm.yaml", "sim"]


def test_short_lists_stay_on_one_line():
    assert dump_robot_yaml({"a": [1.0, 2.0], "b": {"c": 1}}) == "a: [1.0, 2.0]\nb: {c: 1}\n"
