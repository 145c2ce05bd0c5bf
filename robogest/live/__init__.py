"""A live robot session: :class:`Robot` (Python API) and ``robogest serve`` (the same session over WebSocket).

Stage-wise this package sits on top of everything: it drives speech -> generator -> IK -> control loop.
"""

from robogest.live.config import SessionConfig
from robogest.live.idle import IdleConfig, IdleMotion
from robogest.live.session import Robot
from robogest.live.stream import StreamUtterance
from robogest.live.utterance import EVENT_TYPES, UtteranceHandle

__all__ = ["EVENT_TYPES", "IdleConfig", "IdleMotion", "Robot", "SessionConfig", "StreamUtterance", "UtteranceHandle"]
