"""The options of a live session (:class:`SessionConfig`), checked once, each error naming its field.

``Robot(name, **options)`` builds one from its keyword arguments; ``Robot(name, config=SessionConfig(...))`` takes
one made beforehand (e.g. shared by a server's reopen).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robogest.errors import InputError
from robogest.live.idle import IdleConfig

#: Where says are prepared (:mod:`robogest.live.prepare`).
PREPARE_MODES = ("process", "thread")


@dataclass(frozen=True)
class SessionConfig:
    """Options of a :class:`~robogest.live.Robot` session; validated on creation (an InputError names the field).

    Parameters
    ----------
    backend : str
        ``sim`` (MuJoCo, paced in real time; the default), ``dynamixel`` or ``feetech``.
    port : str, optional
        Serial port of a servo backend (default: the robot YAML's ``bus.port``).
    idle : bool
        Breathing and weight shift between utterances (:mod:`robogest.live.idle`); False holds rest.
    idle_config : IdleConfig, optional
        Rate and amplitude of the idle motion.
    generator : str
        Gesture generator for :meth:`say` (learned ones need ``checkpoint`` in ``generator_options``).
        Streaming always uses ``rhythm``: learned generators are batch-only.
    seed : int
        Seed of the gesture choices.
    lookahead_s : float
        L of streamed speech, seconds (motion and audio are played this far behind the newest chunk).
    rate_hz : float
        Control-loop rate, Hz.
    time_scale : float
        Loop seconds per wall second (tests run faster than real time with > 1; audio is then not played).
    audio : bool
        Play speech through ``sounddevice`` when it and an output device exist.
    voice, words_per_minute : str, int
        eSpeak NG voice and rate for text.
    baudrate : int, optional
        Baud rate of a servo backend.
    on_tick : callable (loop_s, goal_rad), optional
        Called after every control tick with the goal ``(J,)`` radians sent (keep it short).
    backend_options : dict, optional
        More keyword options of the backend (e.g. ``lost_after_s`` of a servo backend).
    warm_up : bool
        Run the speech (eSpeak NG, the front-end) and planning code of a say and of a stream once in the
        background after opening, so the first utterance after :attr:`ready` is nearly as fast as later ones
        (measured on the quiet 2-core machine: 424 ms to the first goal against 260 ms, docs/live.md).
    blas_threads : int or None
        While the session is open, BLAS thread pools of the whole process are limited to this many threads (the
        planner's matrices are small; more threads only take cores from the control loop: 2.5x faster streaming
        measured on 2 cores). Restored on close; None leaves them alone.
    stop_within_s : float or None
        The robot is always within this many seconds of standing at rest (every limit kept), so :meth:`interrupt`
        is at rest within it: the control loop's limiter cuts short any gesture that would take it farther (on
        humanoid_xl430, 0.45 s allows about 0.65 rad from rest at the shoulders). None: gestures as large as the
        joint limits allow, and an interrupt takes as long as the limits make it.
    approach_within_rad : float
        An utterance starting this close (every joint, radians) to the pose held starts at once, the limiter
        taking up the difference; farther away, the robot first glides to its first pose.
    prepare : str
        ``"process"``: says are prepared in a child Python process started with the session
        (:mod:`robogest.live.prepare`), so their seconds of GIL-holding work never delay the control loop or the
        caller's asyncio loop; ``"thread"``: in the session's worker thread (where child processes are unwanted;
        the same results bit for bit). Streams are planned in their own thread either way.
    generator_options : dict
        Keyword options of the generator (e.g. ``{"amount": 1.5}`` for ``rhythm``).
    """

    backend: str = "sim"
    port: str | None = None
    idle: bool = True
    idle_config: IdleConfig | None = None  #: None: ``IdleConfig()``
    generator: str = "rhythm"
    generator_options: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    lookahead_s: float | None = None  #: None: :data:`robogest.speech.stream.DEFAULT_LOOKAHEAD_S`
    rate_hz: float = 100.0
    time_scale: float = 1.0
    audio: bool = True
    voice: str = "en-us"
    words_per_minute: int = 160
    baudrate: int | None = None
    on_tick: Callable[[float, np.ndarray], None] | None = None
    backend_options: Mapping[str, Any] = field(default_factory=dict)
    warm_up: bool = True
    blas_threads: int | None = 1
    stop_within_s: float | None = 0.45
    approach_within_rad: float = 0.2
    prepare: str = "process"

    def __post_init__(self) -> None:
        if self.prepare not in PREPARE_MODES:
            raise InputError(f'session option "prepare": {self.prepare!r}; use "process" (says prepared in a child '
                             'process) or "thread" (in the session\'s worker thread)')  # fmt: skip
        _positive("rate_hz", self.rate_hz)
        _positive("time_scale", self.time_scale)
        _positive("words_per_minute", self.words_per_minute)
        if self.lookahead_s is not None:
            _positive("lookahead_s", self.lookahead_s, zero=True)
        if self.stop_within_s is not None:
            _positive("stop_within_s", self.stop_within_s)
        _positive("approach_within_rad", self.approach_within_rad, zero=True)
        if self.blas_threads is not None and (isinstance(self.blas_threads, bool) or int(self.blas_threads) < 1):
            raise InputError(f'session option "blas_threads": {self.blas_threads!r}; give a count >= 1, or None')
        for name in ("generator_options", "backend_options"):
            if not isinstance(getattr(self, name), Mapping):
                raise InputError(f'session option "{name}": a dict of keyword options, not {getattr(self, name)!r}')

    @classmethod
    def from_options(cls, **options: Any) -> SessionConfig:
        """From ``Robot``'s keyword arguments; an unknown one is an InputError naming it."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise InputError(f"Robot: unknown session option(s) {', '.join(map(repr, unknown))}; the options are "
                             f"{', '.join(sorted(known))}")  # fmt: skip
        return cls(**options)


def _positive(name: str, value: object, zero: bool = False) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or value < 0
        or (value == 0 and not zero)
    ):
        what = "a number >= 0" if zero else "a number > 0"
        raise InputError(f'session option "{name}": {value!r}; give {what}')
