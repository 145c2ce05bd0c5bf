"""--export: ROS 2 bags (read back with rosbags) and CSV carry the same names, times and positions as the trajectory."""

from __future__ import annotations

import dataclasses
import re
import sys

import numpy as np
import pytest

from robogest.cli.main import main
from robogest.errors import InputError, MissingDependencyError
from robogest.trajectory import Trajectory
from robogest.trajectory.export import COMMANDS_TOPIC, TRAJECTORY_TOPIC, export_trajectory

JOINTS = ["a_joint", "b_joint", "c_joint"]


def _traj(n: int = 75, fps: float = 50.0) -> Trajectory:
    t = np.arange(n) / fps
    q = np.column_stack([0.3 * np.sin(2 * np.pi * t), -0.2 * t, np.full(n, 0.1)])
    silent = np.zeros(n, dtype=bool)
    silent[40:60] = True
    lim = np.ones(3)
    return Trajectory(t, q, JOINTS, -lim, lim, lim, lim, np.zeros(3), silent, robot="test_bot")


def _read_bag(path):
    rosbags = pytest.importorskip("rosbags")  # noqa: F841  (in the dev extras; the test needs it to read back)
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        msgs: dict[str, list] = {}
        for conn, t_ns, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append((t_ns, reader.deserialize(raw, conn.msgtype)))
    return topics, msgs


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


@pytest.mark.parametrize("name", ["out.mcap", "bag_folder"])
def test_bag_round_trip(tmp_path, name):
    traj = _traj()
    path = export_trajectory(traj, tmp_path / "sub" / name)
    assert path.is_file() if name.endswith(".mcap") else (path / "metadata.yaml").is_file()
    topics, msgs = _read_bag(path)
    assert topics == {
        TRAJECTORY_TOPIC: "trajectory_msgs/msg/JointTrajectory",
        COMMANDS_TOPIC: "sensor_msgs/msg/JointState",
    }
    expected_ns = [round(k * 20_000_000) for k in range(traj.n_frames)]  # 50 Hz on the audio clock, exactly

    ((t0, whole),) = msgs[TRAJECTORY_TOPIC]
    assert t0 == 0 and _ns(whole.header.stamp) == 0 and list(whole.joint_names) == JOINTS
    assert [_ns(p.time_from_start) for p in whole.points] == expected_ns
    np.testing.assert_array_equal(np.stack([p.positions for p in whole.points]), traj.q_rad)

    cmds = msgs[COMMANDS_TOPIC]
    assert [t for t, _ in cmds] == expected_ns == [_ns(m.header.stamp) for _, m in cmds]
    assert all(list(m.name) == JOINTS for _, m in cmds)
    np.testing.assert_array_equal(np.stack([m.position for _, m in cmds]), traj.q_rad)


def test_csv_round_trip(tmp_path):
    traj = _traj()
    path = export_trajectory(traj, tmp_path / "t.csv")
    header = path.read_text().splitlines()[0]
    assert header == "t_s,silent,a_joint_rad,b_joint_rad,c_joint_rad"
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 0], traj.t_s, atol=1e-6)
    np.testing.assert_array_equal(table[:, 1].astype(bool), traj.silent)
    np.testing.assert_allclose(table[:, 2:], traj.q_rad, atol=1e-9)


def test_csv_header_quotes_a_joint_name_with_a_comma(tmp_path):
    import csv

    traj = dataclasses.replace(_traj(), joint_names=["a,b", 'say "hi"', "c"])
    path = export_trajectory(traj, tmp_path / "t.csv")
    rows = list(csv.reader(path.read_text().splitlines()))
    assert rows[0] == ["t_s", "silent", "a,b_rad", 'say "hi"_rad', "c_rad"]
    assert {len(r) for r in rows} == {5}


def test_existing_bag_folder_is_never_overwritten(tmp_path):
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "keep.txt").write_text("mine")
    with pytest.raises(InputError, match=r"bag: already exists; a bag folder is never overwritten"):
        export_trajectory(_traj(), tmp_path / "bag")
    assert (tmp_path / "bag" / "keep.txt").read_text() == "mine"


def test_unknown_suffix(tmp_path):
    with pytest.raises(InputError, match=r"t\.json: unknown format '\.json'; write FILE\.mcap"):
        export_trajectory(_traj(), tmp_path / "t.json")


def test_missing_rosbags_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)  # import fails as if not installed
    with pytest.raises(MissingDependencyError, match=r"rosbags library: .*pip install -e '.*\[ros\]'"):
        export_trajectory(_traj(), tmp_path / "t.mcap")
    assert not (tmp_path / "t.mcap").exists() and list(tmp_path.iterdir()) == []


def test_speak_and_play_export(tmp_path, capsys):
    """Both commands, on the sim: the bag holds exactly the saved command trajectory."""
    saved, bag, csv = tmp_path / "hi.npz", tmp_path / "hi.mcap", tmp_path / "replay.csv"
    assert main(["speak", "Hello there.", "--save", str(saved), "--export", str(bag)]) == 0
    assert f"exported: {bag}" in capsys.readouterr().out
    traj = Trajectory.load(saved)
    _, msgs = _read_bag(bag)
    ((_, whole),) = msgs[TRAJECTORY_TOPIC]
    assert list(whole.joint_names) == traj.joint_names
    np.testing.assert_array_equal(np.stack([p.positions for p in whole.points]), traj.q_rad)
    assert [t for t, _ in msgs[COMMANDS_TOPIC]] == list(np.rint(traj.t_s * 1e9).astype(int))

    assert main(["play", str(saved), "--export", str(csv)]) == 0
    np.testing.assert_allclose(np.loadtxt(csv, delimiter=",", skiprows=1)[:, 2:], traj.q_rad, atol=1e-9)


def test_speak_missing_rosbags_is_exit_6(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)
    assert main(["speak", "Hi.", "--export", str(tmp_path / "x.mcap")]) == 6
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(r"pip install -e '.*\[ros\]'", err[0])


def test_bad_export_fails_before_anything_runs(tmp_path, capsys, monkeypatch):
    import robogest.pipeline

    def must_not_run(*a, **k):
        raise AssertionError("the pipeline ran before --export was checked")

    monkeypatch.setattr(robogest.pipeline, "speak", must_not_run)
    (tmp_path / "old_bag").mkdir()
    assert main(["speak", "Hi.", "--export", str(tmp_path / "t.txt")]) == 2
    assert main(["speak", "Hi.", "--export", str(tmp_path / "old_bag")]) == 2
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)
    assert main(["speak", "Hi.", "--export", str(tmp_path / "t.mcap")]) == 6
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and "unknown format '.txt'" in err[0] and "already exists" in err[1]
