"""The idle motion of a live session on its control loop: switched on once tabulated, faded out when speech comes,
in again when none came after all or a glide to rest ended (:class:`~robogest.live.idle.IdleMotion` is the motion).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from robogest.live.idle import IdleMotion

if TYPE_CHECKING:
    from robogest.backends.control import ControlLoop
    from robogest.backends.play_handle import PlayHandle


class IdlePlayer:
    """Plays ``motion`` on ``loop`` between utterances. :meth:`switch_on` and :meth:`after_glide` run in the
    session's owner thread (in order with interrupts); :meth:`target` in the loop's tick."""

    def __init__(self, loop: ControlLoop, motion: IdleMotion) -> None:
        self.loop = loop
        self.motion = motion
        self._last_s: float | None = None

    def fade_out(self) -> None:
        """Speech is coming: the idle motion fades out now (see :meth:`IdleMotion.stop`)."""
        self.motion.stop(self.loop.now_s)

    def fade_in(self) -> None:
        """No speech after all (refused, abandoned, interrupted): the idle motion fades in again."""
        self.motion.restart(self.loop.now_s)

    def target(self, t_s: float) -> np.ndarray:
        """Pose ``(J,)`` rad at loop time ``t_s``."""
        if self._last_s is None or t_s - self._last_s > 0.25:  # idle was not playing (late ticks skip less)
            self.motion.restart(t_s)  # fade in from zero
        self._last_s = t_s
        return self.motion.target(t_s)

    def switch_on(self) -> None:
        """Play from now on (after the glide, if an interrupt's is under way: :meth:`after_glide` then)."""
        loop = self.loop
        if not loop.closed and loop.error is None and (loop.resting is None or loop.resting.done):
            loop.set_idle(self.target)

    def after_glide(self, rest: PlayHandle) -> None:
        """The glide ``rest`` ended: play again, unless a newer interrupt's glide is under way."""
        if not self.loop.closed and self.loop.resting is rest:
            self.fade_in()
            self.loop.set_idle(self.target)
