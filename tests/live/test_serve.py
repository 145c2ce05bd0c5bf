"""`robogest serve` in its own process, driven by a real WebSocket client from this one."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from robogest.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
TOKEN = "s3cret"


def _start(*extra: str) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-m", "robogest", "serve", "--listen", "127.0.0.1:0", "--no-idle", *extra]
    if "--token" not in extra:
        cmd = [*cmd, "--token", TOKEN]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    line = proc.stdout.readline()  # blocks until ready (or the process died)
    if "ready on" not in line:
        proc.kill()
        raise AssertionError(f"serve did not start: {line!r} {proc.stderr.read()}")
    return proc, line.split("ready on ")[1].split()[0]


@pytest.fixture(scope="module")
def server():
    proc, url = _start(
        "--token", TOKEN, "--allow-origin", "http://localhost:3000", "--time-scale", "2", "--max-clients", "3",
        "--stream-buffer-s", "3",
    )  # fmt: skip
    yield proc, url
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)


def _client(url: str, **kw):
    return connect(url, additional_headers={"Authorization": f"Bearer {TOKEN}"}, open_timeout=30, **kw)


_EVENTS: dict[int, list[str]] = {}  # utterance -> events received so far (whoever was waiting for what)


def _next(ws, deadline: float) -> dict:
    msg = json.loads(ws.recv(timeout=max(0.1, deadline - time.monotonic())))
    if msg["type"] == "event":
        _EVENTS.setdefault(msg["utterance"], []).append(msg["event"])
    return msg


def _recv(ws, want: str, timeout_s: float = 60.0) -> dict:
    """Next message of type ``want`` (others are skipped; events are kept in _EVENTS)."""
    deadline = time.monotonic() + timeout_s
    while True:
        msg = _next(ws, deadline)
        if msg["type"] == want:
            return msg


def _until_event(ws, utterance: int, event: str, timeout_s: float = 120.0) -> set[str]:
    """Wait until ``utterance`` reported ``event``; all its events so far."""
    deadline = time.monotonic() + timeout_s
    while event not in _EVENTS.get(utterance, []):
        _next(ws, deadline)
    return set(_EVENTS[utterance])


def test_malformed_messages_get_errors_and_the_session_keeps_running(server):
    _, url = server
    with _client(url) as ws:
        hello = _recv(ws, "hello")
        assert hello["protocol"] == 1 and hello["robot"] == "humanoid_xl430" and hello["open"]
        for bad, match in [
            ("{not json", "not JSON"),
            ('["say"]', 'string "type"'),
            ('{"type": "dance"}', "unknown message type 'dance'"),
            ('{"type": "say", "text": 3}', '"text" must be a string'),
            ('{"type": "stream_start", "format": "mp3"}', "not supported"),
            ('{"type": "stream_end"}', "without an open stream"),
        ]:
            ws.send(bad)
            assert match in _recv(ws, "error")["message"]
        ws.send(b"\x00\x01\x02")  # PCM with no stream open
        assert "stream_start" in _recv(ws, "error")["message"]
        for bad, match in [  # what Python's decoder cannot take is an error naming it, not an "internal error"
            ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
            ('{"type": "say", "text": "hi", "id": ' + "9" * 5000 + "}", "number too long"),
            ('{"type": "say", "text": "hi", "id": ' + "9" * 4000 + "}", '"id" must be'),
            (json.dumps({"type": "say", "text": "word " * 1001}), "5005 characters is over the limit of 5000"),
        ]:
            ws.send(bad)
            msg = _recv(ws, "error")["message"]
            assert match in msg and "internal error" not in msg
        ws.send('{"type": "say"}')  # neither text nor audio: the pipeline's own one-line error
        assert "either text to speak" in _recv(ws, "error")["message"]
        ws.send('{"type": "status"}')
        status = _recv(ws, "status")
        assert status["open"] and len(status["goal_rad"]) == 11


def test_say_stream_and_interrupt_push_events(server):
    _, url = server
    with _client(url) as ws:
        _recv(ws, "hello")
        ws.send(json.dumps({"type": "say", "text": "Hi there.", "id": "a"}))
        acc = _recv(ws, "accepted")
        assert acc["id"] == "a"
        seen = _until_event(ws, acc["utterance"], "done")
        assert {"requested", "first_goal", "started", "audio_start", "done"} <= seen

        # streamed speech: 20 ms int16 frames of a voiced tone with pauses
        sr = 16000
        t = np.arange(int(1.5 * sr)) / sr
        tone = 0.3 * np.sin(2 * np.pi * 160 * t) * (np.sin(2 * np.pi * 2.5 * t) > -0.3)
        pcm = np.round(tone * 32767).astype("<i2").tobytes()
        ws.send(json.dumps({"type": "stream_start", "sample_rate": sr, "format": "int16"}))
        acc = _recv(ws, "accepted")
        for i in range(0, len(pcm), 640):
            ws.send(pcm[i : i + 640])
        ws.send(json.dumps({"type": "words", "words": [["hello", 0.1, 0.5]]}))
        ws.send(json.dumps({"type": "stream_end"}))
        seen = _until_event(ws, acc["utterance"], "done")
        assert {"first_chunk", "first_goal", "started", "audio_chunk", "done"} <= seen

        ws.send(json.dumps({"type": "say", "text": "This sentence is interrupted before it ends, on purpose."}))
        acc = _recv(ws, "accepted")
        _until_event(ws, acc["utterance"], "first_goal")
        ws.send('{"type": "interrupt"}')
        res = _recv(ws, "interrupted")
        assert res["at_rest_s"] >= res["interrupt_s"]
        assert "done" not in _until_event(ws, acc["utterance"], "interrupted")


def test_say_and_stream_start_take_per_call_body_language_and_name_a_bad_field(server):
    _, url = server
    with _client(url) as ws:
        _recv(ws, "hello")
        for bad, match in [
            ({"type": "say", "text": "Hi.", "amount": 5}, 'say: "amount" must be a number within [0, 2]'),
            ({"type": "say", "text": "Hi.", "style": "wild"}, "say: \"style\" 'wild' is not one of calm"),
            ({"type": "say", "text": "Hi.", "style": "calm", "amount": 1}, '"style" or "amount", not both'),
            ({"type": "stream_start", "gestures": 3}, 'stream_start: "gestures" must be'),
            ({"type": "stream_start", "gestures": "/no/such/units"}, '"gestures" /no/such/units: no such folder'),
        ]:
            ws.send(json.dumps(bad))
            assert match in _recv(ws, "error")["message"]
        ws.send(json.dumps({"type": "say", "audio": "/no/such/speech.wav", "id": 7}))  # fails while prepared
        assert "/no/such/speech.wav" in _recv(ws, "error")["message"]
        ws.send(json.dumps({"type": "say", "text": "Calm now.", "style": "calm", "gestures": "none", "id": "c"}))
        acc = _recv(ws, "accepted")
        assert acc["id"] == "c" and "done" in _until_event(ws, acc["utterance"], "done")
        ws.send(json.dumps({"type": "stream_start", "sample_rate": 16000, "amount": 0.5}))
        acc = _recv(ws, "accepted")
        ws.send(json.dumps({"type": "stream_end"}))
        _until_event(ws, acc["utterance"], "interrupted")  # no speech came: nothing to play


def test_a_long_say_holds_another_clients_short_one_no_longer_than_it_plays(server):
    """Says are queued per client and served in turn: client A's second long say comes after B's short one, which
    waits only for the one playing (utterance ids are given in the order says start)."""
    _, url = server
    long = "This is a long answer with several parts, and it goes on for a while before it ends. " * 2
    with _client(url) as a, _client(url) as b:
        _recv(a, "hello")
        _recv(b, "hello")
        a.send(json.dumps({"type": "say", "text": long, "id": "a1"}))
        a.send(json.dumps({"type": "say", "text": long, "id": "a2"}))
        first = _recv(a, "accepted")
        assert first["id"] == "a1"
        b.send(json.dumps({"type": "say", "text": "Quick hello.", "id": "b1"}))
        b.send(json.dumps({"type": "status"}))
        assert _recv(b, "status")["says_queued"] == 2
        quick = _recv(b, "accepted")
        assert "done" in _until_event(a, first["utterance"], "done")  # it was played to its end, not replaced
        second = _recv(a, "accepted")
        assert second["id"] == "a2" and first["utterance"] < quick["utterance"] < second["utterance"], (
            first,
            quick,
            second,
        )
        assert "done" in _until_event(b, quick["utterance"], "done")
        _until_event(a, second["utterance"], "done")


def test_a_stream_fed_far_ahead_of_playback_is_refused_and_the_session_keeps_running(server):
    _, url = server
    sr = 16000
    pcm = np.round(0.2 * np.sin(2 * np.pi * 150 * np.arange(8 * sr) / sr) * 32767).astype("<i2").tobytes()
    with _client(url) as ws:
        _recv(ws, "hello")
        ws.send(json.dumps({"type": "stream_start", "sample_rate": sr}))
        acc = _recv(ws, "accepted")
        for i in range(0, len(pcm), 3200):  # 8 s of audio at once: over the server's 3 s buffer
            ws.send(pcm[i : i + 3200])
        assert "over the 3 s limit (--stream-buffer-s)" in _recv(ws, "error", timeout_s=30)["message"]
        ws.send(json.dumps({"type": "stream_end"}))
        _until_event(ws, acc["utterance"], "done")
        ws.send(json.dumps({"type": "status"}))
        assert _recv(ws, "status")["open"]


def test_clients_over_the_limit_get_an_error_and_the_session_keeps_running(server):
    _, url = server
    with contextlib.ExitStack() as stack:
        replies = []
        for _ in range(4):  # the server takes 3
            ws = stack.enter_context(_client(url))
            replies.append(_next(ws, time.monotonic() + 30))
        busy = [m for m in replies if m["type"] == "error"]
        assert busy and all("server busy" in m["message"] and "--max-clients" in m["message"] for m in busy)
        assert sum(m["type"] == "hello" for m in replies) <= 3
    with _client(url) as ws:
        assert _recv(ws, "hello")["open"]


def test_handshakes_without_token_or_from_a_web_page_are_refused(server):
    _, url = server
    with pytest.raises(InvalidStatus) as e:
        connect(url, open_timeout=30)
    assert e.value.response.status_code == 401
    with pytest.raises(InvalidStatus) as e:
        _client(url, origin="http://evil.example")
    assert e.value.response.status_code == 403
    with _client(url, origin="http://localhost:3000") as ws:  # explicitly allowed
        assert _recv(ws, "hello")["open"]
    with connect(url + f"?token={TOKEN}", open_timeout=30) as ws:
        assert _recv(ws, "hello")["open"]
    with connect(url, additional_headers={"Authorization": f"bearer {TOKEN}"}, open_timeout=30) as ws:
        assert _recv(ws, "hello")["open"]  # the scheme's case does not matter (RFC 7235)


def test_says_sent_before_an_interrupt_never_start_after_it(server):
    """A client that queued replies and then barges in: what it asked for before the interrupt never moves the
    robot afterwards (queued says are dropped, the one being prepared is abandoned), whatever the order."""
    _, url = server
    with _client(url) as ws:
        _recv(ws, "hello")
        for k in range(4):
            ws.send(json.dumps({"type": "say", "text": f"Reply number {k} is a fairly long sentence.", "id": k}))
        ws.send('{"type": "interrupt"}')
        replies, deadline = [], time.monotonic() + 60
        while sum(m["type"] in ("accepted", "error") for m in replies) < 4:
            replies.append(_next(ws, deadline))
        assert any(m["type"] == "interrupted" for m in replies) or _recv(ws, "interrupted")
        dropped = [m for m in replies if m["type"] == "error"]
        assert all("dropped, an interrupt came before it started" in m["message"] for m in dropped)
        for m in (m for m in replies if m["type"] == "accepted"):
            assert "started" not in _until_event(ws, m["utterance"], "interrupted")
        ws.send(json.dumps({"type": "status"}))
        assert not _recv(ws, "status")["speaking"]
    # a client that vanishes without a closing handshake: the server carries on, and prints no traceback (its
    # stderr is read by the SIGTERM test below)
    with contextlib.suppress(Exception), _client(url) as ws:
        _recv(ws, "hello")
        ws.socket.close()


def test_sigterm_ends_the_server_at_rest_with_torque_off(server):
    proc, _ = server
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(60) == 143
    err = proc.stderr.read()
    assert "SIGTERM" in err and "Traceback" not in err and "connection handler failed" not in err
    assert "leak" not in err  # nanobind's report of native objects alive at interpreter teardown
    # the log (serve's default level is info): connections with address and origin, requests, refusals, interrupts
    assert "connected (origin http://localhost:3000)" in err and "connected (origin None)" in err
    assert "say accepted as utterance" in err and "stream accepted as utterance" in err
    assert "missing or wrong token" in err and "the most --max-clients allows" in err
    assert re.search(r"interrupt; at rest \d+\.\d\d s after it", err)


NO_SERVO = ["--backend", "dynamixel", "--port", "/dev/robogest-no-such-port"]  # a robot that would fail to open


def test_non_loopback_listen_needs_a_token(capsys):
    for where in ("0.0.0.0:8765", "127.0.0.2:8765", "[::ffff:127.0.0.1]:8765"):
        assert main(["serve", "--listen", where, *NO_SERVO]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--token" in err[-1] and where.split("]")[0].strip("[") in err[-1]
    assert main(["serve", "--listen", "nonsense"]) == 2


def test_a_busy_address_is_one_line_before_the_robot_is_touched(capsys):
    """The socket is bound before the robot opens: a second serve on the same address never turns torque on."""
    import socket

    with socket.create_server(("127.0.0.1", 0)) as busy:
        port = busy.getsockname()[1]
        assert main(["serve", "--listen", f"127.0.0.1:{port}", *NO_SERVO]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"127.0.0.1:{port}: cannot listen there" in err[0] and "no-such-port" not in err[0]


def test_a_numeric_port_is_refused_with_a_hint_to_listen(capsys):
    assert main(["serve", "--backend", "dynamixel", "--port", "8766"]) == 2  # (it opened serial port "8766")
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--listen 127.0.0.1:8766" in err[0]


def _vanish_first_servo(bus) -> int:
    sid = bus.servos[0].id
    bus.servo(sid).vanished = True
    return sid


def test_a_dead_session_is_told_to_every_client_at_once_and_refuses_new_work():
    """Python API: a servo vanishes; before any say, every client hears ``session_lost``, ``status`` says why, says
    and streams are refused naming it; when reopening fails, ``run`` ends with a BackendError (exit 5)."""
    import asyncio
    import threading

    from robogest.errors import BackendError
    from robogest.live import Robot
    from robogest.live.server import Server
    from robogest.robot.registry import find_robot
    from robogest.virtualbus import VirtualBus

    release, reopened = threading.Event(), []

    def reopen():
        reopened.append(True)
        release.wait(30)
        raise BackendError("servo id 1 does not answer")

    opts = {"lost_after_s": 0.3, "health_hz": 0}
    with VirtualBus(find_robot("humanoid_xl430")) as bus, Robot(
        "humanoid_xl430", backend="dynamixel", port=bus.port, idle=False, warm_up=False, backend_options=opts
    ) as robot:  # fmt: skip
        server = Server(robot, "127.0.0.1", 0, reopen=reopen)
        ready, outcome = threading.Event(), []

        def run() -> None:
            try:
                asyncio.run(server.run(lambda h, p: ready.set()))
            except BaseException as e:
                outcome.append(e)

        th = threading.Thread(target=run, daemon=True)
        th.start()
        assert ready.wait(30)
        url = f"ws://127.0.0.1:{server.port}"
        with connect(url, open_timeout=30) as a, connect(url, open_timeout=30) as b:
            assert _recv(a, "hello")["error"] is None and _recv(b, "hello")["open"]
            sid = _vanish_first_servo(bus)
            for ws in (a, b):  # no message sent: the server tells them itself
                assert f"servo id {sid}" in _recv(ws, "session_lost", timeout_s=20)["message"]
            a.send(json.dumps({"type": "status"}))
            st = _recv(a, "status")
            assert not st["open"] and f"servo id {sid}" in st["error"]
            a.send(json.dumps({"type": "say", "text": "Hello?"}))
            assert "say: refused, the robot session was lost" in _recv(a, "error")["message"]
            b.send(json.dumps({"type": "stream_start", "sample_rate": 16000}))
            assert "stream_start: refused, the robot session was lost" in _recv(b, "error")["message"]
            deadline = time.monotonic() + 30
            while not reopened and time.monotonic() < deadline:  # tried once, in a worker thread
                time.sleep(0.05)
            assert reopened == [True]
            release.set()
            th.join(30)
        assert len(outcome) == 1 and isinstance(outcome[0], BackendError)
        assert outcome[0].exit_code == 5 and "robot session lost" in str(outcome[0])


def test_serve_exits_5_when_a_servo_vanishes_and_the_session_cannot_reopen():
    """CLI: the death is logged at once, clients hear of it, and the process exits 5 (it went on serving and
    exited 130 on Ctrl-C)."""
    from robogest.robot.registry import find_robot
    from robogest.virtualbus import VirtualBus

    with VirtualBus(find_robot("humanoid_xl430")) as bus:
        proc, url = _start("--backend", "dynamixel", "--port", bus.port)
        try:
            with _client(url) as ws:
                _recv(ws, "hello")
                sid = _vanish_first_servo(bus)
                assert f"servo id {sid}" in _recv(ws, "session_lost", timeout_s=20)["message"]
                with pytest.raises(ConnectionClosed):
                    while True:
                        _next(ws, time.monotonic() + 60)
            assert proc.wait(60) == 5
        finally:
            if proc.poll() is None:
                proc.kill()
        err = proc.stderr.read()
    assert re.search(rf"ERROR: robot session lost: .*servo id {sid}", err)
    assert "reopening the robot session once" in err and "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("robogest: error:")]
    assert len(errors) == 1 and errors[0].startswith("robogest: error: robot session lost")


def test_log_level_quiets_the_servers_log():
    """serve logs at info by default (the SIGTERM test above reads it); --log-level warning keeps only problems."""
    proc, url = _start("--log-level", "warning")
    try:
        with _client(url) as ws:
            _recv(ws, "hello")
            ws.send('{"type": "dance"}')
            _recv(ws, "error")
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
    err = proc.stderr.read()
    assert "WARNING" in err and "unknown message type 'dance'" in err
    assert "INFO" not in err and "connected" not in err


def test_sigquit_mid_say_ends_the_server_at_rest_like_sigterm():
    """Ctrl-\\ (SIGQUIT) reached serve through Python's handler, not the event loop's, so mid-say it could be raised
    inside an asyncio task; it is taken like SIGTERM: at rest, torque off, exit 131, no traceback."""
    proc, url = _start()
    try:
        with _client(url) as ws:
            _recv(ws, "hello")
            ws.send(json.dumps({"type": "say", "text": "This is a sentence long enough to be cut short."}))
            n = _recv(ws, "accepted")["utterance"]
            _until_event(ws, n, "first_goal")
            proc.send_signal(signal.SIGQUIT)
            assert proc.wait(60) == 131
    finally:
        if proc.poll() is None:
            proc.kill()
    err = proc.stderr.read()
    assert "SIGQUIT" in err and "Traceback" not in err and "connection handler failed" not in err
