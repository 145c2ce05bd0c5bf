"""SIGTERM, SIGHUP and SIGQUIT outside motion unwind like Ctrl-C: half-written outputs are removed, the exit code is
128 + the signal (Python's default for them ended the process at once and left hidden temporary files behind)."""

from __future__ import annotations

import os
import signal

import pytest

import robogest.cli.robots_cmds as robots_cmds
from robogest.cli.main import main
from robogest.fileio import atomic_path


@pytest.mark.usefixtures("quit_does_not_dump_core")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT])
def test_a_signal_mid_write_removes_the_temporary_file_and_exits_128_plus_it(tmp_path, monkeypatch, capsys, sig):
    out = tmp_path / "out.csv"

    def slow_writer(args):
        with atomic_path(out, ".csv") as tmp:
            tmp.write_text("half of it")
            os.kill(os.getpid(), sig)  # delivered before the next bytecode
            tmp.write_text("all of it")
        return 0

    monkeypatch.setattr(robots_cmds, "cmd_list", slow_writer)
    before = signal.getsignal(sig)
    assert main(["robots", "list"]) == 128 + sig
    assert f"robogest: terminated by {signal.Signals(sig).name}" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # neither the output nor its temporary file
    assert signal.getsignal(sig) is before  # the command's handlers are gone again
