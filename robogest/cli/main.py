"""``robogest`` command line: one subcommand module per area, each exposing ``register(subparsers)``.

Exit codes: 0 success; 1 other robogest error; 2 bad input (file, flag, transcript); 3 bad robot/config
file; 4 safety refusal; 5 hardware or simulator failure; 6 missing optional dependency; 130 Ctrl-C
(SIGINT), 143 SIGTERM, 129 SIGHUP, 131 SIGQUIT; 141 stdout closed early (``robogest ... | head``), quietly, as a
command killed by SIGPIPE would.

When stdout is not a terminal it is line-buffered (each line reaches the pipe when printed) and tables are
printed as tab-separated lines; ``--json`` on the listing commands prints JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import io
import logging
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import TextIO

from robogest.cli.checks import OneLineParser, require_extras
from robogest.errors import RobogestError

#: Subcommand modules under ``robogest.cli``; each defines ``register(subparsers) -> None`` and sets
#: ``func`` (``(argparse.Namespace) -> int``) on its parsers.
_MODULES = ("speech_cmds", "robots_cmds", "speak_cmds", "servo_cmds", "eval_cmds", "train_cmds", "serve_cmds")

EPILOG = """exit codes:
  0  success
  1  other robogest error, e.g. an output could not be written (disk full; no partial file is left)
     or out of memory
  2  bad input (audio, transcript, motion file, option value, output path); checked before any work:
     an output that is an input or another output, a folder, a device or FIFO, or not writable
  3  bad robot definition or config file (the message names file and key)
  4  safety refusal (e.g. NaN from a generator)
  5  hardware or simulator failure (servo missing, in error, port lost); torque was turned off
  6  optional dependency missing (the message says what to install)
  130 interrupted (Ctrl-C / SIGINT), 143 SIGTERM, 129 SIGHUP (terminal closed), 131 SIGQUIT (Ctrl-\\):
      the robot was sent to rest and torque turned off (the message says if rest could not be reached)
  141 stdout closed before the output ended (e.g. `| head`); ends quietly

When stdout is a pipe or file: tables are tab-separated lines, each line is written as soon as it is
printed, and `--json` (robots list/show, analyze) prints JSON. Progress goes to stderr (plain lines
when it is not a terminal).
"""

#: Exit status for a closed stdout: 128 + SIGPIPE, what a shell reports for a command killed by SIGPIPE.
EXIT_BROKEN_PIPE = 141


class _VersionAction(argparse.Action):
    """``--version``: the installed distribution's version, looked up only when asked (keeps --help fast)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser: argparse.ArgumentParser, *args: object) -> None:
        from robogest._version import __version__

        print(f"robogest {__version__}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="robogest",
        description="Co-speech gestures for servo-driven humanoid robots: speech in, safe gestures out, "
        "on Dynamixel/Feetech servos or in MuJoCo.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=_VersionAction, help="print the installed version and exit")
    add_log_level(parser)
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


LOG_LEVELS = ("debug", "info", "warning", "error")


def add_log_level(parser: argparse.ArgumentParser, default: str | None = None) -> None:
    """``--log-level``: what the ``robogest.*`` loggers print on stderr (given after a subcommand too)."""
    parser.add_argument(
        "--log-level", choices=LOG_LEVELS, default=argparse.SUPPRESS,
        help="log messages shown on stderr (default: warning; info for serve)",
    )  # fmt: skip


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record comes (tests replace it)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: TextIO) -> None:
        pass


def _configure_logging(level: str) -> None:
    """The CLI's readable default: ``robogest.*`` records on stderr with time and level (the library configures
    nothing on import; other libraries' loggers are left alone)."""
    logger = logging.getLogger("robogest")
    logger.setLevel(level.upper())
    if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
        h = _StderrHandler()
        h.setFormatter(logging.Formatter("%(asctime)s robogest %(levelname)s: %(message)s", "%H:%M:%S"))
        logger.addHandler(h)


def _quiet_stdout() -> None:
    """After a closed pipe: point stdout at /dev/null so the interpreter's final flush cannot fail again.

    The standard recipe (Python docs, "Note on SIGPIPE" in the signal module).
    """
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):  # stdout replaced (tests), or closed
        pass


def _one_line_warnings(show: Callable[..., None]) -> Callable[..., None]:
    """``warnings.showwarning`` printing robogest's own warnings as one ``robogest: warning: ...`` line."""

    def show_warning(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        from robogest.errors import RobogestWarning

        if issubclass(category, RobogestWarning):
            print(f"robogest: warning: {message}", file=sys.stderr if file is None else file)
        else:
            show(message, category, filename, lineno, file, line)

    return show_warning


def _reopen_closed_streams() -> None:
    """Started with stdout or stderr closed (``2>&-``): point the closed descriptor at /dev/null and give Python a
    stream for it. Python leaves ``sys.stderr`` None, so the first progress line failed and the command ended with
    exit 1 before any motion; and a file opened later would take descriptor 2 and receive C libraries' messages."""
    for fd, name in ((1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
            continue
        except OSError:
            pass
        devnull = os.open(os.devnull, os.O_WRONLY)
        if devnull != fd:
            os.dup2(devnull, fd)
            os.close(devnull)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, "w", closefd=False))  # noqa: SIM115 - lives as long as the process


def main(argv: Sequence[str] | None = None) -> int:
    _reopen_closed_streams()
    previous = warnings.showwarning
    warnings.showwarning = _one_line_warnings(previous)
    if not sys.stdout.isatty() and isinstance(sys.stdout, io.TextIOWrapper):
        sys.stdout.reconfigure(line_buffering=True)  # a pipe sees each line when it is printed
    try:
        return _run(argv)
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    finally:
        warnings.showwarning = previous


class Terminated(KeyboardInterrupt):
    """SIGTERM, SIGHUP or SIGQUIT outside motion: unwinds like Ctrl-C, so half-written outputs are removed on the way
    out (Python's default for these signals ends the process at once, leaving them). ``exit_code`` is 128 + signum."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"terminated by {signal.Signals(signum).name}")
        self.exit_code = 128 + signum


@contextlib.contextmanager
def _terminate_like_ctrl_c() -> Iterator[None]:
    """Within the block, SIGTERM, SIGHUP and SIGQUIT raise :class:`Terminated` (main thread; a signal ignored when it
    began, as SIGHUP under ``nohup``, stays ignored). During motion the control loop's own handlers take over and end
    at rest."""
    taken = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None), getattr(signal, "SIGQUIT", None)):
            if sig is None or signal.getsignal(sig) is signal.SIG_IGN:
                continue
            taken[sig] = signal.signal(sig, _raise_terminated)
    try:
        yield
    finally:
        for sig, prev in taken.items():
            signal.signal(sig, prev)


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated(signum)


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    _configure_logging(str(getattr(args, "log_level", None) or getattr(args, "default_log_level", "warning")))
    try:
        require_extras(args)  # a missing extra fails before any work
        with _terminate_like_ctrl_c():
            rc = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler in main, not at interpreter exit
        return rc
    except RobogestError as e:
        print(f"robogest: error: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGINT/SIGTERM/SIGHUP/SIGQUIT in motion (robogest.backends.control)
        with contextlib.suppress(OSError):  # after SIGHUP the terminal may be gone
            print(f"robogest: {e if str(e) else 'interrupted'}", file=sys.stderr)
        return int(getattr(e, "exit_code", 130))
    except MemoryError:
        print("robogest: error: out of memory; the input is too large for this machine", file=sys.stderr)
        return 1
    except OSError as e:
        if e.errno != errno.ENAMETOOLONG:
            raise
        name = os.fsdecode(e.filename or "a path")
        short = name if len(name) <= 60 else name[:30] + "..." + name[-20:]
        print(f"robogest: error: {short}: the file name is too long for this file system; choose a shorter name",
              file=sys.stderr)  # fmt: skip
        return 2


if __name__ == "__main__":
    sys.exit(main())
