"""Fault-injection spec for the simulated bus.

Grammar (comma-separated items, whitespace ignored; times in seconds since the bus started,
probabilities in [0, 1]):

======================  ==========================================================================
``noreply=P``           each status packet is dropped with probability P (the client times out)
``drop=P``              each instruction packet is ignored with probability P (lost sync writes)
``badcrc=P``            each status packet goes out with a corrupted checksum with probability P
``delay=MIN[:MAX][/P]`` status packets are delayed by U(MIN, MAX) s, with probability P (default 1)
``hwerror=ID:KIND@T``   servo ID latches a hardware error from time T (``@T`` optional, default 0);
                        KIND is ``overload``, ``overheating``, ``voltage``, ``encoder`` or ``shock``,
                        several joined with ``+`` (``hwerror=3:overload+voltage@2``)
``vanish=ID@T``         servo ID stops answering from time T
``torqueoff=ID@T``      servo ID's torque goes off at time T, as another program on the bus would switch it
                        (``torqueoff=all@T``: every servo); it answers on, limp
``reboot=ID@T``         servo ID reboots at time T, as after a brownout: torque off, RAM registers (goal,
                        speed cap) back to their defaults, latched errors cleared (``reboot=all@T``: every servo)
``disconnect@T``        the whole port goes away at time T (master side closed: clients get I/O errors)
``seed=N``              seed of the random faults (default 0), so a run is repeatable
======================  ==========================================================================

Example: ``noreply=0.05,badcrc=0.02,delay=0.01:0.05/0.1,hwerror=3:overload@2.0,vanish=5@3.0,disconnect@4.0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from robogest.errors import InputError

HW_KINDS = ("overload", "overheating", "voltage", "encoder", "shock")
_ALIASES = {"overheat": "overheating", "temperature": "overheating", "input_voltage": "voltage", "electrical": "shock"}

GRAMMAR = (
    "fault spec is a comma-separated list of: noreply=P, drop=P, badcrc=P, delay=MIN[:MAX][/P], "
    f"hwerror=ID:KIND[+KIND]@T (KIND: {', '.join(HW_KINDS)}), vanish=ID@T, torqueoff=ID|all@T, reboot=ID|all@T, "
    "disconnect@T, seed=N; "
    "P in [0, 1], times in seconds, e.g. 'noreply=0.05,hwerror=3:overload@2.0,disconnect@4.0'"
)


@dataclass
class FaultSpec:
    """Parsed fault configuration; the default injects nothing."""

    noreply: float = 0.0
    drop: float = 0.0
    badcrc: float = 0.0
    delay_min_s: float = 0.0
    delay_max_s: float = 0.0
    delay_p: float = 0.0
    hwerrors: list[tuple[int, tuple[str, ...], float]] = field(default_factory=list)
    vanish: list[tuple[int, float]] = field(default_factory=list)
    #: (servo id, or None for every servo, time): torque switched off / the servo rebooted (a brownout)
    torqueoff: list[tuple[int | None, float]] = field(default_factory=list)
    reboot: list[tuple[int | None, float]] = field(default_factory=list)
    disconnect_at_s: float | None = None
    seed: int = 0

    @classmethod
    def parse(cls, text: str | None) -> FaultSpec:
        spec = cls()
        if not text or not text.strip():
            return spec
        for raw in text.replace(" ", "").split(","):
            if not raw:
                continue
            try:
                spec._item(raw)
            except (ValueError, IndexError) as e:
                detail = f" ({e})" if str(e) else ""
                raise InputError(f"bad fault item {raw!r}{detail}; {GRAMMAR}") from None
        return spec

    def _item(self, item: str) -> None:
        if item.startswith("disconnect@"):
            self.disconnect_at_s = _time(item.split("@", 1)[1])
            return
        if "=" not in item:
            raise ValueError("expected KEY=VALUE")
        key, val = item.split("=", 1)
        if key in ("noreply", "drop", "badcrc"):
            setattr(self, key, _prob(val))
        elif key == "delay":
            rng, _, p = val.partition("/")
            lo, _, hi = rng.partition(":")
            self.delay_min_s = _time(lo)
            self.delay_max_s = _time(hi) if hi else self.delay_min_s
            if self.delay_max_s < self.delay_min_s:
                raise ValueError("delay MAX must be >= MIN")
            self.delay_p = _prob(p) if p else 1.0
        elif key == "hwerror":
            body, _, t = val.partition("@")
            sid, kinds = body.split(":", 1)
            names = tuple(_ALIASES.get(k, k) for k in kinds.split("+"))
            bad = [k for k in names if k not in HW_KINDS]
            if bad:
                raise ValueError(f"unknown hardware error {bad[0]!r}")
            self.hwerrors.append((_id(sid), names, _time(t) if t else 0.0))
        elif key == "vanish":
            sid, _, t = val.partition("@")
            self.vanish.append((_id(sid), _time(t) if t else 0.0))
        elif key in ("torqueoff", "reboot"):
            sid, _, t = val.partition("@")
            getattr(self, key).append((None if sid == "all" else _id(sid), _time(t) if t else 0.0))
        elif key == "seed":
            self.seed = int(val)
        else:
            raise ValueError(f"unknown key {key!r}")

    def __str__(self) -> str:
        parts = [f"{k}={getattr(self, k)}" for k in ("noreply", "drop", "badcrc") if getattr(self, k)]
        if self.delay_p:
            parts.append(f"delay={self.delay_min_s}:{self.delay_max_s}/{self.delay_p}")
        parts += [f"hwerror={i}:{'+'.join(k)}@{t}" for i, k, t in self.hwerrors]
        parts += [f"vanish={i}@{t}" for i, t in self.vanish]
        for key in ("torqueoff", "reboot"):
            parts += [f"{key}={'all' if i is None else i}@{t}" for i, t in getattr(self, key)]
        if self.disconnect_at_s is not None:
            parts.append(f"disconnect@{self.disconnect_at_s}")
        return ",".join(parts) or "none"


def _prob(s: str) -> float:
    p = float(s)
    if not 0.0 <= p <= 1.0:
        raise ValueError("probability must lie in [0, 1]")
    return p


def _time(s: str) -> float:
    t = float(s)
    if t < 0:
        raise ValueError("time must be >= 0")
    return t


def _id(s: str) -> int:
    i = int(s)
    if not 0 <= i <= 252:
        raise ValueError("servo id must lie in 0..252")
    return i
