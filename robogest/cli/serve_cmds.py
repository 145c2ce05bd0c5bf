"""``robogest serve``: a live robot session behind a local WebSocket server (protocol: robogest/live/server.py)."""

from __future__ import annotations

import argparse

from robogest.cli import checks
from robogest.cli.common import generator_options
from robogest.cli.main import add_log_level
from robogest.errors import InputError
from robogest.robot.registry import DEFAULT_ROBOT

SERVE_EPILOG = """protocol (JSON text frames; binary frames are PCM of the open stream):
  -> {"type": "say", "text": "Hello!"}      {"type": "say", "audio": "/abs/reply.wav", "transcript": "..."}
  -> {"type": "stream_start", "sample_rate": 16000, "format": "int16"}, binary PCM frames, {"type": "stream_end"}
  -> {"type": "interrupt"}                  {"type": "status"}
  <- {"type": "accepted", "utterance": N}   {"type": "event", "utterance": N, "event": "first_goal", ...}
  <- {"type": "error", "message": "..."}    (malformed or refused messages never stop the session)
  <- {"type": "session_lost", "message": "..."}  the robot's session died (a servo lost): it is reopened once,
                                            or the server exits 5

Says are queued per client and served in turn (round-robin), each played to its end before the next; streams
start at once. Over a limit (--max-clients, --max-say-chars, --stream-buffer-s, 1 MiB per message) a client gets
an error and the robot's session carries on. Logs (stderr): connections, requests, refusals, interrupts.

Streamed speech uses the default `rhythm` generator with a look-ahead of 0.25 s; learned generators
(--generator with --checkpoint) are batch-only: they serve "say" messages only. Speech audio is played
through sounddevice (the audio extra) when an output device exists; otherwise the events
carry the time each stretch of audio should start. Ctrl-C or SIGTERM: the robot glides to rest, torque off.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="keep a robot session open and take speech over a local WebSocket (say, stream, interrupt)",
        description="One robot session (torque on, idle motion between utterances) serving other processes "
        "over WebSocket. Listens on 127.0.0.1 only unless --listen names another address; any but 127.0.0.1, ::1 "
        "and localhost needs --token. "
        "Handshakes that carry an Origin header (every browser sends one) are refused unless --allow-origin "
        "names it, so a web page cannot move the robot.",
        epilog=SERVE_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--robot", default=DEFAULT_ROBOT, help="robot name or YAML path (default: %(default)s)")
    p.add_argument("--backend", default="sim", help="sim (MuJoCo, real time, default), dynamixel or feetech")
    p.add_argument(
        "--port", help="serial port for dynamixel/feetech (default: the robot YAML's bus.port); the address to listen "
        "on is --listen",
    )  # fmt: skip
    p.add_argument("--baud", type=checks.baud, help="baud rate (default: the robot YAML's bus.baudrate)")
    p.add_argument("--listen", default="127.0.0.1:8765", metavar="HOST:PORT", help="address (default: %(default)s)")
    p.add_argument("--token", help="shared secret clients must send (Authorization: Bearer T, or ?token=T)")
    p.add_argument(
        "--allow-origin", action="append", default=[], metavar="ORIGIN",
        help="accept browser handshakes from this Origin, e.g. http://localhost:3000 (repeatable)",
    )  # fmt: skip
    p.add_argument(
        "--max-clients", type=checks.number(1, 1000, integer=True), metavar="N",
        help="clients connected at once; one more gets an error (default: 8)",
    )  # fmt: skip
    p.add_argument(
        "--max-say-chars", type=checks.number(1, 10**6, integer=True), metavar="N",
        help="longest say text, characters (default: 5000, about 5 minutes of speech)",
    )  # fmt: skip
    p.add_argument(
        "--stream-buffer-s", type=checks.number(1.0, 600.0, "s"), metavar="SECONDS",
        help="audio a stream may hold ahead of what has played; a chunk past it is refused (default: 60)",
    )  # fmt: skip
    p.add_argument("--no-idle", action="store_true", help="hold rest between utterances (no breathing motion)")
    p.add_argument("--generator", default="rhythm", help="generator for say messages (default: %(default)s)")
    p.add_argument("--checkpoint", metavar="FILE", help="trained weights for a learned generator")
    p.add_argument("--seed", type=checks.seed, default=0, help="random seed of the gesture choices, 0..2**32-1")
    p.add_argument(
        "--stop-within", type=checks.number(0.1, 10.0, "s"), default=0.45, metavar="SECONDS",
        help="keep the robot within SECONDS of standing at rest, so an interrupt is at rest within it; larger "
        "gestures are cut short (default: %(default)s)",
    )  # fmt: skip
    p.add_argument(
        "--full-gestures", action="store_true",
        help="no stop envelope: gestures as large as the joint limits allow (an interrupt then takes as long as the "
        "limits make it)",
    )  # fmt: skip
    # tests: faster than real time
    p.add_argument("--time-scale", type=checks.number(0.1, 100.0), default=1.0, help=argparse.SUPPRESS)
    add_log_level(p)
    p.set_defaults(func=run_serve, default_log_level="info")  # a server's log is its output


def run_serve(args: argparse.Namespace) -> int:
    from robogest.live import Robot
    from robogest.live.serve_limits import ServeLimits, bind, check_token, parse_listen
    from robogest.live.server import Server, serve_forever

    host, port = parse_listen(args.listen)
    check_token(host, port, args.token)  # before connecting: a non-loopback address without a token is refused
    if args.port is not None and args.port.isdigit():
        raise InputError(
            f"--port {args.port} is the servos' serial port (e.g. /dev/ttyUSB0), not a network port; to listen on "
            f"port {args.port} use --listen 127.0.0.1:{args.port}"
        )
    opts = generator_options(args)  # checks --checkpoint against --generator, one line
    given = {"max_clients": args.max_clients, "max_say_chars": args.max_say_chars}
    given["stream_buffer_s"] = args.stream_buffer_s
    limits = ServeLimits(**{k: v for k, v in given.items() if v is not None})  # defaults: ServeLimits (and --help)
    robot_kw = dict(
        backend=args.backend, port=args.port, baudrate=args.baud, idle=not args.no_idle, generator=args.generator,
        generator_options=opts, seed=args.seed, time_scale=args.time_scale,
        stop_within_s=None if args.full_gestures else args.stop_within,
    )  # fmt: skip
    sock = bind(host, port)  # before the robot: a busy address is one line, torque never touched
    server: Server | None = None
    try:
        with Robot(args.robot, **robot_kw) as robot:
            server = Server(
                robot, host, port, token=args.token, allow_origins=args.allow_origin, limits=limits, sock=sock,
                reopen=lambda: Robot(args.robot, **robot_kw).open(),
            )  # fmt: skip
            try:
                serve_forever(server, robot.config.name, robot.backend_name)
            finally:
                if server.robot is not robot:  # reopened after the first session died
                    server.robot.close()
    finally:
        sock.close()
    return 0
