"""Feetech servos (``scservo_sdk``): the wire of STS/SMS (protocol 0, little-endian) and SCS (protocol 1,
big-endian), the control tables (:mod:`.tables`) and the ``feetech`` backend (:mod:`.backend`). Importing this
package registers both."""

from __future__ import annotations

from collections.abc import Callable

from robogest.backends.servos.feetech.tables import MODELS, SCS_SIGN_BITS, STS_SIGN_BITS, SCSReg, STSReg
from robogest.backends.servos.protocol import ServoProtocol
from robogest.backends.servos.sdk import SdkModule
from robogest.backends.servos.wire import Wire, register_wire


def _sdk() -> SdkModule:
    import scservo_sdk

    sdk: SdkModule = scservo_sdk
    return sdk


def _byte_order(end: int) -> Callable[[SdkModule], None]:
    """Before every call: the SDK keeps the byte order in a module global (``SCS_SETEND``) that its group writers
    encode with, so each call re-asserts this bus's (another bus in the same process may have changed it)."""

    def set_end(_sdk: SdkModule) -> None:
        import scservo_sdk

        scservo_sdk.SCS_SETEND(end)

    return set_end


register_wire(Wire(ServoProtocol.STS, _sdk, 0, STSReg, MODELS, before_call=_byte_order(0), sign_bits=STS_SIGN_BITS))
register_wire(Wire(ServoProtocol.SCS, _sdk, 1, SCSReg, MODELS, before_call=_byte_order(1), sign_bits=SCS_SIGN_BITS))

from robogest.backends.servos.feetech.backend import FeetechBackend  # noqa: E402 - registers "feetech"

__all__ = ["FeetechBackend"]
