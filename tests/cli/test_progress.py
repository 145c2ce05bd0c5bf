"""Progress of long commands: plain lines when stderr is a pipe or file, quiet for short runs."""

from __future__ import annotations

import io
import sys

from robogest.cli.progress import QUIET_FIRST_S, progress_bar, progress_lines


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_lines_every_ten_percent_after_the_quiet_start():
    clock, out = FakeClock(), io.StringIO()
    update = progress_lines("simulating", stream=out, clock=clock)
    update(10, 200)  # before QUIET_FIRST_S: nothing
    clock.t += QUIET_FIRST_S
    for done in range(11, 201):
        update(done, 200)
    lines = out.getvalue().splitlines()
    assert lines[0] == "robogest: simulating: 0% (11/200)"
    assert lines[-1] == "robogest: simulating: 100% (200/200)"
    assert [int(line.split(": ")[2].split("%")[0]) for line in lines] == list(range(0, 101, 10))


def test_short_runs_print_nothing():
    out = io.StringIO()
    update = progress_lines("playing", stream=out, clock=FakeClock())
    for done in range(1, 51):
        update(done, 50)
    assert out.getvalue() == ""


def test_a_closed_stream_stops_the_lines_not_the_work():
    clock, out = FakeClock(), io.StringIO()
    update = progress_lines("playing", stream=out, clock=clock)
    clock.t += QUIET_FIRST_S
    out.close()
    for done in range(1, 101):
        update(done, 100)  # no exception


def test_progress_bar_writes_lines_to_a_log_file(tmp_path, monkeypatch):
    log = tmp_path / "err.log"
    with log.open("w") as f:
        monkeypatch.setattr(sys, "stderr", f)
        monkeypatch.setattr("robogest.cli.progress.QUIET_FIRST_S", 0.0)
        with progress_bar("simulating") as cb:
            for done in range(1, 21):
                cb(done, 20)
    assert log.read_text().splitlines()[-1] == "robogest: simulating: 100% (20/20)"


def test_progress_bar_is_quiet_when_stderr_is_captured_in_process(capsys):
    with progress_bar("simulating") as cb:
        cb(5, 5)
    assert capsys.readouterr().err == ""


def test_eta_lines_say_how_long_the_rest_takes_from_the_rate_since_the_first_update():
    """With ``eta`` (a video render): the set-up before the first update does not count; no line before an estimate
    from a second of work; each line then says the time left at the rate so far."""
    clock, out = FakeClock(), io.StringIO()
    update = progress_lines("simulating + rendering", stream=out, clock=clock, eta=True)
    clock.t += 5.0  # renderer set-up: not part of the rate
    update(0, 100)
    for done in range(5, 101, 5):
        clock.t += 0.5  # 10 units a second: 10 s in all
        update(done, 100)
    lines = out.getvalue().splitlines()
    assert lines[0] == "robogest: simulating + rendering: 10% (10/100), about 9 s left"
    assert lines[4] == "robogest: simulating + rendering: 50% (50/100), about 5 s left"
    assert lines[-1] == "robogest: simulating + rendering: 100% (100/100)"
    assert len(lines) == 10
