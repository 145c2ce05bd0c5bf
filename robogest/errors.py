"""One root exception so the CLI can turn every user-facing failure into one clear line.

Anything raised as a :class:`RobogestError` is the user's to fix (bad file, bad config, a servo that
does not answer); its message names the input and the fix. Anything else is a bug and keeps its
traceback.
"""

from __future__ import annotations


class RobogestError(Exception):
    """Root of every error robogest raises on purpose."""

    exit_code = 1


class InputError(RobogestError):
    """A user input (audio, transcript, motion file, CLI value) is unusable."""

    exit_code = 2


class ConfigError(RobogestError):
    """A robot YAML or other configuration file is invalid; the message names file and key."""

    exit_code = 3


class SafetyError(RobogestError):
    """A command would be unsafe (NaN/inf from a generator, limits that cannot be met)."""

    exit_code = 4


class BackendError(RobogestError):
    """Hardware or simulator failure: a servo missing, in hardware error, or the port lost."""

    exit_code = 5


class MissingDependencyError(RobogestError):
    """An optional component (renderer, audio device, model weights) is not installed."""

    exit_code = 6


class RobogestWarning(UserWarning):
    """Something the user should know that does not stop the command (e.g. a plugin shadowed by a built-in).

    The CLI prints it as one ``robogest: warning: ...`` line on stderr.
    """
