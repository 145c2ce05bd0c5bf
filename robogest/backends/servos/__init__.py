"""Serial servo families, each one folder: ``dynamixel/`` and ``feetech/``.

Shared here, written once for every family:

- :mod:`.protocol`: :class:`ServoProtocol` (the one protocol enum) and :class:`ServoModel` (the one model record);
- :mod:`.sdk`: the parts of the vendor SDKs robogest calls, as typing Protocols;
- :mod:`.wire`: what a family declares about each protocol it speaks (SDK, status layout, control table, signs);
- :mod:`.transport`: the one transport (port opened exclusively, raw transactions, late replies, retries) that the
  backends and bring-up share;
- :mod:`.bus_io` and :mod:`.bus`: the servo backend base (rad <-> tick mapping, retries and budgets, connect,
  torque and health checks, safe shutdown);
- :mod:`.bringup`, :mod:`.setup`, :mod:`.check`: scan and doctor, find-port and setup, the servo check before
  torque goes on.

A family folder holds ``__init__.py`` (registers its :class:`~.wire.Wire` per protocol and imports its backend),
``tables.py`` (registers, model records, error bits) and ``backend.py`` (a :class:`~.bus.ServoBackend` subclass
with its quirks). :mod:`robogest.backends` imports every folder here, so a new family is one new folder (plus its
member in :class:`ServoProtocol`). Radians at every public API; ticks stay inside this package.
"""

from robogest.backends.servos.protocol import ServoModel, ServoProtocol

__all__ = ["ServoModel", "ServoProtocol"]
