"""Shared fixtures: a seeded rng, and the location of ../shared/data (tests using it skip when absent); which tests
are ``slow`` (left out of ``make test-fast``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


#: Test modules that are end-to-end as a whole (the CLI in a subprocess, training runs, real-time playback on the
#: simulated bus): every test in them is marked ``slow``, so ``make test-fast`` (``-m "not slow"``) leaves them to
#: ``make test``. Chosen from the per-test durations of a whole run (docs/development.md); a slow test elsewhere
#: is listed in :data:`SLOW_TESTS` or carries ``@pytest.mark.slow`` itself.
SLOW_MODULES: frozenset[str] = frozenset(
    {
        "tests/backends/test_torque_watch.py",
        "tests/cli/test_bad_inputs.py",
        "tests/cli/test_gestures_e2e.py",
        "tests/cli/test_learned_e2e.py",
        "tests/cli/test_speak_e2e.py",
        "tests/cli/test_speak_virtual_bus.py",
        "tests/eval/test_fgd.py",
    }
)
#: Single slow tests in otherwise quick modules (node id without parameters: every parametrisation).
SLOW_TESTS: frozenset[str] = frozenset(
    {
        "tests/backends/test_goal_guard.py::test_servo_backends_send_only_safe_goals_on_the_bus",
        "tests/backends/test_governor.py::test_long_monologue_ends_cooler_with_the_governor",
        "tests/backends/test_servo_bringup.py::test_calibrate_takes_the_furthest_reading_on_the_way_as_the_end",
        "tests/backends/test_servo_lossy_bus.py::test_five_percent_reply_faults_on_eleven_servos_complete",
        "tests/backends/test_servo_port.py::test_late_replies_of_5_to_20_ms_cause_no_false_stop",
        "tests/backends/test_servo_setup.py::test_setup_gives_each_servo_its_id_and_baud_one_at_a_time",
        "tests/backends/test_servo_stop.py::test_a_servo_fault_mid_gesture_still_takes_the_others_to_rest_before_torque_off",
        "tests/cli/test_script_output.py::test_closed_stderr_is_not_an_error",
        "tests/data/test_datasets.py::test_a_take_longer_than_600_s_trains",
        "tests/data/test_datasets.py::test_feature_cache_larger_than_the_memory_allowed_is_mapped_not_loaded",
        "tests/data/test_datasets.py::test_layouts_give_the_same_aligned_takes",
        "tests/data/test_datasets.py::test_training_windows_are_read_lazily_from_disk_within_a_memory_limit",
        "tests/eval/test_cli.py::test_bvh_motion_pair",
        "tests/generators/learned/test_rhythmic.py::test_generator_overfits_a_training_take",
        "tests/generators/learned/test_rhythmic.py::test_train_cli_and_generate_text_and_audio_only",
        "tests/generators/learned/test_s2ag.py::test_training_history_and_checkpoint",
        "tests/live/test_planner.py::test_each_plan_generates_over_a_bounded_stretch",
        "tests/live/test_planner.py::test_plans_share_a_live_plan_that_commits_the_frames_played",
        "tests/live/test_planner.py::test_played_frames_are_never_revised_and_later_ones_are",
        "tests/live/test_serve.py::test_a_long_say_holds_another_clients_short_one_no_longer_than_it_plays",
    }
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.nodeid.split("::")[0] in SLOW_MODULES or item.nodeid.split("[")[0] in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)


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
