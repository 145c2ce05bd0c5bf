"""Shared fixtures of the command-line tests."""

from __future__ import annotations

import signal

import pytest


@pytest.fixture
def quit_does_not_dump_core():
    """SIGQUIT's default dumps core: where robogest does not take it, the test is to fail, not the whole run."""
    previous = signal.signal(signal.SIGQUIT, lambda *_: None)
    yield
    signal.signal(signal.SIGQUIT, previous)
