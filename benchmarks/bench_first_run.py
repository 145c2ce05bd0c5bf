"""A new user's first ``robogest speak``: wheel -> new venv -> empty numba cache -> first and warm run (not a test).

Usage: python benchmarks/bench_first_run.py [--venv PATH] [--warm N] [--text TEXT] [--source CHECKOUT]

Builds a wheel of this checkout (``pip wheel --no-deps --no-build-isolation``), makes a new venv and installs
the wheel with its dependencies (from pip's configured indexes and cache; minutes), then, from an empty
folder with ``NUMBA_CACHE_DIR`` pointed at an empty folder, times the first
``robogest speak TEXT --save x.npz`` and ``N`` warm ones (wall clock, the console script as a user runs it).
``--venv PATH`` keeps the venv there; when PATH already holds one, only the wheel is reinstalled, so reruns
take seconds. ``--source CHECKOUT`` measures another checkout the same way (e.g. before a change).
Targets (issue 35): first <= 8 s, warm <= 2.5 s on the 2-core machine. The load average is printed: on a
busy machine the numbers are upper bounds. Not in ``run.py`` (a new venv takes minutes).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SOURCES = ("robogest", "robots", "sim", "setup.py", "pyproject.toml", "README.md")
FIRST_TARGET_S, WARM_TARGET_S = 8.0, 2.5


def _cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _run(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> float:
    """Run ``cmd``; its wall time in s. Exits with its output when it fails."""
    return _timed(cmd, cwd, env)[0]


def _timed(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> tuple[float, float]:
    """Run ``cmd``; (wall s, CPU s of it and its children: on a busy machine closer to a quiet machine's wall)."""
    c0, t0 = _cpu_s(), time.perf_counter()
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _cpu_s() - c0
    if res.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({res.returncode}):\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}")
    return wall, cpu


def build_wheel(tmp: Path, repo: Path) -> Path:
    """The wheel of checkout ``repo``, built from a copy of its sources (the checkout gets no build/)."""
    src = tmp / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    for name in SOURCES:
        p = repo / name
        (shutil.copytree(p, src / name, ignore=ignore) if p.is_dir() else shutil.copy2(p, src / name))
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    _run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(tmp / "dist"), str(src)], cwd=tmp)
    (wheel,) = (tmp / "dist").glob("robogest-*.whl")
    return wheel


def install(venv: Path, wheel: Path) -> tuple[float, bool]:
    """Install ``wheel`` into ``venv`` (created when missing); (wall s, whether the venv was new)."""
    py = venv / "bin" / "python"
    new = not py.is_file()
    t = _run([sys.executable, "-m", "venv", str(venv)], cwd=venv.parent) if new else 0.0
    pip = [str(py), "-m", "pip", "--disable-pip-version-check", "-q", "install"]
    if new:
        t += _run([*pip, str(wheel)], cwd=venv.parent)
    else:
        t += _run([*pip, "--no-deps", "--force-reinstall", str(wheel)], cwd=venv.parent)
    return t, new


def du_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink()) / 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--venv", type=Path, help="venv to create here, or to reuse when it exists")
    ap.add_argument("--warm", type=int, default=3, help="warm runs after the first (default 3)")
    ap.add_argument("--text", default="Hello there, nice to meet you.")
    ap.add_argument("--source", type=Path, default=REPO, help="checkout to build (default: this one)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="robogest_first_run_") as d:
        tmp = Path(d)
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        wheel = build_wheel(tmp, args.source.resolve())
        print(f"wheel: {wheel.name} built in {time.perf_counter() - t0:.1f} s")
        venv = (args.venv or tmp / "venv").resolve()
        venv.parent.mkdir(parents=True, exist_ok=True)
        t_inst, new = install(venv, wheel)
        what = "new venv + wheel with dependencies" if new else "wheel reinstalled into the existing venv"
        print(f"install: {what} in {t_inst:.1f} s; venv {du_mb(venv):.0f} MB at {venv}")

        cache, work = tmp / "numba_cache", tmp / "work"
        cache.mkdir()
        work.mkdir()
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ROBOGEST_ROBOTS", "VIRTUAL_ENV")}
        env.update(NUMBA_CACHE_DIR=str(cache), MUJOCO_GL=env.get("MUJOCO_GL", "egl"))
        cmd = [str(venv / "bin" / "robogest"), "speak", args.text, "--save", "x.npz"]
        first, first_cpu = _timed(cmd, cwd=work, env=env)
        warm_runs = [_timed(cmd, cwd=work, env=env) for _ in range(args.warm)]
        warm, warm_cpu = [w for w, _ in warm_runs], [c for _, c in warm_runs]
        n_cache = sum(1 for p in cache.rglob("*") if p.is_file())
        load1 = os.getloadavg()
        print(f'command: robogest speak "{args.text}" --save x.npz (empty NUMBA_CACHE_DIR before the first run)')
        ok = "ok" if first <= FIRST_TARGET_S else "OVER"
        print(f"first speak: {first:.2f} s wall, {first_cpu:.2f} s CPU (target <= {FIRST_TARGET_S:.1f} s wall: {ok})")
        if warm:
            ok = "ok" if min(warm) <= WARM_TARGET_S else "OVER"
            print(f"warm speak: best {min(warm):.2f} s, median {statistics.median(warm):.2f} s wall of {len(warm)}; "
                  f"CPU best {min(warm_cpu):.2f} s (target <= {WARM_TARGET_S:.1f} s wall: {ok})")  # fmt: skip
        print(f"numba cache files written: {n_cache} (0: nothing was JIT-compiled)")
        print(f"load average (1 min) before {load0[0]:.1f}, after {load1[0]:.1f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
