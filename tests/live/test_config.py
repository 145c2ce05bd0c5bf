"""Session options (SessionConfig): checked once, each error naming its field; Robot(name, **options) and
Robot(name, config=...) make the same session."""

from __future__ import annotations

import pytest

from robogest.errors import InputError
from robogest.live import Robot, SessionConfig


@pytest.mark.parametrize(
    ("options", "field"),
    [
        ({"rate_hz": 0}, '"rate_hz"'),
        ({"time_scale": -1.0}, '"time_scale"'),
        ({"words_per_minute": "fast"}, '"words_per_minute"'),
        ({"stop_within_s": float("nan")}, '"stop_within_s"'),
        ({"approach_within_rad": -0.1}, '"approach_within_rad"'),
        ({"blas_threads": 0}, '"blas_threads"'),
        ({"prepare": "fork"}, '"prepare"'),
        ({"generator_options": [1, 2]}, '"generator_options"'),
    ],
)
def test_a_bad_option_is_an_input_error_naming_its_field(options, field):
    with pytest.raises(InputError, match=field):
        SessionConfig(**options)
    with pytest.raises(InputError, match=field):
        Robot("humanoid_xl430", **options)


def test_an_unknown_option_is_named_and_a_config_is_taken_with_overrides():
    with pytest.raises(InputError, match="'speed'"):
        Robot("humanoid_xl430", speed=2)
    cfg = SessionConfig(time_scale=4.0, idle=False, prepare="thread")
    robot = Robot("humanoid_xl430", config=cfg, seed=7)
    assert robot.options.time_scale == 4.0 and robot.options.prepare == "thread" and robot.seed == 7
    same = Robot("humanoid_xl430", "sim", time_scale=4.0, idle=False, prepare="thread", seed=7)
    assert same.options == robot.options
