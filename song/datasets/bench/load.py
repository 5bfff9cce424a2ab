"""Load API for the runtime: ``song.datasets.bench.open(path, version=None)``.

Reads only the release's own files; never imports ``song.pipeline``.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from song.datasets.bench.info import (
    Info,
    check_schema_version,
    fingerprint_of,
    read_info,
    resolve_version,
    runtime_params,
    version_key,
)
from song.datasets.bench.schema import (
    AVATARS,
    AVATARS_PATH,
    DIFFICULTIES,
    EPISODES,
    EPISODES_PATH,
    INFO_FINGERPRINT_SINCE,
    INFO_PATH,
    MANIFEST_PATH,
    META_SCHEMA_VERSION,
    PEDESTRIANS,
    PEDESTRIANS_PATH,
    SCENES,
    SCENES_PATH,
)
from song.datasets.bench.types import AvatarBinding, Episode, PedestrianTrack, RuntimeParams, StaticMap
from song.datasets.limits import check_png_size, limits, over
from song.errors import BenchmarkError
from song.util import sha256_file

BLOB_ADDRESS = re.compile(r"blobs/sha256/([0-9a-f]{2})/([0-9a-f]{64})(\.[A-Za-z0-9]{1,8}){0,2}")


OPTIONAL_COLUMNS = frozenset({"split", "reference_ped_id", "encounter_time"})  # added in schema 1.3


class Benchmark:
    """An opened release. Tables are read once; per-scene data is decoded on first use and cached.

    A release is untrusted input: every path it names must stay inside its folder (symbolic links
    included), a blob is used only under its content address and only after its sha256 was checked
    (once per process), and sizes are bounded before decoding (:mod:`song.datasets.limits`).
    """

    def __init__(self, root: Path) -> None:
        self.root = root
        self._real_root = root.resolve()
        self._verified: set[Path] = set()
        self.info: Info = read_info(self._inside(INFO_PATH, "release info"))
        self.params: RuntimeParams = runtime_params(self.info, root / INFO_PATH)
        self.episodes_table = self._read(EPISODES_PATH.format(part=0), EPISODES)
        self.scenes_table = self._read(SCENES_PATH, SCENES)
        self.pedestrians_table = self._read(PEDESTRIANS_PATH.format(part=0), PEDESTRIANS)
        self.avatars_table = self._read(AVATARS_PATH.format(part=0), AVATARS)
        self._scenes = {row["scene_id"]: row for row in self.scenes_table.to_pylist()}
        self.static_map = lru_cache(maxsize=64)(self._static_map)
        self.pedestrians = lru_cache(maxsize=64)(self._pedestrians)

    @property
    def version(self) -> str:
        """The release's dataset version."""
        return self.info.dataset_version

    @functools.cached_property
    def integrity(self) -> str:
        """Why the release no longer matches its fingerprint, or "" when it does (checked once, cheaply).

        ``meta/info.json`` and the manifest against the fingerprint, the four tables against the
        manifest's sha256; the blobs are checked as they are read (:meth:`blob`). What ``song bench
        verify`` does in full, at the cost of hashing the tables alone.
        """
        try:
            manifest = pq.read_table(self._inside(MANIFEST_PATH, "manifest")).to_pylist()
            raw = json.loads(self._inside(INFO_PATH, "release info").read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            return f"{MANIFEST_PATH} cannot be read ({exc})"
        covered = version_key(self.info.schema_version) >= INFO_FINGERPRINT_SINCE
        if fingerprint_of(manifest, raw if covered else None) != self.info.fingerprint:
            return "meta/info.json or the manifest was edited (the fingerprint no longer matches)"
        listed = {row.get("path"): row for row in manifest}
        for rel in (
            EPISODES_PATH.format(part=0),
            SCENES_PATH,
            PEDESTRIANS_PATH.format(part=0),
            AVATARS_PATH.format(part=0),
        ):
            row = listed.get(rel)
            if row is None or sha256_file(self._inside(rel, "table")) != row.get("sha256"):
                return f"{rel} was edited (its sha256 is not the manifest's)"
        return ""

    def require_intact(self, allow_modified: bool = False) -> str:
        """Refuse a release that fails :attr:`integrity` unless ``allow_modified``; the problem ("" if none).

        Raises:
            BenchmarkError: one line naming the release and what changed.
        """
        if self.integrity and not allow_modified:
            raise BenchmarkError(
                f"{self.root}: {self.integrity}; results on it would not be the benchmark's "
                "(`song bench verify` lists every change; --allow-modified runs it, marked unofficial)"
            )
        return self.integrity

    @functools.cached_property
    def max_pedestrians(self) -> int:
        """The largest number of pedestrians in one scene of the release."""
        table = self.pedestrians_table.select(["scene_id", "ped_id"])
        if table.num_rows == 0:
            return 0
        counts = table.group_by("scene_id").aggregate([("ped_id", "count_distinct")])
        return int(max(counts.column("ped_id_count_distinct").to_pylist()))

    def _inside(self, rel: str, what: str) -> Path:
        """``root / rel`` resolved, refused when it leaves the release (``..``, absolute, symlinks)."""
        path = (self.root / rel).resolve()
        if not path.is_relative_to(self._real_root):
            raise BenchmarkError(f"{self.root}: {what} {rel!r} resolves outside the release ({path})")
        return path

    def _read(self, rel: str, schema):
        """A release table, refused (one line naming the file and column) when a column is missing or mistyped.

        Columns added by later schema versions (:data:`OPTIONAL_COLUMNS`) may be absent.
        """
        path = self._inside(rel, "table")
        try:
            meta = pq.read_metadata(path)
            if meta.num_rows > limits().max_table_rows:
                raise over(path, "", "row count", meta.num_rows, "max_table_rows")
            decoded = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
            if decoded > limits().max_array_bytes:  # a tiny file can declare a huge decoded table
                raise over(path, "", "decoded size (bytes)", decoded, "max_array_bytes")
            table = pq.read_table(path)
        except (OSError, ValueError) as exc:
            raise BenchmarkError(f"{path}: cannot read table: {exc}") from exc
        found = (table.schema.metadata or {}).get(META_SCHEMA_VERSION)
        if found is None:
            raise BenchmarkError(f"{path}: no schema version in the Parquet metadata; not a song release file")
        check_schema_version(found.decode(), path)
        for field in schema:
            if field.name not in table.column_names:
                if field.name not in OPTIONAL_COLUMNS:
                    raise BenchmarkError(f"{path}: column {field.name!r} is missing")
                continue
            found_type = table.schema.field(field.name).type
            if found_type != field.type and not (pa.types.is_null(found_type) and field.nullable):
                raise BenchmarkError(f"{path}: column {field.name!r} is {found_type}, expected {field.type}")
        return table

    def blob(self, ref: dict | None) -> Path | None:
        """Path of a blob reference ``{path, sha256, bytes}`` after checking it (None stays None).

        Raises:
            BenchmarkError: the path is not the content address of its sha256, leaves the release, or
                the file's size or sha256 differs from the reference.
        """
        if not ref:
            return None
        rel, digest = ref.get("path"), ref.get("sha256")
        match = BLOB_ADDRESS.fullmatch(rel) if isinstance(rel, str) else None
        if match is None or match.group(2) != digest or match.group(1) != digest[:2]:
            raise BenchmarkError(f"{self.root}: blob path {rel!r} is not the content address of sha256 {digest!r}")
        path = self._inside(rel, "blob path")
        if path not in self._verified:
            if not path.is_file() or path.stat().st_size != ref.get("bytes") or sha256_file(path) != digest:
                raise BenchmarkError(f"{self.root / rel}: missing or altered blob; run `song bench verify`")
            self._verified.add(path)
        return path

    def _static_map(self, scene_id: str) -> StaticMap:
        import cv2

        row = self._scenes.get(scene_id)
        if row is None:
            raise BenchmarkError(f"{self.root}: scene '{scene_id}' is not in this release")
        path = self.blob(row["occupancy"])
        raw = path.read_bytes()
        check_png_size(raw, path)  # before decoding
        cells = cv2.imdecode(np.frombuffer(raw, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if cells is None or cells.ndim != 2 or cells.dtype != np.uint8:
            raise BenchmarkError(f"{path}: occupancy is not an 8-bit single-channel PNG")
        return StaticMap(cells=cells, resolution=float(row["resolution"]), origin=tuple(row["origin"]))

    def _pedestrians(self, scene_id: str) -> tuple[PedestrianTrack, ...]:
        table = self.pedestrians_table.filter(pc.equal(self.pedestrians_table.column("scene_id"), scene_id))
        ped = table.column("ped_id").to_numpy()
        t = table.column("t").to_numpy()
        xy = np.column_stack([table.column("x").to_numpy(), table.column("y").to_numpy()])
        yaw = table.column("yaw").to_numpy()
        tracks = []
        for ped_id in np.unique(ped):
            mask = ped == ped_id
            tracks.append(PedestrianTrack(int(ped_id), t[mask], xy[mask], yaw[mask]))
        return tuple(tracks)

    def _avatars(self, scene_id: str) -> list[AvatarBinding]:
        table = self.avatars_table.filter(pc.equal(self.avatars_table.column("scene_id"), scene_id))
        return [
            AvatarBinding(row["ped_id"], row["avatar_id"], self.blob(row["asset"]), self.blob(row["cache"]))
            for row in table.to_pylist()
        ]

    def __len__(self) -> int:
        return self.episodes_table.num_rows

    def episode_ids(self) -> list[str]:
        """Every episode id, in table order."""
        return self.episodes_table.column("episode_id").to_pylist()

    def splits(self) -> set[str]:
        """The splits this release holds (``{"test"}`` before schema 1.3)."""
        table = self.episodes_table
        return set(table.column("split").to_pylist()) if "split" in table.column_names else {"test"}

    def episodes(
        self, difficulty: str | None = None, scene: str | None = None, split: str | None = None
    ) -> Iterator[Episode]:
        """Typed episodes in episode-id order, optionally filtered by difficulty, scene and split.

        Releases before schema 1.3 have no split column: all their episodes are ``test``.
        """
        table = self.episodes_table
        if split is not None:
            names = self.splits()
            if split not in names:
                raise BenchmarkError(
                    f"{self.root}: no split '{split}' in this release (it has {', '.join(sorted(names))})"
                )
            if "split" in table.column_names:
                table = table.filter(pc.equal(table.column("split"), split))
        if difficulty is not None and difficulty not in DIFFICULTIES:
            raise BenchmarkError(f"unknown difficulty '{difficulty}': use one of {', '.join(DIFFICULTIES)}")
        if difficulty is not None:
            table = table.filter(pc.equal(table.column("difficulty"), difficulty))
        if scene is not None:
            table = table.filter(pc.equal(table.column("scene_id"), scene))
        for row in table.to_pylist():
            yield self._episode(row)

    def episode(self, episode_id: str) -> Episode:
        """One episode by id."""
        table = self.episodes_table.filter(pc.equal(self.episodes_table.column("episode_id"), episode_id))
        if table.num_rows != 1:
            raise BenchmarkError(f"{self.root}: episode '{episode_id}' not found")
        return self._episode(table.to_pylist()[0])

    def _episode(self, row: dict) -> Episode:
        scene_id = row["scene_id"]
        factors = {k: row[k] for k in ("path_length", "n_turns", "n_encounters", "corridor_width", "score")}
        factors.update({k: row[k] for k in ("bin_length", "bin_turns", "bin_encounters", "bin_width")})
        return Episode(
            episode_id=row["episode_id"],
            scene_id=scene_id,
            difficulty=row["difficulty"],
            mode=row["mode"],
            seed=int(row["seed"]),
            start_xy=np.asarray(row["start_position"][:2], dtype=np.float64),
            start_yaw=float(row["start_yaw"]),
            goal_xy=np.asarray(row["goal_position"][:2], dtype=np.float64),
            goal_radius=float(row["goal_radius"]),
            geodesic_distance=float(row["geodesic_distance"]),
            optimal_time=float(row["optimal_time"]),
            t0=float(row["t0"]),
            path=np.asarray(row["path"], dtype=np.float64).reshape(-1, 2),
            static_map=self.static_map(scene_id),
            pedestrians=list(self.pedestrians(scene_id)),
            avatars=self._avatars(scene_id),
            factors=factors,
            params=self.params,
            gaussians_path=self.blob(self._scenes[scene_id]["gaussians"]),
            usd_path=self.blob(self._scenes[scene_id].get("usd")),
            split=row.get("split") or "test",
            reference_ped_id=int(row.get("reference_ped_id", -1)),
            encounter_time=float("nan") if row.get("encounter_time") is None else float(row["encounter_time"]),
        )


def open_benchmark(path: str | Path, version: str | None = None) -> Benchmark:
    """Open a release: ``path`` is a release folder, or a benchmark folder plus ``version`` (latest when None).

    ``path`` may also be written ``DIR@X.Y.Z``.
    """
    text = str(path)
    if "@" in text and version is None:
        text, version = text.rsplit("@", 1)
    path = Path(text)
    if (path / INFO_PATH).is_file() and version is None:
        return Benchmark(path)
    return Benchmark(resolve_version(path, version))
