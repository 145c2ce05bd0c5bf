"""Build glue that ``pyproject.toml`` cannot express: the robots travel inside the wheel.

The repository keeps robot definitions in the top-level ``robots/`` and their MuJoCo models in ``sim/``;
the wheel carries them as ``robogest/_assets/robots`` and ``robogest/_assets/sim`` (same relative layout,
so a YAML's ``model: ../sim/...`` still points at its model). ``robogest.robot.registry.robots_dir``
finds them there, or in the checkout when robogest runs from source (editable install, PYTHONPATH).
"""

from pathlib import Path

from setuptools import find_packages, setup

#: Data-only packages in the wheel -> the repository folders they are copied from.
ASSETS = {"robogest._assets.robots": "robots", "robogest._assets.sim": "sim"}


def asset_packages() -> list[str]:
    """Every folder under the asset roots, named as a package (setuptools copies package data per package)."""
    here = Path(__file__).parent
    names = []
    for pkg, root in ASSETS.items():
        for d in [here / root, *sorted(p for p in (here / root).rglob("*") if p.is_dir() and p.name != "__pycache__")]:
            names.append(".".join([pkg, *d.relative_to(here / root).parts]))
    return names


setup(
    packages=[*find_packages(include=["robogest*"]), *asset_packages()],
    package_dir=ASSETS,
    package_data={
        "robogest": ["py.typed"],
        "robogest.generators": ["gestures/*.yaml"],
        **{name: ["*"] for name in asset_packages()},
    },
)
