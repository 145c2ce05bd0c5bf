"""Preparing a say (speech -> gestures -> safe trajectory), in the session's thread or in a child process.

A say's preparation is seconds of Python and C code (text-to-speech post-processing, the generator, IK, the safety
layer's QP) that holds the GIL in long stretches; run in a thread of the session's process it makes the control
loop and the caller's asyncio loop wait (ticks late by up to 26 ms in a 120-word say). :class:`ProcessPreparer`
runs it in a child Python process started for the session (``subprocess``, a fresh interpreter: no ``fork`` of a
process with threads, and the caller's ``__main__`` is not imported again as ``multiprocessing``'s spawn does), so
the session's process only waits on a pipe. :class:`SayPreparer` is the preparation itself, used by the child and,
with ``SessionConfig(prepare="thread")``, in the session's worker thread: both give the same outputs bit for bit.

The child ignores SIGINT (Ctrl-C reaches the whole process group: the session, not the child, ends at rest) and
exits when its input pipe closes (the session closed, crashed or was killed), so it never outlives the session.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pickle
import signal
import subprocess
import sys
import threading
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Protocol

import numpy as np

from robogest.errors import BackendError, RobogestError
from robogest.robot.config import RobotConfig
from robogest.speech.types import Speech
from robogest.trajectory import Trajectory

#: What the warm-up says (in the child: the first real say then pays no imports or voice loading).
WARM_UP_TEXT = "Hello there, nice to meet you."
#: Generators kept for reuse per preparer (a client trying every ``amount`` must not grow it without bound).
_MAX_GENERATORS = 16


class SayGenerator(Protocol):
    """What a say needs of a gesture generator (:class:`robogest.generators.Generator` and plugins)."""

    def generate(self, speech: Speech, seed: int = ...) -> Any: ...


@dataclass(frozen=True)
class SayRequest:
    """Everything a say's preparation depends on besides the robot (picklable: sent to the child process)."""

    text: str | None = None
    audio: str | None = None  #: an audio file's path (instead of ``text``)
    transcript: str | None = None
    voice: str = "en-us"
    words_per_minute: int = 160
    lenient: bool = False
    generator: str = "rhythm"
    generator_options: dict[str, Any] = field(default_factory=dict)  #: incl. a say's own body language
    seed: int = 0
    fps: float = 50.0


@dataclass
class PreparedSay:
    """A say made ready to play: its trajectory and speech audio ``(N,)`` float32 at ``sr`` Hz."""

    trajectory: Trajectory
    audio: np.ndarray
    sr: int
    #: warnings the preparation logged in the child, ``(logger name, level, message)``: logged again here
    logged: list[tuple[str, int, str]] = field(default_factory=list)


def generator_key(name: str, options: dict[str, Any]) -> str:
    """A stable key of a generator's name and options (options hold paths, numbers and strings)."""
    return repr((name, sorted(options.items())))


class GeneratorCache:
    """Generators made by name and options, kept for later calls: per-call body language makes one per distinct
    ``amount``/``gestures``, and building one (gesture units, filters) costs more than a say's planning. Bounded:
    past :data:`_MAX_GENERATORS` made here, all but the ``kept`` ones are dropped."""

    def __init__(self, kept: dict[str, SayGenerator] | None = None) -> None:
        self._generators: dict[str, SayGenerator] = dict(kept or {})
        self._keep = set(self._generators)  # given by the owner (e.g. the session's own generator): never dropped

    def get(self, name: str, options: dict[str, Any]) -> SayGenerator:
        from robogest.generators import make_generator

        key = generator_key(name, options)
        gen = self._generators.get(key)
        if gen is None:
            gen = make_generator(name, **options)
            if len(self._generators) >= _MAX_GENERATORS + len(self._keep):
                self._generators = {k: g for k, g in self._generators.items() if k in self._keep}
            self._generators[key] = gen
        return gen


class SayPreparer:
    """Prepares says for one robot, keeping the generators it made (by name and options) for later says."""

    def __init__(self, config: RobotConfig, generators: dict[str, SayGenerator] | None = None) -> None:
        self.config = config
        self.generators = GeneratorCache(generators)

    def generator(self, name: str, options: dict[str, Any]) -> SayGenerator:
        return self.generators.get(name, options)

    def prepare(self, req: SayRequest) -> PreparedSay:
        """Speech, gestures and the safe trajectory of ``req`` (InputError etc. for a bad input)."""
        from robogest.pipeline import load_speech_input, motion_to_trajectory

        gen = self.generator(req.generator, req.generator_options)
        speech = load_speech_input(
            text=req.text, audio=req.audio, transcript=req.transcript, voice=req.voice,
            words_per_minute=req.words_per_minute, lenient=req.lenient,
            units=getattr(getattr(gen, "repertoire", None), "units", None),
        )  # fmt: skip
        motion = gen.generate(speech, seed=req.seed)
        traj, _, _ = motion_to_trajectory(
            motion, self.config, silent_spans=speech.silent_spans, fps=req.fps,
            audio_path=str(speech.audio_path or ""),
        )  # fmt: skip
        return PreparedSay(traj, np.asarray(speech.audio), int(speech.sr))


class ProcessPreparer:
    """A child process that prepares says (see module docstring); one request at a time.

    :meth:`start` launches it (returns at once: the child imports while the session gets ready); :meth:`prepare`
    sends a request and waits for the result, raising the child's exception as it was raised there. A child that
    dies is reported once on stderr and started again; the say it was preparing fails with a BackendError.
    """

    def __init__(self, config: RobotConfig, blas_threads: int | None) -> None:
        self.config = config
        self.blas_threads = blas_threads
        self._proc: subprocess.Popen[bytes] | None = None
        self._lock = threading.Lock()  # one request on the pipe at a time (the worker and the warm-up)
        self._life = threading.Lock()  # a child is started only while not closed: close() may come from any thread
        self._closed = False
        self.restarts = 0  #: how often the child died and was started again
        self.served = 0  #: requests the child answered (the warm-up's included)

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    def start(self) -> None:
        """Launch the child and send it the robot (it then imports the preparation code)."""
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[2])  # this robogest, whatever the caller's sys.path
        env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
        with self._life:
            if self._closed:
                raise BackendError("say: the session is closing; the preparation process is not started")
            self._proc = subprocess.Popen(
                [sys.executable, "-c", "from robogest.live.prepare import main; main()"], stdin=subprocess.PIPE,
                stdout=subprocess.PIPE, env=env, start_new_session=True, close_fds=True,
            )  # fmt: skip
        self._send(("init", self.config, self.blas_threads))

    def _send(self, msg: object) -> None:
        proc = self._proc
        assert proc is not None and proc.stdin is not None
        pickle.dump(msg, proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
        proc.stdin.flush()

    def _receive(self) -> tuple[str, Any]:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        reply: tuple[str, Any] = pickle.load(proc.stdout)
        return reply

    def prepare(self, req: SayRequest) -> PreparedSay:
        """``req`` prepared in the child; raises what the preparation raised (BackendError if the child died)."""
        with self._lock:
            if self._closed:
                raise BackendError("say: the session is closing; the utterance was not prepared")
            try:
                if self._proc is None:  # (the session's start-up failed to start it)
                    self.start()
                elif self._proc.poll() is not None:
                    self._died("before this say")
                self._send(("say", req))
                kind, value = self._receive()
                self.served += 1
            except (EOFError, OSError, pickle.UnpicklingError) as e:
                if self._closed:
                    raise BackendError("say: the session closed while the utterance was prepared") from e
                self._died("while preparing this say")
                raise BackendError(
                    "say: the preparation process died while preparing this utterance (it was started again); "
                    "say it again, or use SessionConfig(prepare='thread') if it keeps dying"
                ) from e
        if kind == "error":
            raise value
        prepared: PreparedSay = value
        for name, level, message in prepared.logged:  # through the caller's logging configuration
            logging.getLogger(name).log(level, "%s", message)
        prepared.logged = []
        return prepared

    def _died(self, when: str) -> None:
        """Report the dead child (one line) and start a new one; BackendError (one line) if that fails too."""
        code = None if self._proc is None else self._proc.wait()
        print(f"robogest: the say-preparation process died {when} (exit code {code}); starting it again",
              file=sys.stderr)  # fmt: skip
        self.restarts += 1
        try:
            self.start()
        except Exception as e:
            raise BackendError(f"say: the preparation process cannot be started again ({e})") from e

    def close(self) -> None:
        """End the child now (a preparation in progress is dropped: its say is abandoned)."""
        with self._life:
            self._closed = True
            proc = self._proc
        if proc is None:
            return
        with contextlib.suppress(OSError):
            if proc.stdin is not None:
                proc.stdin.close()  # an idle child exits on EOF
        with contextlib.suppress(OSError):
            proc.terminate()  # a busy one now
        try:
            proc.wait(5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()


def _reply(out: IO[bytes], kind: str, value: object) -> None:
    pickle.dump((kind, value), out, protocol=pickle.HIGHEST_PROTOCOL)
    out.flush()


def _error_reply(e: Exception) -> Exception:
    """``e`` if it survives pickling (RobogestError and most others), else a RuntimeError with its text; a bug
    (not a RobogestError) carries the child's traceback as a note."""
    add_note = getattr(e, "add_note", None)  # Python >= 3.11
    if not isinstance(e, RobogestError) and add_note is not None:
        add_note("in the say-preparation process:\n" + "".join(traceback.format_exception(e)).rstrip())
    try:
        pickle.loads(pickle.dumps(e))
        return e
    except Exception:
        return RuntimeError(f"{type(e).__name__}: {e}")


class _Collect(logging.Handler):
    """Keeps the child's log records of one request, sent back with its result."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[tuple[str, int, str]] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append((record.name, record.levelno, record.getMessage()))


def _serve(inp: IO[bytes], out: IO[bytes]) -> None:
    """The child's loop: an ``init`` message, then ``say`` requests until EOF."""
    kind, config, blas_threads = pickle.load(inp)
    assert kind == "init"
    if blas_threads is not None:  # as the session limits its own (bit-for-bit the same results)
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=int(blas_threads), user_api="blas")
    preparer = SayPreparer(config)
    logged = _Collect()
    logging.getLogger().addHandler(logged)
    logging.getLogger().setLevel(logging.WARNING)
    while True:
        try:
            kind, req = pickle.load(inp)
        except EOFError:
            return
        try:
            logged.records.clear()
            result = preparer.prepare(req)
        except Exception as e:
            _reply(out, "error", _error_reply(e))
            continue
        result.logged = list(logged.records)
        _reply(out, "ok", result)


def main() -> None:
    """Entry point of the child (started by :meth:`ProcessPreparer.start`): requests on stdin, replies on stdout."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the session's to handle; EOF ends this process
    out = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # a print anywhere must not corrupt the replies
    with contextlib.suppress(BrokenPipeError):  # the session is gone
        _serve(sys.stdin.buffer, out)
