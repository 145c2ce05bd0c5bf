"""Backends: what moves. ``sim`` (MuJoCo) and every servo family folder in :mod:`robogest.backends.servos`
(``dynamixel``, ``feetech``) register themselves on import; each family imports its SDK only when a port is opened,
so importing this package stays cheap."""

from importlib import import_module
from pkgutil import iter_modules

from robogest.backends import servos as _servos
from robogest.backends.base import Backend, backend_names, get_backend_factory, register_backend

import_module("robogest.backends.mujoco_sim")
for _family in iter_modules(_servos.__path__):
    if _family.ispkg:  # a servo family is one folder
        import_module(f"robogest.backends.servos.{_family.name}")

__all__ = ["Backend", "backend_names", "get_backend_factory", "register_backend"]
