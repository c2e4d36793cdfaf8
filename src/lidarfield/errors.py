"""The one error type of lidarfield.

Every failure a user can cause (a bad file, a bad config, a hypothesis that breaks, a full
disk) raises a ``LidarfieldError`` whose message names the thing at fault and the problem, so
that the CLI and the workflow can print one readable line and exit non-zero.
"""

from __future__ import annotations

from pathlib import Path


class LidarfieldError(Exception):
    """A problem with the user's input: its message is meant to be read by a person."""

    def __init__(self, message: str, path: str | Path | None = None):
        self.path = None if path is None else str(path)
        super().__init__(f"{self.path}: {message}" if self.path else message)


class InputError(LidarfieldError):
    """A scan, pose or transform file that is missing, malformed or unusable."""


class ConfigError(LidarfieldError):
    """A study config or grid/hypothesis settings that do not validate."""


class HypothesisError(LidarfieldError):
    """A hypothesis that is unknown, badly parameterised, or fails when applied."""


class NotApplicableError(HypothesisError):
    """A hypothesis that cannot apply to this pair as it is (e.g. ``field_of_view`` without
    sensor models): an error in a stack, a skipped default candidate in the suggestions."""


class StorageError(LidarfieldError):
    """An output that could not be written: its file system is full or the user's quota spent."""


class RegistrationError(LidarfieldError):
    """A registration method that cannot run on its input."""
