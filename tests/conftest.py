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
#: Single slow tests in otherwise quick modules (node id without parameters: every parametrisation): those of 1.5 s
#: or more in a whole run on the quiet 2-core machine (docs/development.md).
SLOW_TESTS: frozenset[str] = frozenset(
    {
        "tests/backends/test_control_loop.py::test_late_ticks_advance_the_target_but_not_the_step",
        "tests/backends/test_goal_guard.py::test_servo_backends_send_only_safe_goals_on_the_bus",
        "tests/backends/test_governor.py::test_long_monologue_ends_cooler_with_the_governor",
        "tests/backends/test_servo_backends.py::test_five_percent_faults_finish_safely",
        "tests/backends/test_servo_backends.py::test_hardware_error_mid_play_names_servo_and_turns_torque_off",
        "tests/backends/test_servo_backends.py::test_play_trajectory_then_rest_and_torque_off",
        "tests/backends/test_servo_bringup.py::test_calibrate_takes_the_furthest_reading_on_the_way_as_the_end",
        "tests/backends/test_servo_bringup.py::test_jog_moves_one_joint_gently_then_rests_with_torque_off",
        "tests/backends/test_servo_lossy_bus.py::test_five_percent_reply_faults_on_eleven_servos_complete",
        "tests/backends/test_servo_lossy_bus.py::test_vanished_servo_is_declared_lost_within_0_2_s",
        "tests/backends/test_servo_port.py::test_late_replies_of_5_to_20_ms_cause_no_false_stop",
        "tests/backends/test_servo_profile.py::test_servos_own_acceleration_stays_within_1_1x_the_limit_when_goals_are_lost_or_late",
        "tests/backends/test_servo_scan_robot.py::test_nothing_answering_says_what_to_check_in_one_line",
        "tests/backends/test_servo_setup.py::test_setup_gives_each_servo_its_id_and_baud_one_at_a_time",
        "tests/backends/test_servo_stop.py::test_a_servo_fault_mid_gesture_still_takes_the_others_to_rest_before_torque_off",
        "tests/backends/test_servo_stop.py::test_at_a_low_control_rate_the_servo_keeps_near_the_velocity_limit_between_goals",
        "tests/cli/test_script_output.py::test_closed_stderr_is_not_an_error",
        "tests/data/test_datasets.py::test_a_take_longer_than_600_s_trains",
        "tests/data/test_datasets.py::test_feature_cache_larger_than_the_memory_allowed_is_mapped_not_loaded",
        "tests/data/test_datasets.py::test_layouts_give_the_same_aligned_takes",
        "tests/data/test_datasets.py::test_training_windows_are_read_lazily_from_disk_within_a_memory_limit",
        "tests/eval/test_cli.py::test_bvh_motion_pair",
        "tests/generators/learned/test_rhythmic.py::test_generator_overfits_a_training_take",
        "tests/generators/learned/test_rhythmic.py::test_resumed_run_keeps_its_stage_plan",
        "tests/generators/learned/test_rhythmic.py::test_train_cli_and_generate_text_and_audio_only",
        "tests/generators/learned/test_s2ag.py::test_discriminator_loss_falls_with_the_generator_frozen",
        "tests/generators/learned/test_s2ag.py::test_generator_step_lowers_reconstruction_and_leaves_the_discriminator",
        "tests/generators/learned/test_s2ag.py::test_train_cli_then_generate",
        "tests/generators/learned/test_s2ag.py::test_training_history_and_checkpoint",
        "tests/generators/learned/test_speech_encoder.py::test_rhythmic_takes_its_high_level_features_from_the_encoder",
        "tests/generators/learned/test_training.py::test_loss_falls",
        "tests/generators/learned/test_training.py::test_resume_continues_and_is_deterministic",
        "tests/live/test_aio.py::test_a_second_session_on_the_same_serial_port_is_refused_before_the_bus_is_touched",
        "tests/live/test_aio.py::test_ready_waits_for_the_warm_up_and_wait_ready_reports_it",
        "tests/live/test_owner.py::test_the_sessions_utterance_state_changes_only_in_its_owner_thread",
        "tests/live/test_planner.py::test_a_failure_while_planning_stops_the_utterance_and_is_raised_to_the_caller",
        "tests/live/test_planner.py::test_each_plan_generates_over_a_bounded_stretch",
        "tests/live/test_planner.py::test_plans_share_a_live_plan_that_commits_the_frames_played",
        "tests/live/test_planner.py::test_played_frames_are_never_revised_and_later_ones_are",
        "tests/live/test_planner.py::test_speech_and_motion_start_no_earlier_than_the_lookahead_after_the_first_chunk",
        "tests/live/test_planner.py::test_the_streamed_feed_keeps_the_velocity_and_acceleration_limits_across_plans",
        "tests/live/test_serve.py::test_a_long_say_holds_another_clients_short_one_no_longer_than_it_plays",
        "tests/live/test_serve.py::test_a_stream_fed_far_ahead_of_playback_is_refused_and_the_session_keeps_running",
        "tests/live/test_serve.py::test_log_level_quiets_the_servers_log",
        "tests/live/test_serve.py::test_malformed_messages_get_errors_and_the_session_keeps_running",
        "tests/live/test_serve.py::test_say_stream_and_interrupt_push_events",
        "tests/live/test_serve.py::test_serve_exits_5_when_a_servo_vanishes_and_the_session_cannot_reopen",
        "tests/live/test_serve.py::test_sigquit_mid_say_ends_the_server_at_rest_like_sigterm",
        "tests/live/test_serve_memory.py::test_large_blocks_get_their_own_mapping_after_a_larger_one_was_freed",
        "tests/live/test_session.py::test_a_finished_utterance_keeps_no_audio_speech_or_planner_alive",
        "tests/live/test_session.py::test_a_replaced_stream_that_fails_later_leaves_the_utterance_playing_now_alone",
        "tests/live/test_session.py::test_an_interrupt_while_a_say_is_still_being_prepared_keeps_it_from_starting",
        "tests/live/test_session.py::test_interrupt_mid_utterance_glides_to_rest_within_limits_and_idle_resumes",
        "tests/live/test_session.py::test_session_refuses_bad_input_with_one_clear_line",
        "tests/live/test_session.py::test_signal_or_exception_inside_the_session_ends_at_rest_with_torque_off",
        "tests/live/test_session.py::test_streamed_utterance_passes_the_batch_checks",
        "tests/live/test_session.py::test_torque_lost_between_utterances_ends_the_session_at_rest_and_the_next_say_names_the_servo",
        "tests/live/test_session.py::test_torque_stays_on_between_utterances_and_goes_off_at_rest_on_close",
        "tests/safety/test_safety_properties.py::test_apply_safety_meets_every_limit_and_holds_rest",
        "tests/safety/test_safety_stage.py::test_any_chunking_is_safe_and_rests_in_long_silences",
        "tests/safety/test_safety_stage.py::test_one_chunk_is_bit_identical_to_apply_safety",
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
