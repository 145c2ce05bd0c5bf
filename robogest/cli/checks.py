"""What every subcommand checks before doing any work: option values and output paths.

Option values are checked by argparse ``type=`` functions, so a bad value is one ``robogest CMD: error:`` line
and exit code 2 (bad input), like every other usage error. Output paths are checked against each other and
against the command's inputs, so no command overwrites its own input or writes two outputs to one file.
Kept light (standard library only): ``robogest --help`` imports it.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Iterable, Mapping
from typing import NoReturn

from robogest.errors import InputError
from robogest.fileio import check_output_dir, check_output_path

#: Seeds are fed to numpy and torch generators, which take unsigned 32-bit values.
MAX_SEED = 2**32 - 1


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line on stderr (exit code 2), like every robogest error."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")


def number(lo: float, hi: float, unit: str = "", integer: bool = False) -> Callable[[str], float | int]:
    """An argparse ``type=``: a finite number (an integer if ``integer``) in ``[lo, hi]``."""
    unit_s = f" {unit}" if unit else ""
    kind = "an integer" if integer else "a number"
    span = f"{int(lo)}..{int(hi)}" if integer else f"{lo:g}..{hi:g}"

    def parse(text: str) -> float | int:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {kind}; expected {span}{unit_s}") from None
        if not (math.isfinite(value) and lo <= value <= hi):
            raise argparse.ArgumentTypeError(f"{text} is out of range; expected {span}{unit_s}")
        return value

    parse.__name__ = "integer" if integer else "number"  # argparse names the type in some messages
    return parse


#: ``--fps`` and other command/playback rates, Hz.
rate_hz = number(1, 1000, "Hz")
#: ``--seed``: what numpy's and torch's generators accept.
seed = number(0, MAX_SEED, integer=True)
#: ``--baud``: serial baud rates the supported adapters can run.
baud = number(300, 20_000_000, "baud", integer=True)


def positive_int(hi: int) -> Callable[[str], float | int]:
    """An argparse ``type=``: an integer in ``[1, hi]``."""
    return number(1, hi, integer=True)


def frame_size(text: str) -> tuple[int, int]:
    """An argparse ``type=`` for ``WIDTHxHEIGHT`` in pixels: even (H.264), 16..4096 each."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096 and w % 2 == 0 and h % 2 == 0):
        raise argparse.ArgumentTypeError(f"{text}: width and height must be even numbers of pixels in 16..4096")
    return w, h


def _same_file(a: str, b: str) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)  # hard links
    except OSError:
        return False


def check_outputs(
    outputs: Mapping[str, str | os.PathLike | None],
    inputs: Mapping[str, str | os.PathLike | Iterable[str | os.PathLike] | None] | None = None,
    folders: Mapping[str, str | os.PathLike | None] | None = None,
) -> None:
    """Refuse, before any work, outputs the command must not write.

    Parameters
    ----------
    outputs : mapping of flag to path or None
        Files the command will write (None: not asked for), e.g. ``{"--save": "a.npz", "--plot": None}``.
    inputs : mapping of flag to path, list of paths, or None
        Files it reads; no output may be one of them (symlinks, ``..`` and hard links resolved).
    folders : mapping of flag to path or None
        Output folders; each must be a folder or creatable.

    Raises
    ------
    InputError
        One line naming both flags and paths (or the bad path and why, see
        :func:`robogest.fileio.check_output_path`).
    """
    ins: list[tuple[str, str]] = []
    for flag, value in (inputs or {}).items():
        if value is None:
            continue
        paths = [value] if isinstance(value, str | os.PathLike) else list(value)
        ins += [(flag, os.fspath(p)) for p in paths if os.fspath(p)]
    outs: list[tuple[str, str]] = []
    for flag, value in outputs.items():
        if value is None:
            continue
        out = os.fspath(value)
        check_output_path(out, flag)
        for in_flag, in_path in ins:
            if _same_file(out, in_path):
                raise InputError(
                    f"{flag} {out} is the same file as the input {in_flag} {in_path}; writing it would destroy the "
                    "input, choose another output path"
                )
        for other_flag, other in outs:
            if _same_file(out, other):
                raise InputError(f"{flag} {out} and {other_flag} {other} name the same file; give each output its own")
        outs.append((flag, out))
    for flag, value in (folders or {}).items():
        if value is not None:
            check_output_dir(value, flag)


#: Parser default listing ``(flag, dest, extra)``: options that need a pip extra (see :func:`needs_extra`).
_EXTRAS_KEY = "_needs_extras"


def needs_extra(p: argparse.ArgumentParser, flag: str, extra: str) -> None:
    """Mark option ``flag`` of ``p`` as needing pip extra ``extra``; :func:`require_extras` checks it."""
    dest = flag.lstrip("-").replace("-", "_")
    p.set_defaults(**{_EXTRAS_KEY: [*(p.get_default(_EXTRAS_KEY) or ()), (flag, dest, extra)]})


def require_extras(args: argparse.Namespace) -> None:
    """Right after parsing, before any work: each given option marked by :func:`needs_extra` has its extra
    installed, else :class:`~robogest.errors.MissingDependencyError` (exit 6) with the pip command."""
    given = [(flag, extra) for flag, dest, extra in getattr(args, _EXTRAS_KEY, ()) if getattr(args, dest, None)]
    if given:
        from robogest.extras import require_extra

        for flag, extra in given:
            require_extra(extra, flag)
