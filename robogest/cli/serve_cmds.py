"""``robogest serve``: a live robot session behind a local WebSocket server (protocol: robogest/live/server.py)."""

from __future__ import annotations

import argparse

from robogest.cli import checks
from robogest.cli.common import generator_options
from robogest.robot.registry import DEFAULT_ROBOT

SERVE_EPILOG = """protocol (JSON text frames; binary frames are PCM of the open stream):
  -> {"type": "say", "text": "Hello!"}      {"type": "say", "audio": "/abs/reply.wav", "transcript": "..."}
  -> {"type": "stream_start", "sample_rate": 16000, "format": "int16"}, binary PCM frames, {"type": "stream_end"}
  -> {"type": "interrupt"}                  {"type": "status"}
  <- {"type": "accepted", "utterance": N}   {"type": "event", "utterance": N, "event": "first_goal", ...}
  <- {"type": "error", "message": "..."}    (malformed messages never stop the session)

Streamed speech uses the default `rhythm` generator with a look-ahead of 0.25 s; learned generators
(--generator with --checkpoint) are batch-only: they serve "say" messages only. Speech audio is played
through sounddevice (pip install 'robogest[audio]') when an output device exists; otherwise the events
carry the time each stretch of audio should start. Ctrl-C or SIGTERM: the robot glides to rest, torque off.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="keep a robot session open and take speech over a local WebSocket (say, stream, interrupt)",
        description="One robot session (torque on, idle motion between utterances) serving other processes "
        "over WebSocket. Listens on 127.0.0.1 only unless --listen names another address, which needs --token. "
        "Handshakes that carry an Origin header (every browser sends one) are refused unless --allow-origin "
        "names it, so a web page cannot move the robot.",
        epilog=SERVE_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--robot", default=DEFAULT_ROBOT, help="robot name or YAML path (default: %(default)s)")
    p.add_argument("--backend", default="sim", help="sim (MuJoCo, real time, default), dynamixel or feetech")
    p.add_argument("--port", help="serial port for dynamixel/feetech (default: the robot YAML's bus.port)")
    p.add_argument("--baud", type=checks.baud, help="baud rate (default: the robot YAML's bus.baudrate)")
    p.add_argument("--listen", default="127.0.0.1:8765", metavar="HOST:PORT", help="address (default: %(default)s)")
    p.add_argument("--token", help="shared secret clients must send (Authorization: Bearer T, or ?token=T)")
    p.add_argument(
        "--allow-origin", action="append", default=[], metavar="ORIGIN",
        help="accept browser handshakes from this Origin, e.g. http://localhost:3000 (repeatable)",
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
    p.set_defaults(func=run_serve)


def run_serve(args: argparse.Namespace) -> int:
    from robogest.live import Robot
    from robogest.live.server import Server, parse_listen, serve_forever

    host, port = parse_listen(args.listen)
    Server(None, host, port, token=args.token)  # refuses a non-loopback address without a token, before connecting
    opts = generator_options(args)  # checks --checkpoint against --generator, one line
    with Robot(
        args.robot, backend=args.backend, port=args.port, baudrate=args.baud, idle=not args.no_idle,
        generator=args.generator, generator_options=opts, seed=args.seed, time_scale=args.time_scale,
        stop_within_s=None if args.full_gestures else args.stop_within,
    ) as robot:  # fmt: skip
        serve_forever(robot, host, port, token=args.token, allow_origins=args.allow_origin)
    return 0
