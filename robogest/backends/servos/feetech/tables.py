"""Feetech control tables used by the backend: STS/SMS (protocol 0, little-endian) and SCS (protocol 1,
big-endian). Enum value is ``(address, size_bytes)``. Source: Feetech STS/SMS and SCS memory tables.
"""

from __future__ import annotations

import math
from enum import Enum

from robogest.backends.servos.protocol import ServoModel, ServoProtocol
from robogest.backends.servos.wire import Register


class STSReg(Register):
    FIRMWARE_MAJOR_VERSION = (0, 1)
    FIRMWARE_MINOR_VERSION = (1, 1)
    MODEL_NUMBER = (3, 2)
    ID = (5, 1)
    BAUD_RATE = (6, 1)
    RETURN_DELAY_TIME = (7, 1)
    RESPONSE_STATUS_LEVEL = (8, 1)
    MIN_POSITION_LIMIT = (9, 2)
    MAX_POSITION_LIMIT = (11, 2)
    MAX_TEMPERATURE_LIMIT = (13, 1)
    MAX_VOLTAGE_LIMIT = (14, 1)
    MIN_VOLTAGE_LIMIT = (15, 1)
    MAX_TORQUE_LIMIT = (16, 2)
    PHASE = (18, 1)
    UNLOADING_CONDITION = (19, 1)
    LED_ALARM_CONDITION = (20, 1)
    P_COEFFICIENT = (21, 1)
    D_COEFFICIENT = (22, 1)
    I_COEFFICIENT = (23, 1)
    MINIMUM_STARTUP_FORCE = (24, 2)
    CW_DEAD_ZONE = (26, 1)
    CCW_DEAD_ZONE = (27, 1)
    PROTECTION_CURRENT = (28, 2)
    ANGULAR_RESOLUTION = (30, 1)
    HOMING_OFFSET = (31, 2)
    OPERATING_MODE = (33, 1)
    PROTECTIVE_TORQUE = (34, 1)
    PROTECTION_TIME = (35, 1)
    OVERLOAD_TORQUE = (36, 1)
    VELOCITY_P_COEFFICIENT = (37, 1)
    OVER_CURRENT_PROTECTION_TIME = (38, 1)
    VELOCITY_I_COEFFICIENT = (39, 1)
    TORQUE_ENABLE = (40, 1)
    ACCELERATION = (41, 1)
    GOAL_POSITION = (42, 2)
    GOAL_TIME = (44, 2)
    GOAL_VELOCITY = (46, 2)
    TORQUE_LIMIT = (48, 2)
    LOCK = (55, 1)
    PRESENT_POSITION = (56, 2)
    PRESENT_VELOCITY = (58, 2)
    PRESENT_LOAD = (60, 2)
    PRESENT_VOLTAGE = (62, 1)
    PRESENT_TEMPERATURE = (63, 1)
    STATUS = (65, 1)
    MOVING = (66, 1)
    PRESENT_CURRENT = (69, 2)


class SCSReg(Register):
    FIRMWARE_MAJOR_VERSION = (0, 1)
    FIRMWARE_MINOR_VERSION = (1, 1)
    MODEL_NUMBER = (3, 2)
    ID = (5, 1)
    BAUD_RATE = (6, 1)
    RETURN_DELAY_TIME = (7, 1)
    RESPONSE_STATUS_LEVEL = (8, 1)
    MIN_POSITION_LIMIT = (9, 2)
    MAX_POSITION_LIMIT = (11, 2)
    MAX_TEMPERATURE_LIMIT = (13, 1)
    MAX_VOLTAGE_LIMIT = (14, 1)
    MIN_VOLTAGE_LIMIT = (15, 1)
    MAX_TORQUE_LIMIT = (16, 2)
    TORQUE_ENABLE = (40, 1)
    ACCELERATION = (41, 1)
    GOAL_POSITION = (42, 2)
    RUNNING_TIME = (44, 2)
    GOAL_VELOCITY = (46, 2)
    LOCK = (48, 1)
    PRESENT_POSITION = (56, 2)
    PRESENT_VELOCITY = (58, 2)
    PRESENT_LOAD = (60, 2)
    PRESENT_VOLTAGE = (62, 1)
    PRESENT_TEMPERATURE = (63, 1)
    STATUS = (65, 1)
    MOVING = (66, 1)


#: Sign-magnitude encodings: register -> sign bit (STS quirk; SCS positions are unsigned).
STS_SIGN_BITS: dict[Enum, int] = {
    STSReg.HOMING_OFFSET: 11,
    STSReg.GOAL_POSITION: 15,
    STSReg.GOAL_VELOCITY: 15,
    STSReg.PRESENT_POSITION: 15,
    STSReg.PRESENT_VELOCITY: 15,
    STSReg.PRESENT_LOAD: 10,
    STSReg.PRESENT_CURRENT: 15,
}
SCS_SIGN_BITS: dict[Enum, int] = {SCSReg.PRESENT_VELOCITY: 15, SCSReg.PRESENT_LOAD: 10}

#: Status error bits (same layout as Dynamixel Protocol 1.0).
FT_ERRORS = {0x01: "input voltage", 0x02: "angle sensor", 0x04: "overheating", 0x08: "overcurrent",
             0x20: "overload", 0x40: "instruction/access"}  # fmt: skip

FT_BAUDRATES = {0: 1_000_000, 1: 500_000, 2: 250_000, 3: 128_000, 4: 115_200, 5: 57_600, 6: 38_400, 7: 19_200}


#: Feetech speeds are in position steps per second: the speed-cap register (Goal Velocity) counts steps/s, the
#: Acceleration register (address 41, RAM) 100 steps/s², 0-254 on STS/SMS (Feetech ST3215 memory table: "10
#: corresponds to 1000 steps per second squared"); SCS models have none (Feetech's own SCSCL library documents no
#: acceleration register; its WritePosEx drops the argument).
_STEP_RAD = 2 * math.pi / 4096
_SCS_STEP_RAD = 2 * math.pi / (1024 * 360 / 300)
_STS, _SCS = ServoProtocol.STS, ServoProtocol.SCS

MODELS: dict[str, ServoModel] = {
    m.name: m
    for m in (
        ServoModel("STS3215", 777, _STS, 4096, 2048, 4095, _STEP_RAD, 32767, 100.0 * _STEP_RAD, 254),
        ServoModel("STS3250", 2825, _STS, 4096, 2048, 4095, _STEP_RAD, 32767, 100.0 * _STEP_RAD, 254),
        ServoModel("SCS0009", 1284, _SCS, 1024 * 360 / 300, 512, 1023, _SCS_STEP_RAD, 1023),
    )
}
