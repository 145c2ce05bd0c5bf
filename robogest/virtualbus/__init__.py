"""A simulated Dynamixel/Feetech servo bus on a pseudo-terminal, for testing backends without hardware."""

from robogest.virtualbus.bus import VirtualBus
from robogest.virtualbus.faults import FaultSpec
from robogest.virtualbus.servo import ThermalModel

__all__ = ["FaultSpec", "ThermalModel", "VirtualBus"]
