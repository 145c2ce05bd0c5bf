"""``robogest robots list|show``."""

from __future__ import annotations

from robogest.cli.main import main


def test_list(capsys):
    assert main(["robots", "list"]) == 0
    out = capsys.readouterr().out
    for name in ("humanoid_xl430", "humanoid_sts3215", "desk_arm_sts3215", "so101_sts3215"):
        assert name in out
    assert "dynamixel" in out and "feetech" in out


def test_show(capsys):
    assert main(["robots", "show", "humanoid_sts3215"]) == 0
    out = capsys.readouterr().out
    assert "l_shoulder_pitch" in out and "-57.3..160.4" in out and "STS3215" in out and "nose_site" in out


def test_show_unknown_robot(capsys):
    assert main(["robots", "show", "no_such_robot"]) == 3
    err = capsys.readouterr().err
    assert "unknown robot 'no_such_robot'" in err and "humanoid_xl430" in err


def test_show_render(tmp_path, capsys):
    out = tmp_path / "r.png"
    rc = main(["robots", "show", "desk_arm_sts3215", "--render", str(out), "--size", "160x120"])
    assert rc in (0, 6)  # 6 = no offscreen GL on this machine (MissingDependencyError)
    assert out.is_file() == (rc == 0)
