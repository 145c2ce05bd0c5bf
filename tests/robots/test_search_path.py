"""Where robots are found: $ROBOGEST_ROBOTS, then ./robots, then the packaged robots; the first folder wins."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

from robogest.errors import ConfigError
from robogest.robot.registry import find_robot, list_robots, robots_dir, search_path


def _copy_as(folder: Path, description: str, name: str = "humanoid_xl430") -> Path:
    """The shipped humanoid under ``name``, its model path made absolute so it loads from anywhere."""
    src = robots_dir() / "humanoid_xl430.yaml"
    raw = yaml.safe_load(src.read_text())
    raw["model"] = str((src.parent / raw["model"]).resolve())
    raw["description"] = description
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{name}.yaml"
    out.write_text(yaml.safe_dump(raw))
    return out


def test_packaged_robots_are_found_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.delenv("ROBOGEST_ROBOTS", raising=False)
    monkeypatch.chdir(tmp_path)
    assert {"humanoid_xl430", "humanoid_sts3215", "desk_arm_sts3215"} <= set(list_robots())
    assert find_robot("desk_arm_sts3215").model_path.is_file()


def test_order_env_then_cwd_then_packaged(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("ROBOGEST_ROBOTS", raising=False)
    _copy_as(tmp_path / "robots", "from cwd")
    _copy_as(tmp_path / "robots", "cwd only", name="my_bot")
    assert find_robot("humanoid_xl430").description == "from cwd"  # ./robots beats the packaged one
    assert find_robot("my_bot").description == "cwd only"
    assert find_robot("humanoid_sts3215").path.parent == robots_dir()  # the rest still come from the package

    _copy_as(tmp_path / "env2", "from env2")
    _copy_as(tmp_path / "env1", "from env1")
    monkeypatch.setenv("ROBOGEST_ROBOTS", os.pathsep.join([str(tmp_path / "env1"), str(tmp_path / "env2")]))
    assert find_robot("humanoid_xl430").description == "from env1"  # first env folder beats all
    assert search_path()[:3] == [tmp_path / "env1", tmp_path / "env2", tmp_path / "robots"]
    assert search_path()[-1] == robots_dir()


def test_unknown_robot_names_the_folders_searched(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path / "mine"))
    with pytest.raises(ConfigError, match=r"unknown robot 'nobot'.*searched .*mine, .*robots"):
        find_robot("nobot")


def test_a_yml_robot_is_found_by_name_and_yaml_wins_a_tie(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path / "mine"))
    _copy_as(tmp_path / "mine", "short suffix", name="ymlbot").rename(tmp_path / "mine" / "ymlbot.yml")
    assert "ymlbot" in list_robots() and find_robot("ymlbot").description == "short suffix"
    _copy_as(tmp_path / "mine", "long suffix", name="ymlbot")
    assert find_robot("ymlbot").description == "long suffix"
