"""Small bottom-layer helpers shared by every layer: hashing, atomic writes, seeded RNGs.

Imports nothing else of ``song`` except :mod:`song.errors`.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import struct
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

    A crash at any moment leaves either the old file or the new one, never a half-written file. On an
    exception the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}-", suffix=".tmp", dir=path.parent)
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


_ABANDONED = re.compile(r"^\..+\.(\d+)-[a-z0-9_]+\.tmp$")  # atomic_writer's temporary names: .<name>.<pid>-<random>.tmp


def remove_abandoned_writes(folder: str | Path) -> None:
    """Delete the temporary files of :func:`atomic_writer` under ``folder`` whose process is gone.

    A process killed with kill -9 during an atomic write leaves its temporary file behind (the target
    itself is intact). Files of live processes, and anything else, are left alone.
    """
    for tmp in Path(folder).rglob(".*.tmp"):
        match = _ABANDONED.match(tmp.name)
        if match is None or tmp.is_symlink() or not tmp.is_file():
            continue
        if process_gone(int(match.group(1))):
            tmp.unlink(missing_ok=True)


def process_gone(pid: int) -> bool:
    """No process has this pid (its owner was killed); False while it runs, or may (another user's)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except (PermissionError, OverflowError):
        return False
    return False


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Atomically replace ``path`` with ``data``."""
    with atomic_writer(path, "wb") as handle:
        handle.write(data)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Atomically replace ``path`` with UTF-8 ``text``."""
    write_bytes_atomic(path, text.encode("utf-8"))


@contextmanager
def folder_lock(path: str | Path, what: str) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (a lock file, created) while the block runs.

    A second writer gets a one-line :class:`~song.errors.SongError` at once instead of interleaving
    its files with the first's. The lock is the operating system's (``flock``): it goes with the
    process, so a killed writer never leaves a stale lock behind.
    """
    import fcntl

    from song.errors import SongError

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = open(path, "a+b")  # noqa: SIM115 - held open for the lock's lifetime
    try:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise SongError(f"{path.parent}: another song process is writing this {what}; wait for it to end") from None
        yield
    finally:
        handle.close()  # closing releases the lock


def finite_json(obj: Any) -> Any:
    """``obj`` with every non-finite float (NaN, ±inf, numpy's too) replaced by None: strict JSON's null.

    Strings are left alone (a path or a policy named ``NaN`` stays as it is).
    """
    if isinstance(obj, dict):
        return {key: finite_json(value) for key, value in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_json(value) for value in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def write_json_atomic(path: str | Path, obj: Any) -> None:
    """Atomically write ``obj`` as indented, key-sorted strict JSON (non-finite numbers become null)."""
    text = json.dumps(finite_json(obj), indent=2, sort_keys=True, ensure_ascii=False, allow_nan=False)
    write_text_atomic(path, text + "\n")


def write_npz_atomic(path: str | Path, **arrays: np.ndarray) -> None:
    """Atomically write an uncompressed ``.npz``; bytes depend only on the arrays (no timestamps)."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


NPZ_DEFLATE_LEVEL = 1  # ISA-L's level 1: on motion arrays ~6x quicker than zlib's fastest level, and smaller
_ZIP_LOCAL = struct.Struct("<IHHHHHIIIHH")  # local file header (APPNOTE 4.3.7)
_ZIP_CENTRAL = struct.Struct("<IHHHHHHIIIHHHHHII")  # central directory header (4.3.12)
_ZIP_END = struct.Struct("<IHHHHIIH")  # end of central directory (4.3.16)
_ZIP_DATE = (0 << 9) | (1 << 5) | 1  # 1980-01-01 (DOS date), time 00:00: bytes never depend on the clock
_ZIP_LIMIT = 0xFFFFFFFF  # beyond this a member or an offset needs ZIP64


def _deflated_zip(members: dict[str, bytes]) -> bytes:
    """A zip archive of ``members`` (name: bytes), each deflated by ISA-L (``isal``).

    Written here, not with :mod:`zipfile`: zipfile deflates with zlib only and cannot take a stream
    deflated elsewhere, and ISA-L deflates motion arrays about six times faster (the AMASS export was
    an eighth of the motion stage). Archives that would need ZIP64 are left to zipfile.
    """
    from isal import isal_zlib

    if len(members) >= 0xFFFF:  # more members than a plain end record counts
        return _zipfile_deflated(members)
    local, central, offset = [], [], 0
    for name, data in members.items():
        packer = isal_zlib.compressobj(NPZ_DEFLATE_LEVEL, isal_zlib.DEFLATED, -15)  # raw deflate, as zip stores it
        packed = packer.compress(data) + packer.flush()
        crc, key = isal_zlib.crc32(data), name.encode("utf-8")
        if max(len(data), len(packed), offset) >= _ZIP_LIMIT:
            return _zipfile_deflated(members)
        head = _ZIP_LOCAL.pack(0x04034B50, 20, 0, 8, 0, _ZIP_DATE, crc, len(packed), len(data), len(key), 0)
        central.append(
            _ZIP_CENTRAL.pack(
                0x02014B50, 20, 20, 0, 8, 0, _ZIP_DATE, crc, len(packed), len(data), len(key), 0, 0, 0, 0, 0, offset
            )
            + key
        )
        local += [head, key, packed]
        offset += len(head) + len(key) + len(packed)
    directory = b"".join(central)
    if offset + len(directory) >= _ZIP_LIMIT:
        return _zipfile_deflated(members)
    end = _ZIP_END.pack(0x06054B50, 0, 0, len(central), len(central), len(directory), offset, 0)
    return b"".join(local) + directory + end


def _zipfile_deflated(members: dict[str, bytes]) -> bytes:
    """The same archive written by :mod:`zipfile` with zlib (ZIP64 where needed)."""
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED, compresslevel=NPZ_DEFLATE_LEVEL) as archive:
        for name, data in members.items():
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, data, compresslevel=NPZ_DEFLATE_LEVEL)
    return buffer.getvalue()


def write_npz_compressed_atomic(path: str | Path, **arrays: np.ndarray) -> None:
    """Atomically write a deflated ``.npz`` (``np.load`` reads it as usual); bytes depend only on the arrays.

    Members are ``<name>.npy`` as numpy's ``savez_compressed`` writes them, with a fixed timestamp,
    deflated at ``NPZ_DEFLATE_LEVEL`` (:func:`_deflated_zip`).
    """
    members = {}
    for name, value in arrays.items():
        member = io.BytesIO()
        np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
        members[f"{name}.npy"] = member.getvalue()
    write_bytes_atomic(path, _deflated_zip(members))


def derive_seed(*parts: object) -> int:
    """A 64-bit seed from a hash of ``parts`` (run seed, scene id, stage name, item id, ...).

    every stage draws from a generator seeded by such a hash, so results never depend on
    worker count, order or executor.
    """
    text = "\x1f".join(str(part) for part in parts)
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "little")


def derive_rng(*parts: object) -> np.random.Generator:
    """A ``numpy.random.Generator`` seeded by :func:`derive_seed` of ``parts``."""
    return np.random.Generator(np.random.PCG64(derive_seed(*parts)))
