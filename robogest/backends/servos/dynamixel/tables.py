"""Dynamixel control tables used by the backend (X-series on Protocol 2.0, AX/MX on Protocol 1.0).

Register names are Enums whose value is ``(address, size_bytes)``; model facts (model number,
resolution, centre tick) live in :data:`MODELS`. Source: ROBOTIS e-manual.
"""

from __future__ import annotations

import math
from enum import Enum

from robogest.backends.servos.protocol import ServoModel, ServoProtocol
from robogest.backends.servos.wire import Register


class XReg(Register):
    """X-series (XL430-W250, XM430-W350, XL330-M288), Protocol 2.0."""

    MODEL_NUMBER = (0, 2)
    MODEL_INFORMATION = (2, 4)
    FIRMWARE_VERSION = (6, 1)
    ID = (7, 1)
    BAUD_RATE = (8, 1)
    RETURN_DELAY_TIME = (9, 1)
    DRIVE_MODE = (10, 1)
    OPERATING_MODE = (11, 1)
    SECONDARY_ID = (12, 1)
    PROTOCOL_TYPE = (13, 1)
    HOMING_OFFSET = (20, 4)
    MOVING_THRESHOLD = (24, 4)
    TEMPERATURE_LIMIT = (31, 1)
    MAX_VOLTAGE_LIMIT = (32, 2)
    MIN_VOLTAGE_LIMIT = (34, 2)
    PWM_LIMIT = (36, 2)
    CURRENT_LIMIT = (38, 2)
    VELOCITY_LIMIT = (44, 4)
    MAX_POSITION_LIMIT = (48, 4)
    MIN_POSITION_LIMIT = (52, 4)
    STARTUP_CONFIGURATION = (60, 1)
    SHUTDOWN = (63, 1)
    TORQUE_ENABLE = (64, 1)
    LED = (65, 1)
    STATUS_RETURN_LEVEL = (68, 1)
    REGISTERED_INSTRUCTION = (69, 1)
    HARDWARE_ERROR_STATUS = (70, 1)
    VELOCITY_I_GAIN = (76, 2)
    VELOCITY_P_GAIN = (78, 2)
    POSITION_D_GAIN = (80, 2)
    POSITION_I_GAIN = (82, 2)
    POSITION_P_GAIN = (84, 2)
    FEEDFORWARD_2ND_GAIN = (88, 2)
    FEEDFORWARD_1ST_GAIN = (90, 2)
    BUS_WATCHDOG = (98, 1)
    GOAL_PWM = (100, 2)
    GOAL_CURRENT = (102, 2)
    GOAL_VELOCITY = (104, 4)
    PROFILE_ACCELERATION = (108, 4)
    PROFILE_VELOCITY = (112, 4)
    GOAL_POSITION = (116, 4)
    REALTIME_TICK = (120, 2)
    MOVING = (122, 1)
    MOVING_STATUS = (123, 1)
    PRESENT_PWM = (124, 2)
    PRESENT_LOAD = (126, 2)  #: Present Current on XM430/XL330 (same address)
    PRESENT_VELOCITY = (128, 4)
    PRESENT_POSITION = (132, 4)
    VELOCITY_TRAJECTORY = (136, 4)
    POSITION_TRAJECTORY = (140, 4)
    PRESENT_INPUT_VOLTAGE = (144, 2)
    PRESENT_TEMPERATURE = (146, 1)
    BACKUP_READY = (147, 1)


class P1Reg(Register):
    """AX-12A / MX-28 on Protocol 1.0 (the registers both share)."""

    MODEL_NUMBER = (0, 2)
    FIRMWARE_VERSION = (2, 1)
    ID = (3, 1)
    BAUD_RATE = (4, 1)
    RETURN_DELAY_TIME = (5, 1)
    CW_ANGLE_LIMIT = (6, 2)
    CCW_ANGLE_LIMIT = (8, 2)
    TEMPERATURE_LIMIT = (11, 1)
    MIN_VOLTAGE_LIMIT = (12, 1)
    MAX_VOLTAGE_LIMIT = (13, 1)
    MAX_TORQUE = (14, 2)
    STATUS_RETURN_LEVEL = (16, 1)
    ALARM_LED = (17, 1)
    SHUTDOWN = (18, 1)
    TORQUE_ENABLE = (24, 1)
    LED = (25, 1)
    GOAL_POSITION = (30, 2)
    MOVING_SPEED = (32, 2)
    TORQUE_LIMIT = (34, 2)
    PRESENT_POSITION = (36, 2)
    PRESENT_SPEED = (38, 2)
    PRESENT_LOAD = (40, 2)
    PRESENT_VOLTAGE = (42, 1)
    PRESENT_TEMPERATURE = (43, 1)
    REGISTERED = (44, 1)
    MOVING = (46, 1)
    LOCK = (47, 1)
    PUNCH = (48, 2)
    GOAL_ACCELERATION = (73, 1)  #: MX-28 only (AX-12A has no acceleration register)


#: Registers holding signed values: two's complement on P2; sign-magnitude bit on P1.
X_SIGNED = {XReg.HOMING_OFFSET, XReg.GOAL_PWM, XReg.GOAL_VELOCITY, XReg.PRESENT_PWM, XReg.PRESENT_LOAD,
            XReg.PRESENT_VELOCITY, XReg.PRESENT_POSITION, XReg.GOAL_POSITION, XReg.VELOCITY_TRAJECTORY,
            XReg.POSITION_TRAJECTORY, XReg.GOAL_CURRENT}  # fmt: skip
P1_SIGN_BITS: dict[Enum, int] = {P1Reg.PRESENT_SPEED: 10, P1Reg.PRESENT_LOAD: 10}

#: Protocol 2.0 Hardware Error Status bits.
X_HW_ERRORS = {0x01: "input voltage", 0x04: "overheating", 0x08: "motor encoder", 0x10: "electrical shock",
               0x20: "overload"}  # fmt: skip
#: Protocol 1.0 status error bits.
P1_ERRORS = {0x01: "input voltage", 0x02: "angle limit", 0x04: "overheating", 0x08: "range", 0x10: "checksum",
             0x20: "overload", 0x40: "instruction"}  # fmt: skip
#: Protocol 2.0 status error codes (low 7 bits of the error byte).
X_STATUS_ERRORS = {1: "result fail", 2: "instruction error", 3: "CRC error", 4: "data range error",
                   5: "data length error", 6: "data limit error", 7: "access error"}  # fmt: skip

#: Baud Rate register value -> baud.
X_BAUDRATES = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000, 7: 4_500_000}


#: X-series Profile Acceleration unit: 214.577 rev/min² (e-manual, velocity-based profile), in rad/s².
X_ACCEL_UNIT_RAD_S2 = 214.577 * 2 * math.pi / 3600.0
#: MX-28 (Protocol 1.0) Goal Acceleration unit: 8.583 °/s² (e-manual), in rad/s²; values 0-254.
MX_ACCEL_UNIT_RAD_S2 = math.radians(8.583)


def _rpm(units_rpm: float) -> float:
    """A speed-cap register unit (X: Profile Velocity; AX/MX: Moving Speed) in rev/min, as rad/s."""
    return units_rpm * 2 * math.pi / 60


_P2, _P1 = ServoProtocol.DXL2, ServoProtocol.DXL1

#: Acceleration register (X: Profile Acceleration in velocity-based profile mode; MX-28: Goal Acceleration): unit in
#: rad/s² and largest value; AX-12A has none.
MODELS: dict[str, ServoModel] = {
    m.name: m
    for m in (
        ServoModel("XL430-W250", 1060, _P2, 4096, 2048, 4095, _rpm(0.229), 32767, X_ACCEL_UNIT_RAD_S2, 32767),
        ServoModel("XM430-W350", 1020, _P2, 4096, 2048, 4095, _rpm(0.229), 32767, X_ACCEL_UNIT_RAD_S2, 32767),
        ServoModel("XL330-M288", 1200, _P2, 4096, 2048, 4095, _rpm(0.229), 32767, X_ACCEL_UNIT_RAD_S2, 32767),
        ServoModel("AX-12A", 12, _P1, 1024 * 360 / 300, 512, 1023, _rpm(0.111), 1023),
        ServoModel("MX-28", 29, _P1, 4096, 2048, 4095, _rpm(0.114), 1023, MX_ACCEL_UNIT_RAD_S2, 254),
    )
}
