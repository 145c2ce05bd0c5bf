"""``robogest`` command line: one subcommand module per area, each exposing ``register(subparsers)``.

Exit codes: 0 success; 1 other robogest error; 2 bad input (file, flag, transcript); 3 bad robot/config
file; 4 safety refusal; 5 hardware or simulator failure; 6 missing optional dependency; 130 Ctrl-C
(SIGINT), 143 SIGTERM, 129 SIGHUP.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import sys
from collections.abc import Sequence

from robogest.errors import RobogestError

#: Subcommand modules under ``robogest.cli``; each defines ``register(subparsers) -> None`` and sets
#: ``func`` (``(argparse.Namespace) -> int``) on its parsers.
_MODULES = ("speech_cmds", "robots_cmds", "speak_cmds", "servo_cmds", "eval_cmds", "train_cmds", "serve_cmds")

EPILOG = """exit codes:
  0  success
  1  other robogest error
  2  bad input (audio, transcript, motion file, option value)
  3  bad robot definition or config file (the message names file and key)
  4  safety refusal (e.g. NaN from a generator)
  5  hardware or simulator failure (servo missing, in error, port lost); torque was turned off
  6  optional dependency missing (the message says what to install)
  130 interrupted (Ctrl-C / SIGINT), 143 SIGTERM, 129 SIGHUP (terminal closed): the robot was sent to rest
      and torque turned off (the message says if rest could not be reached)
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robogest",
        description="Co-speech gestures for servo-driven humanoid robots: speech in, safe gestures out, "
        "on Dynamixel/Feetech servos or in MuJoCo.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _MODULES:
        try:
            mod = importlib.import_module(f"robogest.cli.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"robogest.cli.{name}":
                continue  # area not built yet
            raise
        mod.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except RobogestError as e:
        print(f"robogest: error: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGINT/SIGTERM/SIGHUP during motion (robogest.backends.control)
        with contextlib.suppress(OSError):  # after SIGHUP the terminal may be gone
            print(f"robogest: {e if str(e) else 'interrupted'}", file=sys.stderr)
        return int(getattr(e, "exit_code", 130))


if __name__ == "__main__":
    sys.exit(main())
