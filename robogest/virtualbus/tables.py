"""Control tables of the emulated servo models, typed in from the vendors' manuals.

This file belongs to the *simulated* bus only: the backends keep their own register tables
(``robogest/backends/servos/*/tables.py``) so that a typo on one side shows up as a test failure instead of
being shared by the code under test and the code that checks it.

Sources: ROBOTIS e-manual (XL430-W250, XM430-W350, XL330-M288, AX-12A, MX-28 Protocol 1.0) and the
Feetech STS/SMS and SCS memory tables (STS3215, SCS0009, including their writable factory areas).

EEPROM protection differs by family (:meth:`~robogest.virtualbus.servo.SimServo.check_write`): X-series
refuse EEPROM writes while torque is on; AX/MX with Lock = 1 accept writes to addresses 24-35 only, until
power-off; Feetech accept every write, and Lock (0 = unlocked) only decides whether an EEPROM write
survives a power cycle. Return Delay Time is in units of 2 us on every model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Reg:
    """One register: ``size`` bytes at ``addr``; ``sign_bit`` set for Feetech/P1 sign-magnitude values."""

    name: str
    addr: int
    size: int
    writable: bool = False
    default: int = 0
    signed: bool = False  #: two's complement (Dynamixel P2 velocities, loads, offsets)
    sign_bit: int | None = None  #: sign-magnitude, bit holding the sign (Feetech, Dynamixel P1 speed/load)
    lo: int | None = None  #: writes below are answered with a range error
    hi: int | None = None
    allowed: tuple[int, ...] | None = None  #: the only values accepted (e.g. a model's operating modes)


@dataclass(frozen=True)
class ModelSpec:
    """Everything the emulator needs to impersonate one servo model.

    ``roles`` maps generic role names (``goal``, ``present``, ``torque``, ...) to register names of
    this table so the servo dynamics can be written once for every family.
    """

    name: str
    family: str  #: "dynamixel" or "feetech"
    protocols: tuple[float, ...]
    model_number: int
    regs: tuple[Reg, ...]
    eeprom_end: int  #: addresses below are EEPROM
    ticks_per_rev: float
    centre_tick: int
    max_tick: int
    baud_table: dict[int, int]  #: register value -> baud rate
    roles: dict[str, str]
    nominal_voltage_dv: int  #: present voltage reading, 0.1 V
    vel_unit_ticks_s: float  #: one unit of the velocity registers in ticks/s
    acc_unit_ticks_s2: float  #: one unit of the acceleration register in ticks/s² (0 = unlimited)
    max_speed_ticks_s: float  #: no-load speed
    big_endian: bool = False
    eeprom_locked_by_torque: bool = True  #: Dynamixel P2; P1/Feetech use a Lock register instead
    return_delay_unit_s: float = 2e-6  #: one unit of Return_Delay_Time
    by_name: dict[str, Reg] = field(default_factory=dict, compare=False)
    by_addr: dict[int, Reg] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        for r in self.regs:
            self.by_name[r.name] = r
            self.by_addr[r.addr] = r

    @property
    def table_size(self) -> int:
        return max(r.addr + r.size for r in self.regs)

    def reg(self, role: str) -> Reg:
        return self.by_name[self.roles.get(role, role)]

    def ticks_per_rad(self) -> float:
        return self.ticks_per_rev / (2 * math.pi)


def _R(name: str, addr: int, size: int, access: str = "R", default: int = 0, **kw: object) -> Reg:
    return Reg(name, addr, size, access == "RW", default, **kw)  # type: ignore[arg-type]


#: Role -> register name where every family names the register alike.
_COMMON_ROLES = {
    "goal": "Goal_Position", "present": "Present_Position", "torque": "Torque_Enable", "load": "Present_Load",
    "temperature": "Present_Temperature", "moving": "Moving", "id": "ID", "baud": "Baud_Rate",
}  # fmt: skip

# --- Dynamixel X-series, Protocol 2.0 --------------------------------------------------------------
_X_BAUD = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000, 7: 4_500_000}


def _x_series(
    model_number: int, fw: int, *, current: bool, vel_limit: int, temp_limit: int, vmax: int, vmin: int, volts: int
) -> tuple[Reg, ...]:
    regs = [
        _R("Model_Number", 0, 2, default=model_number),
        _R("Model_Information", 2, 4),
        _R("Firmware_Version", 6, 1, default=fw),
        _R("ID", 7, 1, "RW", 1, lo=0, hi=252),
        _R("Baud_Rate", 8, 1, "RW", 1, lo=0, hi=7),
        _R("Return_Delay_Time", 9, 1, "RW", 250),
        _R("Drive_Mode", 10, 1, "RW", 0),
        _R("Operating_Mode", 11, 1, "RW", 3, allowed=(0, 1, 3, 4, 5, 16) if current else (1, 3, 4, 16)),
        _R("Secondary_ID", 12, 1, "RW", 255),
        _R("Protocol_Type", 13, 1, "RW", 2),
        _R("Homing_Offset", 20, 4, "RW", 0, signed=True),
        _R("Moving_Threshold", 24, 4, "RW", 10),
        _R("Temperature_Limit", 31, 1, "RW", temp_limit, lo=0, hi=100),
        _R("Max_Voltage_Limit", 32, 2, "RW", vmax),
        _R("Min_Voltage_Limit", 34, 2, "RW", vmin),
        _R("PWM_Limit", 36, 2, "RW", 885, lo=0, hi=885),
        _R("Velocity_Limit", 44, 4, "RW", vel_limit, lo=0, hi=1023),
        _R("Max_Position_Limit", 48, 4, "RW", 4095, lo=0, hi=4095),
        _R("Min_Position_Limit", 52, 4, "RW", 0, lo=0, hi=4095),
        _R("Startup_Configuration", 60, 1, "RW", 0),
        _R("Shutdown", 63, 1, "RW", 52),
        _R("Torque_Enable", 64, 1, "RW", 0, lo=0, hi=1),
        _R("LED", 65, 1, "RW", 0, lo=0, hi=1),
        _R("Status_Return_Level", 68, 1, "RW", 2, lo=0, hi=2),
        _R("Registered_Instruction", 69, 1),
        _R("Hardware_Error_Status", 70, 1),
        _R("Velocity_I_Gain", 76, 2, "RW", 1000),
        _R("Velocity_P_Gain", 78, 2, "RW", 100),
        _R("Position_D_Gain", 80, 2, "RW", 4000),
        _R("Position_I_Gain", 82, 2, "RW", 0),
        _R("Position_P_Gain", 84, 2, "RW", 640),
        _R("Feedforward_2nd_Gain", 88, 2, "RW", 0),
        _R("Feedforward_1st_Gain", 90, 2, "RW", 0),
        _R("Bus_Watchdog", 98, 1, "RW", 0),
        _R("Goal_PWM", 100, 2, "RW", 885, signed=True),
        _R("Goal_Velocity", 104, 4, "RW", 0, signed=True),
        _R("Profile_Acceleration", 108, 4, "RW", 0, lo=0, hi=32767),
        _R("Profile_Velocity", 112, 4, "RW", 0, lo=0, hi=32767),
        _R("Goal_Position", 116, 4, "RW", 2048, signed=True),
        _R("Realtime_Tick", 120, 2),
        _R("Moving", 122, 1),
        _R("Moving_Status", 123, 1),
        _R("Present_PWM", 124, 2, signed=True),
        _R("Present_Current" if current else "Present_Load", 126, 2, signed=True),
        _R("Present_Velocity", 128, 4, signed=True),
        _R("Present_Position", 132, 4, default=2048, signed=True),
        _R("Velocity_Trajectory", 136, 4, signed=True),
        _R("Position_Trajectory", 140, 4, signed=True),
        _R("Present_Input_Voltage", 144, 2, default=volts),
        _R("Present_Temperature", 146, 1, default=30),
        _R("Backup_Ready", 147, 1),
    ]
    if current:
        regs += [
            _R("Current_Limit", 38, 2, "RW", 1193 if model_number == 1020 else 1750),
            _R("Goal_Current", 102, 2, "RW"),
        ]
    for n in range(28):  # indirect addresses point at their own data slot by default
        regs.append(_R(f"Indirect_Address_{n + 1}", 168 + 2 * n, 2, "RW", 224 + n))
        regs.append(_R(f"Indirect_Data_{n + 1}", 224 + n, 1, "RW", 0))
    return tuple(sorted(regs, key=lambda r: r.addr))


_X_ROLES = {
    **_COMMON_ROLES,
    "velocity": "Present_Velocity",
    "voltage": "Present_Input_Voltage",
    "hw_error": "Hardware_Error_Status",
    "min": "Min_Position_Limit",
    "max": "Max_Position_Limit",
    "profile_velocity": "Profile_Velocity",
    "profile_acceleration": "Profile_Acceleration",
    "status_level": "Status_Return_Level",
    "shutdown": "Shutdown",
}
_RPM_TICKS = 4096 / 60.0  # ticks/s per rpm


def _x_spec(
    name: str, number: int, *, current: bool, vel_limit: int, volts: int, vmax: int, vmin: int, temp: int
) -> ModelSpec:
    roles = dict(_X_ROLES)
    if current:
        roles["load"] = "Present_Current"
    return ModelSpec(
        name=name,
        family="dynamixel",
        protocols=(2.0,),
        model_number=number,
        regs=_x_series(
            number, 46, current=current, vel_limit=vel_limit, temp_limit=temp, vmax=vmax, vmin=vmin, volts=volts
        ),
        eeprom_end=64,
        ticks_per_rev=4096,
        centre_tick=2048,
        max_tick=4095,
        baud_table=_X_BAUD,
        roles=roles,
        nominal_voltage_dv=volts,
        vel_unit_ticks_s=0.229 * _RPM_TICKS,
        acc_unit_ticks_s2=214.577 * 4096 / 3600.0,
        max_speed_ticks_s=vel_limit * 0.229 * _RPM_TICKS,
    )


# --- Dynamixel AX/MX, Protocol 1.0 ----------------------------------------------------------------
def _p1_baud() -> dict[int, int]:
    return {v: round(2_000_000 / (v + 1)) for v in range(254)}


def _p1_table(number: int, fw: int, *, mx: bool) -> tuple[Reg, ...]:
    top = 4095 if mx else 1023
    regs = [
        _R("Model_Number", 0, 2, default=number),
        _R("Firmware_Version", 2, 1, default=fw),
        _R("ID", 3, 1, "RW", 1, lo=0, hi=253),
        _R("Baud_Rate", 4, 1, "RW", 34 if mx else 1),
        _R("Return_Delay_Time", 5, 1, "RW", 250),
        _R("CW_Angle_Limit", 6, 2, "RW", 0, lo=0, hi=top),
        _R("CCW_Angle_Limit", 8, 2, "RW", top, lo=0, hi=top),
        _R("Temperature_Limit", 11, 1, "RW", 80 if mx else 70),
        _R("Min_Voltage_Limit", 12, 1, "RW", 60),
        _R("Max_Voltage_Limit", 13, 1, "RW", 160 if mx else 140),
        _R("Max_Torque", 14, 2, "RW", 1023, lo=0, hi=1023),
        _R("Status_Return_Level", 16, 1, "RW", 2, lo=0, hi=2),
        _R("Alarm_LED", 17, 1, "RW", 36),
        _R("Shutdown", 18, 1, "RW", 36),
        _R("Torque_Enable", 24, 1, "RW", 0, lo=0, hi=1),
        _R("LED", 25, 1, "RW", 0, lo=0, hi=1),
        _R("Goal_Position", 30, 2, "RW", top // 2 + 1, lo=0, hi=top),
        _R("Moving_Speed", 32, 2, "RW", 0, lo=0, hi=2047),
        _R("Torque_Limit", 34, 2, "RW", 1023, lo=0, hi=1023),
        _R("Present_Position", 36, 2, default=top // 2 + 1),
        _R("Present_Speed", 38, 2, sign_bit=10),
        _R("Present_Load", 40, 2, sign_bit=10),
        _R("Present_Voltage", 42, 1, default=120),
        _R("Present_Temperature", 43, 1, default=30),
        _R("Registered", 44, 1),
        _R("Moving", 46, 1),
        _R("Lock", 47, 1, "RW", 0, lo=0, hi=1),
        _R("Punch", 48, 2, "RW", 0 if mx else 32),
    ]
    if mx:
        regs += [
            _R("Multi_Turn_Offset", 20, 2, "RW", 0),
            _R("Resolution_Divider", 22, 1, "RW", 1),
            _R("D_Gain", 26, 1, "RW", 0),
            _R("I_Gain", 27, 1, "RW", 0),
            _R("P_Gain", 28, 1, "RW", 32),
            _R("Goal_Acceleration", 73, 1, "RW", 0, lo=0, hi=254),
        ]
    else:
        regs += [
            _R("CW_Compliance_Margin", 26, 1, "RW", 1),
            _R("CCW_Compliance_Margin", 27, 1, "RW", 1),
            _R("CW_Compliance_Slope", 28, 1, "RW", 32),
            _R("CCW_Compliance_Slope", 29, 1, "RW", 32),
        ]
    return tuple(sorted(regs, key=lambda r: r.addr))


_P1_ROLES = {
    **_COMMON_ROLES,
    "velocity": "Present_Speed",
    "voltage": "Present_Voltage",
    "min": "CW_Angle_Limit",
    "max": "CCW_Angle_Limit",
    "profile_velocity": "Moving_Speed",
    "status_level": "Status_Return_Level",
    "shutdown": "Shutdown",
    "lock": "Lock",
}

# --- Feetech STS (little-endian) and SCS (big-endian) ---------------------------------------------
_FT_BAUD = {0: 1_000_000, 1: 500_000, 2: 250_000, 3: 128_000, 4: 115_200, 5: 57_600, 6: 38_400, 7: 19_200}


def _sts_table(number: int) -> tuple[Reg, ...]:
    return (
        _R("Firmware_Major_Version", 0, 1, default=3),
        _R("Firmware_Minor_Version", 1, 1, default=6),
        _R("Model_Number", 3, 2, default=number),
        _R("ID", 5, 1, "RW", 1, lo=0, hi=253),
        _R("Baud_Rate", 6, 1, "RW", 0, lo=0, hi=7),
        _R("Return_Delay_Time", 7, 1, "RW", 0),
        _R("Response_Status_Level", 8, 1, "RW", 1, lo=0, hi=1),
        _R("Min_Position_Limit", 9, 2, "RW", 0, lo=0, hi=4095),
        _R("Max_Position_Limit", 11, 2, "RW", 4095, lo=0, hi=4095),
        _R("Max_Temperature_Limit", 13, 1, "RW", 70),
        _R("Max_Voltage_Limit", 14, 1, "RW", 80),
        _R("Min_Voltage_Limit", 15, 1, "RW", 40),
        _R("Max_Torque_Limit", 16, 2, "RW", 1000, lo=0, hi=1000),
        _R("Phase", 18, 1, "RW", 12),
        _R("Unloading_Condition", 19, 1, "RW", 44),
        _R("LED_Alarm_Condition", 20, 1, "RW", 47),
        _R("P_Coefficient", 21, 1, "RW", 32),
        _R("D_Coefficient", 22, 1, "RW", 32),
        _R("I_Coefficient", 23, 1, "RW", 0),
        _R("Minimum_Startup_Force", 24, 2, "RW", 16),
        _R("CW_Dead_Zone", 26, 1, "RW", 1),
        _R("CCW_Dead_Zone", 27, 1, "RW", 1),
        _R("Protection_Current", 28, 2, "RW", 500),
        _R("Angular_Resolution", 30, 1, "RW", 1),
        _R("Homing_Offset", 31, 2, "RW", 0, sign_bit=11),
        _R("Operating_Mode", 33, 1, "RW", 0, lo=0, hi=3),
        _R("Protective_Torque", 34, 1, "RW", 20),
        _R("Protection_Time", 35, 1, "RW", 200),
        _R("Overload_Torque", 36, 1, "RW", 80),
        _R("Velocity_P_Coefficient", 37, 1, "RW", 10),
        _R("Over_Current_Protection_Time", 38, 1, "RW", 200),
        _R("Velocity_I_Coefficient", 39, 1, "RW", 200),
        _R("Torque_Enable", 40, 1, "RW", 0, lo=0, hi=2),
        _R("Acceleration", 41, 1, "RW", 0),
        _R("Goal_Position", 42, 2, "RW", 2048, sign_bit=15),
        _R("Goal_Time", 44, 2, "RW", 0),
        _R("Goal_Velocity", 46, 2, "RW", 0, sign_bit=15),
        _R("Torque_Limit", 48, 2, "RW", 1000, lo=0, hi=1000),
        _R("Lock", 55, 1, "RW", 0, lo=0, hi=1),
        _R("Present_Position", 56, 2, default=2048, sign_bit=15),
        _R("Present_Velocity", 58, 2, sign_bit=15),
        _R("Present_Load", 60, 2, sign_bit=10),
        _R("Present_Voltage", 62, 1, default=74),
        _R("Present_Temperature", 63, 1, default=30),
        _R("Status", 65, 1),
        _R("Moving", 66, 1),
        _R("Present_Current", 69, 2, sign_bit=15),
        _R("Goal_Position_2", 71, 2),
        # Factory area, writable (LeRobot's configure_motors() writes Maximum_Acceleration, address 85)
        _R("Moving_Velocity_Threshold", 80, 1, "RW", 1),
        _R("DTs", 81, 1, "RW", 1),
        _R("Velocity_Unit_Factor", 82, 1, "RW", 1),
        _R("Hts", 83, 1, "RW", 0),
        _R("Maximum_Velocity_Limit", 84, 1, "RW", 254),
        _R("Maximum_Acceleration", 85, 1, "RW", 254),
        _R("Acceleration_Multiplier", 86, 1, "RW", 0),
    )


def _scs_table(number: int) -> tuple[Reg, ...]:
    return (
        _R("Firmware_Major_Version", 0, 1, default=1),
        _R("Firmware_Minor_Version", 1, 1, default=8),
        _R("Model_Number", 3, 2, default=number),
        _R("ID", 5, 1, "RW", 1, lo=0, hi=253),
        _R("Baud_Rate", 6, 1, "RW", 0, lo=0, hi=7),
        _R("Return_Delay_Time", 7, 1, "RW", 0),
        _R("Response_Status_Level", 8, 1, "RW", 1, lo=0, hi=1),
        _R("Min_Position_Limit", 9, 2, "RW", 0, lo=0, hi=1023),
        _R("Max_Position_Limit", 11, 2, "RW", 1023, lo=0, hi=1023),
        _R("Max_Temperature_Limit", 13, 1, "RW", 70),
        _R("Max_Voltage_Limit", 14, 1, "RW", 90),
        _R("Min_Voltage_Limit", 15, 1, "RW", 40),
        _R("Max_Torque_Limit", 16, 2, "RW", 1000, lo=0, hi=1000),
        _R("Phase", 18, 1, "RW", 0),
        _R("Unloading_Condition", 19, 1, "RW", 37),
        _R("LED_Alarm_Condition", 20, 1, "RW", 37),
        _R("P_Coefficient", 21, 1, "RW", 15),
        _R("D_Coefficient", 22, 1, "RW", 0),
        _R("I_Coefficient", 23, 1, "RW", 0),
        _R("Minimum_Startup_Force", 24, 2, "RW", 10),
        _R("CW_Dead_Zone", 26, 1, "RW", 1),
        _R("CCW_Dead_Zone", 27, 1, "RW", 1),
        _R("Protective_Torque", 37, 1, "RW", 20),
        _R("Protection_Time", 38, 1, "RW", 200),
        _R("Torque_Enable", 40, 1, "RW", 0, lo=0, hi=1),
        _R("Acceleration", 41, 1, "RW", 0),
        _R("Goal_Position", 42, 2, "RW", 512, lo=0, hi=1023),
        _R("Running_Time", 44, 2, "RW", 0),
        _R("Goal_Velocity", 46, 2, "RW", 0),
        _R("Lock", 48, 1, "RW", 0, lo=0, hi=1),
        _R("Present_Position", 56, 2, default=512),
        _R("Present_Velocity", 58, 2, sign_bit=15),
        _R("Present_Load", 60, 2, sign_bit=10),
        _R("Present_Voltage", 62, 1, default=50),
        _R("Present_Temperature", 63, 1, default=30),
        _R("Sync_Write_Flag", 64, 1),
        _R("Status", 65, 1),
        _R("Moving", 66, 1),
        # Factory area, writable
        _R("PWM_Maximum_Step", 78, 1, "RW", 0),
        _R("Moving_Velocity_Threshold", 79, 1, "RW", 1),
        _R("DTs", 80, 1, "RW", 1),
        _R("Minimum_Velocity_Limit", 81, 1, "RW", 0),
        _R("Maximum_Velocity_Limit", 82, 1, "RW", 254),
        _R("Acceleration_2", 83, 1, "RW", 0),
    )


_FT_ROLES = {
    **_COMMON_ROLES,
    "velocity": "Present_Velocity",
    "voltage": "Present_Voltage",
    "min": "Min_Position_Limit",
    "max": "Max_Position_Limit",
    "profile_velocity": "Goal_Velocity",
    "profile_acceleration": "Acceleration",
    "status_level": "Response_Status_Level",
    "lock": "Lock",
}

MODELS: dict[str, ModelSpec] = {
    "XL430-W250": _x_spec("XL430-W250", 1060, current=False, vel_limit=265, volts=120, vmax=140, vmin=60, temp=72),
    "XM430-W350": _x_spec("XM430-W350", 1020, current=True, vel_limit=200, volts=120, vmax=160, vmin=95, temp=80),
    "XL330-M288": _x_spec("XL330-M288", 1200, current=True, vel_limit=445, volts=50, vmax=70, vmin=35, temp=70),
    "AX-12A": ModelSpec(
        name="AX-12A",
        family="dynamixel",
        protocols=(1.0,),
        model_number=12,
        regs=_p1_table(12, 24, mx=False),
        eeprom_end=24,
        ticks_per_rev=1024 * 360 / 300,
        centre_tick=512,
        max_tick=1023,
        baud_table=_p1_baud(),
        roles=_P1_ROLES,
        nominal_voltage_dv=120,
        vel_unit_ticks_s=0.111 * 1024 * 360 / 300 / 60,
        acc_unit_ticks_s2=0.0,
        max_speed_ticks_s=59 * 1024 * 360 / 300 / 60,
        eeprom_locked_by_torque=False,
    ),
    "MX-28": ModelSpec(
        name="MX-28",
        family="dynamixel",
        protocols=(1.0,),
        model_number=29,
        regs=_p1_table(29, 30, mx=True),
        eeprom_end=24,
        ticks_per_rev=4096,
        centre_tick=2048,
        max_tick=4095,
        baud_table=_p1_baud(),
        roles={**_P1_ROLES, "profile_acceleration": "Goal_Acceleration"},
        nominal_voltage_dv=120,
        vel_unit_ticks_s=0.114 * _RPM_TICKS,
        acc_unit_ticks_s2=8.583 * 4096 / 360,
        max_speed_ticks_s=55 * _RPM_TICKS,
        eeprom_locked_by_torque=False,
    ),
    "STS3215": ModelSpec(
        name="STS3215",
        family="feetech",
        protocols=(0.0,),
        model_number=777,
        regs=_sts_table(777),
        eeprom_end=40,
        ticks_per_rev=4096,
        centre_tick=2048,
        max_tick=4095,
        baud_table=_FT_BAUD,
        roles=_FT_ROLES,
        nominal_voltage_dv=74,
        vel_unit_ticks_s=1.0,
        acc_unit_ticks_s2=100.0,
        max_speed_ticks_s=3073.0,
        eeprom_locked_by_torque=False,
    ),
    "SCS0009": ModelSpec(
        name="SCS0009",
        family="feetech",
        protocols=(1.0,),
        model_number=1284,
        regs=_scs_table(1284),
        eeprom_end=40,
        ticks_per_rev=1024 * 360 / 300,
        centre_tick=512,
        max_tick=1023,
        baud_table=_FT_BAUD,
        roles=_FT_ROLES,
        nominal_voltage_dv=50,
        vel_unit_ticks_s=1.0,
        acc_unit_ticks_s2=100.0,
        max_speed_ticks_s=800.0,
        big_endian=True,
        eeprom_locked_by_torque=False,
    ),
}


def find_model(name: str) -> ModelSpec:
    """Look a model up by name, forgiving case, dashes and a missing suffix (``xl430`` -> XL430-W250)."""
    key = name.upper().replace("-", "").replace("_", "")
    for spec in MODELS.values():
        full = spec.name.replace("-", "")
        if key in (full, full.split("W")[0], full.split("M")[0]) or full.startswith(key):
            return spec
    raise KeyError(name)
