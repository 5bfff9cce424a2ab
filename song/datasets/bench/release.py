"""Release housekeeping: list versions, verify every hash, diff two versions (``song bench``)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

from song.datasets.bench.info import Info, fingerprint_of, list_versions, read_info, resolve_version, version_key  # noqa: F401
from song.datasets.bench.load import Benchmark
from song.datasets.bench.schema import EPISODES_PATH, INFO_FINGERPRINT_SINCE, INFO_PATH, MANIFEST_PATH
from song.util import sha256_file, sha256_json


@dataclass
class VerifyReport:
    """Outcome of :func:`verify_release`; ``ok`` when nothing is missing, extra or altered."""

    version: str
    fingerprint_ok: bool
    missing: list[str] = field(default_factory=list)
    extra: list[str] = field(default_factory=list)
    altered: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when nothing is missing, extra or altered and the fingerprint matches."""
        return self.fingerprint_ok and not (self.missing or self.extra or self.altered)


def verify_release(release: str | Path) -> VerifyReport:
    """Recompute every file's sha256 against the manifest and the manifest against the fingerprint."""
    release = Path(release)
    info = read_info(release / INFO_PATH)
    try:
        manifest = pq.read_table(release / MANIFEST_PATH).to_pylist()
    except (OSError, ValueError) as exc:
        return VerifyReport(info.dataset_version, False, altered=[MANIFEST_PATH + f" ({exc})"])
    covered = version_key(info.schema_version) >= INFO_FINGERPRINT_SINCE
    raw = json.loads((release / INFO_PATH).read_text(encoding="utf-8")) if covered else None
    report = VerifyReport(info.dataset_version, fingerprint_of(manifest, raw) == info.fingerprint)
    listed = {row["path"]: row for row in manifest}
    real_root = release.resolve()
    for rel, row in listed.items():
        path = release / rel
        if not path.resolve().is_relative_to(real_root):  # `..`, absolute or a symlink leaving the release
            report.altered.append(f"{rel} (resolves outside the release; not read)")
        elif not path.is_file():
            report.missing.append(rel)
        elif path.stat().st_size != row["bytes"] or sha256_file(path) != row["sha256"]:
            report.altered.append(rel)
    for path in sorted(release.rglob("*")):
        rel = path.relative_to(release).as_posix()
        if path.is_symlink() and not path.resolve().is_relative_to(real_root) and rel not in listed:
            report.extra.append(f"{rel} (symlink leaving the release)")
        elif path.is_file() and rel not in listed and rel not in (INFO_PATH, MANIFEST_PATH):
            report.extra.append(rel)
    return report


def summarize(release: Path) -> dict[str, Any]:
    """One line of ``song bench list``."""
    info = read_info(release / INFO_PATH)
    return {
        "version": info.dataset_version,
        "schema": info.schema_version,
        "parent": info.parent or "",
        "fingerprint": info.fingerprint[:16],
        "episodes": info.counts.get("episodes", 0),
        "scenes": info.counts.get("scenes", 0),
        "created": info.created,
    }


def _episode_digests(release: Path) -> dict[str, str]:
    table = pq.read_table(release / EPISODES_PATH.format(part=0))
    return {row["episode_id"]: sha256_json(row) for row in table.to_pylist()}


def _schemas(info: Info) -> dict[str, list[str]]:
    return {name: table.columns for name, table in info.tables.items()}


def _filled_columns(release: Path) -> dict[str, set[str]]:
    """Per table, the columns holding at least one value (the release opened confined and bounded)."""
    bench = Benchmark(release)
    tables = {"episodes": bench.episodes_table, "scenes": bench.scenes_table,
              "pedestrians": bench.pedestrians_table, "avatars": bench.avatars_table}  # fmt: skip
    return {
        name: {c for c in table.column_names if table.num_rows and table.column(c).null_count < table.num_rows}
        for name, table in tables.items()
    }


def diff_releases(old: Path, new: Path) -> dict[str, Any]:
    """Differences between two releases.

    Added, removed and changed episodes (by id, then by content), schema changes, and columns that
    gained or lost all their values (e.g. AMASS files shipped by one version and not the other).
    """
    old_info, new_info = read_info(old / INFO_PATH), read_info(new / INFO_PATH)
    a, b = _episode_digests(old), _episode_digests(new)
    schema_changes = {}
    old_s, new_s = _schemas(old_info), _schemas(new_info)
    for name in sorted(set(old_s) | set(new_s)):
        before, after = set(old_s.get(name, [])), set(new_s.get(name, []))
        if before != after:
            schema_changes[name] = {"added": sorted(after - before), "removed": sorted(before - after)}
    old_f, new_f = _filled_columns(old), _filled_columns(new)
    content_changes = {}
    for name in sorted(set(old_f) & set(new_f)):
        shared = set(old_s.get(name, [])) & set(new_s.get(name, []))
        filled, emptied = (new_f[name] - old_f[name]) & shared, (old_f[name] - new_f[name]) & shared
        if filled or emptied:
            content_changes[name] = {"filled": sorted(filled), "emptied": sorted(emptied)}
    return {
        "old": old_info.dataset_version,
        "new": new_info.dataset_version,
        "schema_version": [old_info.schema_version, new_info.schema_version],
        "added": sorted(set(b) - set(a)),
        "removed": sorted(set(a) - set(b)),
        "changed": sorted(k for k in set(a) & set(b) if a[k] != b[k]),
        "unchanged": sum(1 for k in set(a) & set(b) if a[k] == b[k]),
        "schema_changes": schema_changes,
        "content_changes": content_changes,
    }
