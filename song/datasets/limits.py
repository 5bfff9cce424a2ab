"""Bounds on what SONG decodes from files it did not write (scene packages, releases): checked first.

Every size a file declares (image width × height, PLY element counts, Parquet rows, array bytes, JSON
text and nesting) is compared with a limit *before* anything is decoded, so a 1 MB PNG that declares
30000 × 30000 pixels or a PLY header claiming 10¹² vertices is refused in milliseconds with one line
naming the file, the field and the limit. Limits are generous for real indoor data and can be raised
with environment variables:

| limit | default | variable |
|---|---|---|
| image pixels (occupancy PNG) | 100 M (10 000 × 10 000: a 500 m square at 5 cm) | ``SONG_MAX_IMAGE_PIXELS`` |
| Gaussians per PLY | 50 M | ``SONG_MAX_SPLATS`` |
| JSON file size | 64 MB | ``SONG_MAX_JSON_BYTES`` |
| JSON nesting depth | 64 | ``SONG_MAX_JSON_DEPTH`` |
| rows per table | 50 M | ``SONG_MAX_TABLE_ROWS`` |
| bytes per array (npz member) | 2 GB | ``SONG_MAX_ARRAY_BYTES`` |
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from song.errors import FormatError, InputError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@dataclass(frozen=True)
class Limits:
    """The bounds in force (see the module docstring)."""

    max_image_pixels: int = 100_000_000
    max_splats: int = 50_000_000
    max_json_bytes: int = 64 * 2**20
    max_json_depth: int = 64
    max_table_rows: int = 50_000_000
    max_array_bytes: int = 2 * 2**30


ENV = {
    "max_image_pixels": "SONG_MAX_IMAGE_PIXELS",
    "max_splats": "SONG_MAX_SPLATS",
    "max_json_bytes": "SONG_MAX_JSON_BYTES",
    "max_json_depth": "SONG_MAX_JSON_DEPTH",
    "max_table_rows": "SONG_MAX_TABLE_ROWS",
    "max_array_bytes": "SONG_MAX_ARRAY_BYTES",
}


def limits() -> Limits:
    """The defaults, with any ``SONG_MAX_*`` environment variable applied (read on every call)."""
    values = {}
    for name, var in ENV.items():
        raw = os.environ.get(var)
        if raw is not None:
            try:
                values[name] = int(raw)
            except ValueError as exc:
                raise FormatError(var, "", f"environment variable must be an integer, got {raw!r}") from exc
    return Limits(**values)


def over(
    path: str | Path, field: str, what: str, value: int, name: str, error: type[InputError] = FormatError
) -> InputError:
    """The error for ``value`` above the limit ``name``: one line naming the file, field and limit."""
    bound = getattr(limits(), name)
    return error(path, field, f"{what} {value:,} exceeds the limit {name}={bound:,} (raise it with {ENV[name]})")


def check_png_size(data: bytes, path: str | Path, error: type[InputError] = FormatError) -> tuple[int, int]:
    """(width, height) a PNG declares in its IHDR, refused above ``max_image_pixels`` (nothing decoded)."""
    if len(data) < 24 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
        raise error(path, "", "not a readable PNG image (no PNG signature and IHDR header)")
    width, height = struct.unpack(">II", data[16:24])
    if width * height > limits().max_image_pixels:
        raise over(path, "IHDR", f"{width} × {height} =", width * height, "max_image_pixels", error)
    return width, height


def _depth(value: Any, bound: int, level: int = 1) -> int:
    """Nesting depth of parsed JSON, stopping as soon as it passes ``bound``."""
    if level > bound or not isinstance(value, dict | list):
        return level
    children = value.values() if isinstance(value, dict) else value
    return max((_depth(child, bound, level + 1) for child in children), default=level)


def load_json(path: str | Path, text: str | None = None, error: type[InputError] = FormatError) -> Any:
    """Parse a JSON file (or its ``text``) within ``max_json_bytes`` and ``max_json_depth``.

    Raises:
        FormatError: too large, nested too deeply, not UTF-8 or not JSON (one line, naming the file).
    """
    path = Path(path)
    bound = limits()
    if text is None:
        size = path.stat().st_size if path.is_file() else 0
        if size > bound.max_json_bytes:
            raise over(path, "", "size", size, "max_json_bytes", error)
        try:
            text = path.read_bytes().decode("utf-8")
        except UnicodeDecodeError as exc:
            raise error(path, "", f"not UTF-8 text (byte {exc.start})") from exc
    elif len(text) > bound.max_json_bytes:
        raise over(path, "", "size", len(text), "max_json_bytes", error)
    try:
        data = json.loads(text)
    except RecursionError as exc:
        raise over(path, "", "nesting depth over", bound.max_json_depth, "max_json_depth", error) from exc
    except json.JSONDecodeError as exc:
        raise error(path, "", f"not valid JSON: {exc.msg} at line {exc.lineno}") from exc
    if _depth(data, bound.max_json_depth) > bound.max_json_depth:
        raise over(path, "", "nesting depth over", bound.max_json_depth, "max_json_depth", error)
    return data


def read_npz(path: str | Path, error: type[InputError] = FormatError) -> dict[str, Any]:
    """Every array of an ``.npz``, refused before decoding where a member could not be what it declares.

    Each member's uncompressed size must be within ``max_array_bytes`` and its ``.npy`` header must
    declare a plain (non-object) dtype and a shape whose bytes fit the member: a forged header can
    otherwise make NumPy allocate terabytes before it reads a byte.

    Raises:
        FormatError: unreadable, a member over the limit or with a forged header (one line, naming the file and array).
    """
    import zipfile

    import numpy as np

    bound = limits().max_array_bytes
    arrays = {}
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                field = info.filename.removesuffix(".npy")
                if info.file_size > bound:
                    raise over(path, field, "uncompressed size", info.file_size, "max_array_bytes", error)
                with archive.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    reader = (
                        np.lib.format.read_array_header_1_0
                        if version == (1, 0)
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, _, dtype = reader(member)
                if dtype.hasobject:
                    raise error(path, field, "object arrays are not accepted")
                declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if declared > info.file_size:
                    raise error(
                        path, field, f"header declares {declared:,} bytes of data in a member of {info.file_size:,}"
                    )
                with archive.open(info) as member:
                    arrays[field] = np.lib.format.read_array(member, allow_pickle=False)
        return arrays
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        raise error(path, "", f"not a readable npz ({exc})") from None
