"""A named registry of factories: how generators and backends are found by name.

Third-party packages add entries through entry points (``[project.entry-points."robogest.generators"]``
``NAME = "package.module:factory"``). They are discovered on the first lookup and each is imported only
when its name is asked for, so a slow or broken plugin costs nothing until used. Built-in names win over
plugins of the same name (with a warning); a plugin that fails to import is an error naming the plugin
and the cause when it is asked for, and is never imported otherwise.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING, Generic, TypeVar

from robogest.errors import InputError, RobogestWarning

if TYPE_CHECKING:
    from importlib.metadata import EntryPoint

F = TypeVar("F", bound=Callable[..., object])


class Registry(Generic[F]):
    """``name -> factory``; ``register`` is a decorator, ``get`` names the choices when a name is unknown.

    ``entry_point_group`` (e.g. ``"robogest.backends"``) also offers the factories installed packages
    declare under that entry-point group.
    """

    def __init__(self, kind: str, entry_point_group: str | None = None) -> None:
        self.kind = kind
        self.entry_point_group = entry_point_group
        self._factories: dict[str, F] = {}
        self._plugins: dict[str, EntryPoint] | None = None  # discovered on first lookup, loaded on request
        self._loaded: set[str] = set()  # plugin names whose factory is now in _factories

    def register(self, name: str) -> Callable[[F], F]:
        def deco(factory: F) -> F:
            self._factories[name] = factory
            return factory

        return deco

    def _discover(self) -> dict[str, EntryPoint]:
        if self._plugins is None:
            self._plugins = {}
            if self.entry_point_group:
                from importlib.metadata import entry_points

                try:
                    found = list(entry_points(group=self.entry_point_group))
                except Exception as e:  # a broken installed distribution must not stop robogest
                    _warn(f"cannot read {self.entry_point_group} plugins: {type(e).__name__}: {e}")
                    found = []
                for ep in found:
                    if ep.name in self._factories:
                        _warn(f"{self.kind} plugin {ep.name!r} ({ep.value}) ignored: a built-in has that name")
                    else:
                        self._plugins.setdefault(ep.name, ep)  # first installed distribution wins
        return self._plugins

    def names(self) -> list[str]:
        return sorted({*self._factories, *self._discover()})

    def get(self, name: str) -> F:
        if name in self._factories:
            return self._factories[name]
        ep = self._discover().get(name)
        if ep is None:
            raise InputError(f"unknown {self.kind} {name!r}; choose one of {', '.join(self.names())}")
        dist = f" from package {ep.dist.name!r}" if ep.dist is not None else ""
        try:
            factory: F = ep.load()  # the entry point's object, checked callable below
        except Exception as e:  # any import-time failure of someone else's code: one line, no traceback
            raise InputError(
                f"{self.kind} {name!r} (plugin {ep.value}{dist}) failed to load: {type(e).__name__}: {e}; "
                "fix or uninstall that package"
            ) from None
        if not callable(factory):
            raise InputError(f"{self.kind} {name!r} (plugin {ep.value}{dist}) is not callable; fix that package")
        self._factories[name] = factory
        self._loaded.add(name)
        return factory

    def refresh(self) -> None:
        """Forget the plugins found so far, so that packages installed since then are found."""
        for name in self._loaded:
            del self._factories[name]
        self._loaded.clear()
        self._plugins = None


def _warn(message: str) -> None:
    warnings.warn(message, RobogestWarning, stacklevel=3)
