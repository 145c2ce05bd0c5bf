"""``robogest.__version__``: the installed distribution's version, looked up on first use (keeps import fast)."""

from __future__ import annotations

import re


def _version() -> str:
    """The installed version; from a checkout that was never installed, its ``pyproject.toml``'s; else ``0+unknown``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("robogest")
    except PackageNotFoundError:
        from robogest.extras import source_checkout

        root = source_checkout()
        found = root and re.search(r'^version\s*=\s*"([^"]+)"', (root / "pyproject.toml").read_text(), re.M)
        return found.group(1) if found else "0+unknown"


__version__ = _version()
