"""``base: NAME`` in a robot YAML: the file holds only what differs from another robot, found by name.

A calibrated copy (``robots import-lerobot-calibration``) names the robot it calibrates instead of copying it, so
it survives moving the YAML and reinstalling robogest (a copied relative ``model:`` path into site-packages did
not). Rules, applied when the file is loaded (docs/servos.md):

- the base is looked up by name: ``NAME.yaml`` beside the file first, then the robot search path
  (``$ROBOGEST_ROBOTS``, ``./robots``, the packaged robots; :mod:`robogest.robot.registry`);
- mappings merge key by key, at any depth (``bus``, ``bus.servos``, one servo's entry, ``import``);
- ``joints`` lists changes to the base's joints, matched by ``name``; a joint the base lacks is refused (a joint
  needs the MuJoCo model to have it);
- any other key replaces the base's (``retarget`` replaces the whole list); ``model``, when given, is relative to
  this file, else the base's model is used;
- ``name`` defaults to the file's name; a base may itself have a base (at most :data:`MAX_DEPTH` deep, no loops).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robogest.errors import ConfigError

if TYPE_CHECKING:
    from robogest.robot.config import RobotConfig

#: Longest chain of bases followed (a robot, its base, that one's base, ...).
MAX_DEPTH = 8


def resolve_base(
    raw: dict[str, Any], path: Path, chain: tuple[Path, ...], load: Callable[[Path, tuple[Path, ...]], RobotConfig]
) -> tuple[dict[str, Any], Path]:
    """``(raw merged onto its base robot's values, the base's YAML)``; ``load(path, chain)`` loads the base
    (validated on its own, so a broken base is named as such)."""
    from robogest.robot.registry import find_base

    name = raw["base"]
    if not isinstance(name, str) or not name or "/" in name or "\\" in name:
        raise ConfigError(
            f"{path}: key base: {name!r} is not a robot name; write the name of the robot this file changes, "
            "e.g. base: so101_sts3215 (`robogest robots list` shows the names)"
        )
    here = (*chain, path.resolve())
    if len(here) > MAX_DEPTH:
        raise ConfigError(f"{path}: key base: more than {MAX_DEPTH} bases deep; point base: at the robot itself")
    base_path = find_base(name, path)
    if base_path is None:
        from robogest.robot.registry import list_robots, search_path

        searched = ", ".join(dict.fromkeys(str(d) for d in [path.parent, *search_path()]))
        raise ConfigError(
            f"{path}: key base: unknown robot {name!r} (searched {searched}); known robots: "
            f"{', '.join(sorted(list_robots())) or '(none)'}; fix the name or add its folder to $ROBOGEST_ROBOTS"
        )
    if base_path.resolve() in here:
        loop = " -> ".join(str(p) for p in (*here, base_path.resolve()))
        raise ConfigError(f"{path}: key base: the bases loop ({loop}); a robot cannot be its own base")
    try:
        base = load(base_path, here)
    except ConfigError as e:
        raise ConfigError(f"{path}: key base: base robot {name!r} does not load: {e}") from None
    values = base.model_dump(mode="json", by_alias=True, exclude_none=True)
    values["model"] = str(base.model_path)  # the base's model, wherever this file lies
    merged = _merge_maps(values, {k: v for k, v in raw.items() if k not in ("base", "joints")})
    if "joints" in raw:
        merged["joints"] = _merge_joints(values["joints"], raw["joints"], path, name)
    merged["base"] = name
    if "name" not in raw:
        merged["name"] = path.stem
    return merged, base_path


def _merge_maps(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``over`` onto ``base``: mappings key by key at any depth, everything else replaced."""
    out = dict(base)
    for key, value in over.items():
        old = out.get(key)
        out[key] = _merge_maps(old, value) if isinstance(old, dict) and isinstance(value, dict) else value
    return out


def _merge_joints(base: list[dict[str, Any]], over: object, path: Path, name: str) -> list[dict[str, Any]]:
    """The base's joints, in its order, with the changes ``over`` lists for some of them."""
    names = [j["name"] for j in base]
    if not isinstance(over, list):
        raise ConfigError(
            f"{path}: key joints: with base: it lists changes to {name}'s joints, e.g. "
            "[{name: elbow, upper_rad: 1.2}]"
        )
    changes: dict[str, dict[str, Any]] = {}
    for k, j in enumerate(over):
        joint = j.get("name") if isinstance(j, dict) else None
        if not isinstance(joint, str) or joint not in names:  # names are the base's, all str
            raise ConfigError(
                f"{path}: key joints[{k}]: {joint!r} is not a joint of the base robot {name} (its joints: "
                f"{', '.join(names)}); with base: a file changes its base's joints, it cannot add any"
            )
        if joint in changes:
            raise ConfigError(f"{path}: key joints[{k}]: joint {joint!r} is listed twice; merge the two entries")
        changes[joint] = j
    return [{**j, **changes.get(j["name"], {})} for j in base]
