"""``base: NAME`` in a robot YAML: only what differs from another robot, found by name, so the file survives moves
and reinstalls; unknown bases, loops and added joints are refused naming the key and the file."""

from __future__ import annotations

import shutil

import pytest
import yaml

from robogest.cli.main import main
from robogest.errors import ConfigError
from robogest.robot.config import load_robot_config
from robogest.robot.registry import find_robot, list_robots
from robogest.virtualbus.testing import make_robot


def _write(path, doc):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(doc))
    return path


def test_changes_merge_onto_the_base_and_the_rest_is_the_bases(tmp_path):
    base = make_robot(tmp_path, n_joints=3, name="basebot")
    mine = _write(tmp_path / "mine.yaml", {
        "base": "basebot",
        "joints": [{"name": "j1", "upper_rad": 0.5}],
        "bus": {"baudrate": 57600, "servos": {"j1": {"zero_offset_rad": 0.2, "direction": 1}}},
    })  # fmt: skip
    r = load_robot_config(mine)
    assert (r.name, r.base, r.base_path) == ("mine", "basebot", tmp_path / "basebot.yaml")
    assert r.joints[1].upper_rad == 0.5 and r.joints[1].lower_rad == base.joints[1].lower_rad
    assert [j.name for j in r.joints] == base.joint_names and r.joints[0] == base.joints[0]
    s = r.bus.servos["j1"]
    assert (s.zero_offset_rad, s.direction, s.id, s.model) == (0.2, 1, 2, base.bus.servos["j1"].model)
    assert r.bus.baudrate == 57600 and r.bus.family == base.bus.family and r.model_path == base.model_path
    assert r.retarget == base.retarget


def test_found_by_name_after_a_move(tmp_path, monkeypatch):
    """The copy names its base: moved to another folder it still loads (the base from the search path)."""
    make_robot(tmp_path / "lib", n_joints=2, name="basebot")
    mine = _write(tmp_path / "a" / "mine.yaml", {"base": "basebot", "joints": [{"name": "j0", "upper_rad": 0.4}]})
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path / "lib"))
    moved = tmp_path / "b" / "c" / "mine.yaml"
    moved.parent.mkdir(parents=True)
    shutil.move(mine, moved)
    assert load_robot_config(moved).joints[0].upper_rad == 0.4
    assert "mine" not in list_robots()  # not on the search path; the base is
    monkeypatch.setenv("ROBOGEST_ROBOTS", f"{tmp_path / 'lib'}:{moved.parent}")
    assert find_robot("mine").base_path == tmp_path / "lib" / "basebot.yaml"


def test_a_base_beside_the_file_wins_over_the_search_path(tmp_path, monkeypatch):
    make_robot(tmp_path / "lib", n_joints=2, name="basebot")
    make_robot(tmp_path / "own", n_joints=3, name="basebot")
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path / "lib"))
    r = load_robot_config(_write(tmp_path / "own" / "mine.yaml", {"base": "basebot"}))
    assert len(r.joints) == 3 and r.base_path == tmp_path / "own" / "basebot.yaml"


def test_a_shipped_robot_as_base_and_robots_list(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    _write(tmp_path / "so101_mine.yaml", {"base": "so101_sts3215", "joints": [{"name": "gripper", "upper_rad": 0.5}]})
    r = find_robot("so101_mine")
    assert r.model_path == find_robot("so101_sts3215").model_path and r.joints[-1].upper_rad == 0.5
    assert main(["robots", "list"]) == 0
    assert "so101_mine" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("doc", "pattern"),
    [
        ({"base": "nobot"}, r"mine\.yaml: key base: unknown robot 'nobot' \(searched .*\); known robots: .*so101"),
        ({"base": "../basebot.yaml"}, r"mine\.yaml: key base: '\.\./basebot\.yaml' is not a robot name"),
        ({"base": 3}, r"mine\.yaml: key base: 3 is not a robot name; write the name"),
        ({"base": "basebot", "joints": [{"name": "j9", "upper_rad": 0.5}]},
         r"mine\.yaml: key joints\[0\]: 'j9' is not a joint of the base robot basebot \(its joints: j0, j1\); .*"
         "cannot add any"),
        ({"base": "basebot", "joints": {"j0": {}}}, r"mine\.yaml: key joints: with base: it lists changes"),
        ({"base": "basebot", "joints": [{"name": "j0", "upper_rad": 5.0, "lower_rad": 6.0}]},
         r"mine\.yaml: invalid robot definition: key joints\[0\]: lower_rad .* \(merged onto base basebot, "),
        ({"base": "basebot", "bus": {"servos": {"jx": {"id": 9, "model": "XL430-W250"}}}},
         r"mine\.yaml: invalid robot definition: .*bus\.servos names \['jx'\]"),
    ],
    ids=["unknown", "a-path", "not-text", "added-joint", "joints-not-a-list", "bad-merged-value", "stray-servo"],
)  # fmt: skip
def test_refused_naming_the_key_and_the_file(tmp_path, doc, pattern):
    make_robot(tmp_path, n_joints=2, name="basebot")
    with pytest.raises(ConfigError, match=pattern):
        load_robot_config(_write(tmp_path / "mine.yaml", doc))


def test_loops_and_broken_bases_are_named(tmp_path):
    _write(tmp_path / "a.yaml", {"base": "b"})
    _write(tmp_path / "b.yaml", {"base": "a"})
    with pytest.raises(ConfigError, match=r"a\.yaml: key base: base robot 'b' does not load: .*b\.yaml: key base: "
                                          r"the bases loop \(.*a\.yaml -> .*b\.yaml -> .*a\.yaml\)"):  # fmt: skip
        load_robot_config(tmp_path / "a.yaml")
    _write(tmp_path / "self.yaml", {"base": "self"})  # its own folder's self.yaml is itself: not a base
    with pytest.raises(ConfigError, match=r"self\.yaml: key base: unknown robot 'self'"):
        load_robot_config(tmp_path / "self.yaml")
    (tmp_path / "broken.yaml").write_text("name: broken\nmodel: [")
    with pytest.raises(ConfigError, match=r"c\.yaml: key base: base robot 'broken' does not load: .*broken\.yaml: "
                                          "not valid YAML"):  # fmt: skip
        load_robot_config(_write(tmp_path / "c.yaml", {"base": "broken"}))


def test_every_shipped_robot_loads_as_before():
    """The schema change keeps every robots/*.yaml loading unchanged: no base, same values."""
    for name, path in list_robots().items():
        r = load_robot_config(path)
        assert r.base is None and r.base_path is None, name
        assert "base" not in yaml.safe_load(path.read_text()), name
