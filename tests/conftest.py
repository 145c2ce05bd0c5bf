"""Shared fixtures: a seeded rng, and the location of ../shared/data (tests using it skip when absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


@pytest.fixture
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA


def mount_tmpfs(where: Path, options: str) -> None:
    """Mount a small tmpfs at ``where`` (created), or skip the test where mounting is not allowed (not root)."""
    import subprocess

    where.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True)
    if r.returncode:
        pytest.skip(f"cannot mount a small tmpfs here ({r.stderr.decode().strip()})")


def fill_up(folder: Path) -> None:
    """Write zeros into ``folder/filler`` until its file system is full."""
    import os

    fd = os.open(folder / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while os.write(fd, b"\0" * 4096):
            pass
    except OSError:
        pass
    finally:
        os.close(fd)


@pytest.fixture
def full_disk(tmp_path: Path):
    """A folder on a full 64 kB tmpfs (skips where mounting is not allowed); unmounted afterwards."""
    import subprocess

    where = tmp_path / "full"
    mount_tmpfs(where, "size=64k")
    fill_up(where)
    yield where
    subprocess.run(["umount", "-l", str(where)], check=False)
