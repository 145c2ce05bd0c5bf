"""Dynamixel servos (ROBOTIS ``dynamixel_sdk``): the wire of Protocol 2.0 (X series) and 1.0 (AX/MX), the control
tables (:mod:`.tables`) and the ``dynamixel`` backend (:mod:`.backend`). Importing this package registers both."""

from __future__ import annotations

from robogest.backends.servos.dynamixel.tables import MODELS, P1_SIGN_BITS, X_SIGNED, P1Reg, XReg
from robogest.backends.servos.protocol import ServoProtocol
from robogest.backends.servos.sdk import SdkModule
from robogest.backends.servos.wire import Wire, register_wire


def _sdk() -> SdkModule:
    import dynamixel_sdk

    sdk: SdkModule = dynamixel_sdk
    return sdk


#: Protocol 2.0 status packet: id at 4, error byte at 8, parameters from 9, two CRC bytes (dynamixel_sdk PKT_*);
#: ``rxPacket(port, False)``: no fast-sync option.
register_wire(Wire(ServoProtocol.DXL2, _sdk, 2.0, XReg, MODELS, status_layout=(4, 8, 9, 2), rx_flags=(False,),
                   twos_complement=frozenset(X_SIGNED)))  # fmt: skip
register_wire(Wire(ServoProtocol.DXL1, _sdk, 1.0, P1Reg, MODELS, sign_bits=P1_SIGN_BITS))

from robogest.backends.servos.dynamixel.backend import DynamixelBackend  # noqa: E402 - registers "dynamixel"

__all__ = ["DynamixelBackend"]
