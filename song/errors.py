"""One error tree for the whole package (STYLE: "One error tree").

Library code raises these; the CLI turns them into one-line messages. Input errors always name the
file and the field so that a user can fix the input without reading a traceback.
"""

from __future__ import annotations

from pathlib import Path


class SongError(Exception):
    """Root of every error SONG raises on purpose."""


class InputError(SongError):
    """Bad user input: a file, a field and what was expected, rendered as one line.

    Args:
        file: the offending file (or folder) path.
        field: dotted field path inside the file (``objects[3].footprint``), or ``""``.
        message: what is wrong and what was expected.
    """

    def __init__(self, file: str | Path, field: str, message: str) -> None:
        self.file = str(file)
        self.field = field
        self.message = message
        where = f"{self.file}: {field}" if field else self.file
        super().__init__(f"{where}: {message}")


class SceneError(InputError):
    """A scene package (semantic map, occupancy, PLY, USD) is malformed."""


class FormatError(InputError):
    """A binary or text file does not follow its documented format (PLY, Parquet, npz)."""


class ConfigError(InputError):
    """A configuration file or value is invalid."""


class StageError(SongError):
    """A pipeline stage failed for one scene (the run carries on with the others)."""


class BenchmarkError(SongError):
    """A benchmark release is missing, altered, or written twice."""


class SchemaVersionError(BenchmarkError):
    """A benchmark's schema major version does not match this package's."""


class MissingDependencyError(SongError):
    """An optional dependency is not installed; the message carries the install hint."""

    def __init__(self, module: str, extra: str) -> None:
        super().__init__(f"optional dependency '{module}' is not installed: pip install 'song[{extra}]'")
        self.module = module
        self.extra = extra
