"""User-facing errors.

Every mistake a user can make (a bad rig field, a missing video, an impossible parameter) raises a
:class:`WptrackError` subclass whose message names the file/field and what was expected. The CLI prints
the message on one line and exits with a non-zero code, without a traceback; library users can catch the
base class.
"""

from __future__ import annotations


class WptrackError(Exception):
    """Base class of all errors caused by user input (exit code 2 on the CLI)."""

    exit_code = 2


class RigError(WptrackError):
    """A rig file or camera definition is invalid."""


class FrameError(WptrackError):
    """A frame source (video, image folder, array) is missing, unreadable or inconsistent."""


class ConfigError(WptrackError):
    """A tracker or command parameter is out of range."""


class DeviceError(WptrackError):
    """The requested compute device is not available."""


class OutputError(WptrackError):
    """An output directory or file cannot be written."""
