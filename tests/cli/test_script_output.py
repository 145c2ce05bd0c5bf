"""A CLI scripts can read: plain tab-separated tables when piped, --json, --version, quiet on a closed pipe."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

from robogest.cli.main import EXIT_BROKEN_PIPE, main

REPO = Path(__file__).resolve().parents[2]
BOX = set("─━│┃┏┓┗┛┡┩╇╈┼╭╮╰╯")


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}


def test_robots_list_piped_is_tab_separated(capsys):
    assert main(["robots", "list"]) == 0
    out = capsys.readouterr().out
    assert not BOX & set(out)
    lines = out.splitlines()
    assert lines[0] == "# robots" and lines[1] == "name\tjoints\tbus\tdescription"
    rows = {line.split("\t")[0]: line.split("\t") for line in lines[2:]}
    assert rows["humanoid_xl430 (default)"][1:3] == ["11", "dynamixel (11 servos)"]
    assert rows["desk_arm_sts3215"][1] == "5"


def test_robots_list_on_a_terminal_draws_a_table(capsys, monkeypatch):
    monkeypatch.setattr(sys.stdout, "isatty", lambda: True)
    assert main(["robots", "list"]) == 0
    assert BOX & set(capsys.readouterr().out)


def test_robots_list_json(capsys):
    assert main(["robots", "list", "--json"]) == 0
    entries = {e["name"]: e for e in json.loads(capsys.readouterr().out)}
    assert entries["humanoid_xl430"]["default"] is True and entries["humanoid_xl430"]["bus"] == "dynamixel"
    assert entries["desk_arm_sts3215"]["joints"] == 5 and entries["desk_arm_sts3215"]["error"] is None
    assert Path(entries["humanoid_sts3215"]["file"]).is_file()


def test_robots_list_json_reports_a_broken_file(tmp_path, capsys, monkeypatch):
    (tmp_path / "broken.yaml").write_text("name: broken\n")
    monkeypatch.setenv("ROBOGEST_ROBOTS", str(tmp_path))
    assert main(["robots", "list", "--json"]) == 3
    entries = {e["name"]: e for e in json.loads(capsys.readouterr().out)}
    assert "broken.yaml" in entries["broken"]["error"] and entries["humanoid_xl430"]["error"] is None


def test_robots_show_piped_and_json(capsys):
    assert main(["robots", "show", "humanoid_sts3215"]) == 0
    out = capsys.readouterr().out
    assert not BOX & set(out)
    assert "l_shoulder_pitch\t-57.3..160.4\t-1.000..2.800\t" in out
    model = next(line for line in out.splitlines() if line.startswith("model: ")).removeprefix("model: ")
    assert Path(model).is_file()  # a long path is never wrapped

    assert main(["robots", "show", "humanoid_sts3215", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    joints = {j["name"]: j for j in data["joints"]}
    assert joints["l_shoulder_pitch"]["lower_rad"] == -1.0 and joints["l_shoulder_pitch"]["upper_rad"] == 2.8
    assert data["bus"]["family"] == "feetech" and data["bus"]["servos"]["torso_yaw"]["model"] == "STS3215"
    assert Path(data["model_file"]).is_file() and data["rendered"] is None


def test_analyze_json_is_pure_json(tmp_path, capsys):
    feats = tmp_path / "f.npz"
    assert main(["analyze", "--text", "Hello there.", "--json", "--save-features", str(feats)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["features_file"] == str(feats) and feats.is_file() and summary["n_words"] == 2


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"robogest {version('robogest')}"


def test_closed_pipe_ends_quietly():
    """stdout is a pipe nobody reads (as after `| head` exits): exit 141, no traceback, nothing on stderr."""
    r, w = os.pipe()
    os.close(r)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "robogest", "robots", "show", "humanoid_xl430"],
            stdout=w, stderr=subprocess.PIPE, env=_env(), cwd=REPO, timeout=120,
        )  # fmt: skip
    finally:
        os.close(w)
    assert proc.returncode == EXIT_BROKEN_PIPE == 141
    assert proc.stderr == b""


def test_head_reads_first_line_and_stdout_is_line_buffered():
    code = (
        "import sys; from robogest.cli.main import main; rc = main(['robots', 'list']); "
        "print(sys.stdout.line_buffering, file=sys.stderr); sys.exit(rc)"
    )
    proc = subprocess.run(
        f"{sys.executable} -c \"{code}\" | head -n 1", shell=True, capture_output=True, text=True, env=_env(),
        cwd=REPO, timeout=120,
    )  # fmt: skip
    assert proc.stdout == "# robots\n"
    assert "Traceback" not in proc.stderr and proc.stderr.strip() == "True"


def test_closed_stderr_is_not_an_error(tmp_path):
    """Started with stderr closed (`robogest speak ... 2>&-`) the command ended with exit 1 and no word, before
    any motion: Python leaves sys.stderr None and the progress bar wrote to it."""
    proc = subprocess.run(
        [sys.executable, "-m", "robogest", "speak", "Hi", "--save", str(tmp_path / "s.npz")],
        stdout=subprocess.PIPE, preexec_fn=lambda: os.close(2), env=_env(), cwd=tmp_path, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout
    assert "sim tracking error" in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.npz", "s.wav"]


def test_closed_stdout_is_not_an_error():
    """Started with stdout closed (`robogest robots list >&-`) main's first look at sys.stdout (None) was a
    traceback; the output goes nowhere, as it would to /dev/null."""
    proc = subprocess.run(
        [sys.executable, "-m", "robogest", "robots", "list"],
        stderr=subprocess.PIPE, preexec_fn=lambda: os.close(1), env=_env(), cwd=REPO, timeout=120,
    )  # fmt: skip
    assert (proc.returncode, proc.stderr) == (0, b"")
