"""``meta/info.json`` of a release, as a validated pydantic model."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from song.config import CameraConfig, RobotConfig
from song.datasets.bench.schema import FORMAT_NAME, INFO_PATH, SCHEMA_VERSION, schema_major
from song.datasets.bench.types import RuntimeParams
from song.errors import BenchmarkError, SchemaVersionError
from song.util import canonical_json, sha256_bytes

SEMVER = re.compile(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)")  # always matched in full


class Generator(BaseModel):
    """What wrote a release: package, version, git commit, the run's config sha256."""

    model_config = ConfigDict(extra="forbid")
    package: str = "song"
    version: str
    git_commit: str = ""
    config_sha256: str


class TableInfo(BaseModel):
    """One table of a release: its path, row count and columns."""

    model_config = ConfigDict(extra="forbid")
    path: str
    rows: int
    columns: list[str]


class Info(BaseModel):
    """Everything a reader needs to know about one release before opening a table."""

    model_config = ConfigDict(extra="forbid")
    format: str = FORMAT_NAME
    dataset_version: str
    schema_version: str = SCHEMA_VERSION
    parent: str | None = None
    notes: str = ""
    created: str = Field(..., description="ISO-8601 UTC; SOURCE_DATE_EPOCH when set, for reproducible builds")
    generator: Generator
    frame: dict[str, str] = {"units": "m", "up": "z"}
    fps: int = 30
    robot: dict[str, Any]
    camera: dict[str, Any]
    collision: dict[str, Any]
    pedestrian_radius_m: float | None = Field(
        None, description="pedestrian body radius, m (schema ≥ 1.1; releases of 1.0 used the default 0.25 m)"
    )
    crowd: dict[str, Any] | None = Field(
        None,
        description="how the pedestrians were made: avoidance, speed_profile, comfort_distance_m, scenario_s, "
        "max_legs (schema ≥ 1.3)",
    )
    counts: dict[str, Any]
    tables: dict[str, TableInfo]
    fingerprint: str = Field(..., description="sha256 of the sorted manifest and of this file without this field")

    @field_validator("dataset_version", "schema_version")
    @classmethod
    def _semver(cls, value: str) -> str:
        if not SEMVER.fullmatch(value):
            raise ValueError("expected a semantic version X.Y.Z")
        return value

    @field_validator("format")
    @classmethod
    def _format(cls, value: str) -> str:
        if value != FORMAT_NAME:
            raise ValueError(f"expected '{FORMAT_NAME}'")
        return value


def runtime_params(info: Info, where: str | Path) -> RuntimeParams:
    """The :class:`RuntimeParams` recorded in a release's info (config defaults fill fields it predates)."""
    try:
        robot = RobotConfig.model_validate(info.robot)
        camera = CameraConfig.model_validate(info.camera)
    except ValidationError as exc:
        first = exc.errors()[0]
        field = ".".join(str(p) for p in first["loc"])
        raise BenchmarkError(f"{where}: {field}: {first['msg']}") from exc
    defaults = RuntimeParams()
    radius = info.pedestrian_radius_m if info.pedestrian_radius_m is not None else defaults.pedestrian_radius_m
    return RuntimeParams(robot=robot, camera=camera, pedestrian_radius_m=float(radius), fps=int(info.fps))


def check_schema_version(found: str, where: str | Path) -> None:
    """Refuse a release whose schema major differs from ours, saying what to do, both ways."""
    ours, theirs = schema_major(SCHEMA_VERSION), schema_major(found)
    if theirs > ours:
        raise SchemaVersionError(
            f"{where}: schema {found} is newer than this song reads ({SCHEMA_VERSION}); upgrade: pip install -U song"
        )
    if theirs < ours:
        raise SchemaVersionError(
            f"{where}: schema {found} is older than this song reads ({SCHEMA_VERSION}); re-export it with "
            f"`song export-bench` from its run, or install the song release that wrote it"
        )


def read_info(path: Path) -> Info:
    """Read and validate ``meta/info.json``; checks the schema major version."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise BenchmarkError(f"{path}: cannot read release info: {exc}") from exc
    if (
        isinstance(data, dict)
        and isinstance(data.get("schema_version"), str)
        and SEMVER.fullmatch(data["schema_version"])
    ):
        check_schema_version(data["schema_version"], path)
    try:
        return Info.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        field = ".".join(str(p) for p in first["loc"])
        raise BenchmarkError(f"{path}: {field}: {first['msg']}") from exc


def version_key(version: str) -> tuple[int, int, int]:
    """Sort key of a semver string."""
    major, minor, patch = (int(part) for part in version.split("."))
    return (major, minor, patch)


def list_versions(bench_dir: str | Path) -> list[str]:
    """Published versions under ``bench_dir`` (folders named X.Y.Z with an info.json), oldest first."""
    bench_dir = Path(bench_dir)
    if not bench_dir.is_dir():
        raise BenchmarkError(f"{bench_dir}: benchmark folder is missing")
    found = [
        p.name for p in bench_dir.iterdir() if p.is_dir() and SEMVER.fullmatch(p.name) and (p / INFO_PATH).is_file()
    ]
    return sorted(found, key=version_key)


def resolve_version(bench_dir: str | Path, version: str | None) -> Path:
    """The release folder of ``version`` (the latest when None)."""
    versions = list_versions(bench_dir)
    if not versions:
        raise BenchmarkError(f"{bench_dir}: no released versions; run `song export-bench` first")
    if version is None:
        version = versions[-1]
    if version not in versions:
        raise BenchmarkError(f"{bench_dir}: version {version} not found; available: {', '.join(versions)}")
    return Path(bench_dir) / version


def fingerprint_of(rows: list[dict[str, Any]], info: dict[str, Any] | None = None) -> str:
    """sha256 of the sorted manifest's canonical text (``path sha256 bytes`` per line) and of ``info``.

    ``info`` is ``meta/info.json`` as a dict without its ``fingerprint`` field (releases of schema 1.2
    and later), so editing the recorded robot, camera or collision parameters breaks the fingerprint.
    """
    text = "".join(f"{r['path']}\t{r['sha256']}\t{r['bytes']}\n" for r in sorted(rows, key=lambda r: r["path"]))
    if info is not None:
        text += f"{INFO_PATH}\t{canonical_json({k: v for k, v in info.items() if k != 'fingerprint'})}\n"
    return sha256_bytes(text.encode("utf-8"))
