"""Imports flow down the pipeline: no module of robogest imports from a package in a higher layer.

Every module is parsed with ``ast`` (nothing is imported): top-level imports, imports inside functions and under
``TYPE_CHECKING``, and the targets of the lazy-name tables (``_LAZY``) all count. The layer list is the one in
docs/pipeline.md; a package may import from packages in lower layers only, never from a sibling in its own layer.
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "robogest"

#: Lowest first. "robogest" is the package root (a facade of lazy names), at the top with the CLI; ``__main__``
#: (``python -m robogest``) runs the CLI.
LAYERS: list[set[str]] = [
    {"errors", "_lazy"},
    {"fileio", "registry", "extras"},
    {"robot", "_version", "media"},  # schema, registry, MJCF loader, YAML writer, problems; MP4/PNG/audio out
    {"speech", "motion"},
    {"text"},
    {"data"},
    {"learn"},
    {"generators"},
    {"retarget"},
    {"safety", "trajectory"},
    {"backends", "virtualbus"},  # the simulated bus shares no code with the backends it tests
    {"tools", "pipeline", "viz"},
    {"eval", "live"},
    {"integrations", "aio"},
    {"cli", "robogest"},
    {"__main__"},
]

#: (importing module, imported module) pairs allowed against the layers, each with its reason. Empty: none needed.
EXCEPTIONS: dict[tuple[str, str], str] = {}


def _module_name(path: Path, root: Path = ROOT) -> str:
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _targets(path: Path, root: Path = ROOT) -> list[tuple[str, int]]:
    """Every robogest module ``path`` imports, with the line: absolute, relative, ``from robogest import x``
    (``robogest.x`` when x is a module) and the values of a ``_LAZY`` name table."""
    name = _module_name(path, root)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(up + ([node.module] if node.module else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                where = root.parent / sub.replace(".", "/")
                is_module = where.with_suffix(".py").is_file() or where.is_dir()
                out.append((sub if is_module else base, node.lineno))
        elif isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict) and _is_lazy_table(node):
            out += [(v.value, node.lineno) for v in node.value.values if isinstance(v, ast.Constant)]
    return [(t, line) for t, line in out if t == "robogest" or t.startswith("robogest.")]


def _is_lazy_table(node: ast.Assign) -> bool:
    return any(isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets)


def _package(module: str) -> str:
    """The top-level package of a robogest module (``robogest`` itself for the package root)."""
    parts = module.split(".")
    return parts[1].removesuffix(".py") if len(parts) > 1 else "robogest"


def _layer(package: str) -> int:
    found = [k for k, layer in enumerate(LAYERS) if package in layer]
    assert found, f"robogest/{package} is in no layer: add it to LAYERS here and in docs/pipeline.md"
    return found[0]


@cache
def _imports() -> dict[str, list[tuple[str, int]]]:
    return {_module_name(p): _targets(p) for p in sorted(ROOT.rglob("*.py"))}


def _violations() -> list[str]:
    out = []
    for module, targets in _imports().items():
        src = _package(module)
        for target, line in dict(targets).items():  # one line per imported module
            dst = _package(target)
            if dst == src or (module, target) in EXCEPTIONS:
                continue
            if _layer(dst) >= _layer(src):
                out.append(f"{module}:{line} imports {target} (layer {_layer(dst)} >= {src}'s {_layer(src)})")
    return out


def test_every_package_has_a_layer():
    for module in _imports():
        _layer(_package(module))


def test_imports_flow_down():
    bad = _violations()
    assert not bad, "upward or sideways imports (move the code down, or call it from above):\n" + "\n".join(bad)


def test_the_documented_layers_are_these():
    """docs/pipeline.md's layer table names the same packages in the same layers."""
    known = set().union(*LAYERS)
    text = (ROOT.parent / "docs" / "pipeline.md").read_text()
    rows = re.findall(r"^\| (\d+) \| (.*) \|$", text, flags=re.M)
    documented = [
        {n.replace("robogest/__init__.py", "robogest") for n in re.findall(r"`([\w/.]+)`", row)} & known
        for _, row in rows
    ]
    assert [int(k) for k, _ in rows] == list(range(len(LAYERS)))
    assert documented == LAYERS


def test_exceptions_are_still_needed():
    """An exception nobody needs any more goes away."""
    used = {(m, t) for m, targets in _imports().items() for t, _ in targets}
    assert not set(EXCEPTIONS) - used


def _closure(package: str) -> set[str]:
    """Every robogest module reachable from ``package``'s modules by imports."""
    seen: set[str] = set()
    todo = [m for m in _imports() if _package(m) == package]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        todo += [t for t, _ in _imports().get(m, []) if t in _imports()]
    return seen


def test_virtual_bus_shares_no_code_with_backends():
    """The simulated bus is an independent implementation of the protocols the backends speak, so that it can
    catch their mistakes: neither reaches the other's code, directly or through another module."""
    assert not {m for m in _closure("virtualbus") if _package(m) == "backends"}
    assert not {m for m in _closure("backends") if _package(m) == "virtualbus"}


def test_the_checker_sees_function_local_relative_and_lazy_imports(tmp_path):
    """Imports inside a function, relative ones and lazy-table targets are found (so the test above can fail)."""
    (tmp_path / "robogest" / "robot").mkdir(parents=True)
    (tmp_path / "robogest" / "cli").mkdir()
    (tmp_path / "robogest" / "cli" / "main.py").write_text("")
    mod = tmp_path / "robogest" / "robot" / "x.py"
    mod.write_text("def f():\n    from ..cli import main\n_LAZY = {'Robot': 'robogest.live'}\nimport robogest.speech\n")
    assert sorted(_targets(mod, tmp_path / "robogest")) == [
        ("robogest.cli.main", 2), ("robogest.live", 3), ("robogest.speech", 4)
    ]  # fmt: skip
