"""The loaders' error: a file that could not be turned into a Recording, named in the message."""

from __future__ import annotations

__all__ = ["RecordingFileError", "fail"]


class RecordingFileError(ValueError):
    """A file could not be turned into a Recording (corrupt, truncated, empty, wrong layout...).

    Subclass of :class:`ValueError`; the message always starts with the file path.
    """


def fail(path, message: str) -> RecordingFileError:
    """Build (not raise) the standard error: ``"<path>: <message>"``."""
    return RecordingFileError(f"{path}: {message}")
