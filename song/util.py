"""Small bottom-layer helpers shared by every layer: hashing, atomic writes, seeded RNGs.

Imports nothing else of ``song`` except :mod:`song.errors`.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

CHUNK_BYTES = 1 << 20


def sha256_bytes(data: bytes) -> str:
    """Hex sha256 of a byte string."""
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file's bytes, streamed."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(CHUNK_BYTES), b""):
            digest.update(block)
    return digest.hexdigest()


def canonical_json(obj: Any) -> str:
    """JSON with sorted keys and no whitespace: the form every content hash is taken over."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def read_json_object(path: str | Path) -> dict[str, Any]:
    """A JSON file holding an object, as a dict; empty when the file is missing, unreadable or not an object."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def sha256_json(obj: Any) -> str:
    """Hex sha256 of :func:`canonical_json` of ``obj``."""
    return sha256_bytes(canonical_json(obj).encode("utf-8"))


SAFE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}")  # ids that become path components


def check_id(value: object, what: str) -> str:
    """``value`` if it is a safe path component (1–128 of ``[A-Za-z0-9_.-]``, no leading dot, no ``..``).

    Every id that names a file or folder (scene, avatar, episode ids, release versions) goes through
    this one rule, matched in full (a trailing newline is refused too).

    Raises:
        SongError: one line naming ``what`` and the offending value.
    """
    from song.errors import SongError

    if not isinstance(value, str) or not SAFE_ID.fullmatch(value) or ".." in value:
        raise SongError(f"{what} {value!r}: must be 1-128 of [A-Za-z0-9_.-], starting with a letter or digit, no '..'")
    return value


_UMASK = os.umask(0o022)
os.umask(_UMASK)  # read the process umask once (os.umask is the only way to read it)


@contextmanager
def atomic_writer(path: str | Path, mode: str = "wb") -> Iterator[io.IOBase]:
    """Open a temporary file next to ``path``; on success fsync it and rename it over ``path``.

    A crash at any moment leaves either the old file or the new one, never a half-written file
    (DESIGN §3). On an exception the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.fchmod(fd, 0o666 & ~_UMASK)  # mkstemp makes 0600 files; give the result the usual permissions
    try:
        with os.fdopen(fd, mode) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Atomically replace ``path`` with ``data``."""
    with atomic_writer(path, "wb") as handle:
        handle.write(data)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Atomically replace ``path`` with UTF-8 ``text``."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | Path, obj: Any) -> None:
    """Atomically write ``obj`` as indented, key-sorted JSON (stable bytes for the same content)."""
    write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True, ensure_ascii=False) + "\n")


def write_npz_atomic(path: str | Path, **arrays: np.ndarray) -> None:
    """Atomically write an uncompressed ``.npz``; bytes depend only on the arrays (no timestamps)."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


NPZ_DEFLATE_LEVEL = 1  # fastest deflate: 3–4× quicker than numpy's default level 6 on motion data, ~5 % larger


def write_npz_compressed_atomic(path: str | Path, **arrays: np.ndarray) -> None:
    """Atomically write a deflated ``.npz`` (``np.load`` reads it as usual); bytes depend only on the arrays.

    Members are written as numpy's ``savez_compressed`` does (``<name>.npy`` in a zip), with a fixed
    timestamp and deflate level ``NPZ_DEFLATE_LEVEL``.
    """
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED, compresslevel=NPZ_DEFLATE_LEVEL) as archive:
        for name, value in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, member.getvalue(), compresslevel=NPZ_DEFLATE_LEVEL)
    write_bytes_atomic(path, buffer.getvalue())


def derive_seed(*parts: object) -> int:
    """A 64-bit seed from a hash of ``parts`` (run seed, scene id, stage name, item id, ...).

    DESIGN §3: every stage draws from a generator seeded by such a hash, so results never depend on
    worker count, order or executor.
    """
    text = "\x1f".join(str(part) for part in parts)
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "little")


def derive_rng(*parts: object) -> np.random.Generator:
    """A ``numpy.random.Generator`` seeded by :func:`derive_seed` of ``parts``."""
    return np.random.Generator(np.random.PCG64(derive_seed(*parts)))
