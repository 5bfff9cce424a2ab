"""Every Parquet schema, column name, path template and the format version of a release.

One module holds the on-disk format (STYLE: "the on-disk format is data"). Bump ``SCHEMA_VERSION``'s
major number for any change an older reader cannot handle; minor for additive columns.
"""

from __future__ import annotations

import pyarrow as pa

from song.datasets.run.crowd import CROWD_COLUMNS

SCHEMA_VERSION = "1.3.0"  # 1.1: info.json records the pedestrian body radius; 1.2: the fingerprint covers info.json;
# 1.3: info.json records how the crowd was made (avoidance model, speed profile, personal space, scenario length),
# episodes record their split, reference pedestrian and predicted encounter time
INFO_FINGERPRINT_SINCE = (1, 2, 0)  # releases of this schema or later fingerprint their info.json too
FORMAT_NAME = "song.bench"
PARQUET_COMPRESSION = "zstd"
PARQUET_COMPRESSION_LEVEL = 9
ROW_GROUP_SIZE = 64 * 1024

# Path templates, relative to <bench>/<version>/
INFO_PATH = "meta/info.json"
SCENES_PATH = "meta/scenes.parquet"
MANIFEST_PATH = "meta/manifest.parquet"
CHANGELOG_PATH = "meta/CHANGELOG.md"
EPISODES_PATH = "data/episodes/part-{part:05d}.parquet"
PEDESTRIANS_PATH = "data/pedestrians/part-{part:05d}.parquet"
AVATARS_PATH = "data/avatars/part-{part:05d}.parquet"
BLOB_PATH = "blobs/sha256/{prefix}/{sha256}{ext}"

# Schema-metadata keys stamped into every Parquet file.
META_DATASET_VERSION = b"song.dataset_version"
META_SCHEMA_VERSION = b"song.schema_version"
META_TABLE = b"song.table"

DIFFICULTIES = ("easy", "medium", "hard")
MODES = ("co_directional", "counter_directional", "encounter", "random")

BLOB_REF = pa.struct([("path", pa.string()), ("sha256", pa.string()), ("bytes", pa.int64())])
VEC3 = pa.list_(pa.float64(), 3)
VEC4 = pa.list_(pa.float64(), 4)
GOAL = pa.struct([("position", VEC3), ("radius", pa.float64())])

EPISODES = pa.schema(
    [
        ("episode_id", pa.string()),
        ("scene_id", pa.string()),
        ("difficulty", pa.string()),
        ("mode", pa.string()),
        ("seed", pa.int64()),
        ("t0", pa.float64()),
        ("start_position", VEC3),
        ("start_yaw", pa.float64()),
        ("start_rotation", VEC4),  # quaternion [x, y, z, w] (Habitat order), yaw about +z
        ("goal_position", VEC3),
        ("goal_radius", pa.float64()),
        ("goals", pa.list_(GOAL)),  # Habitat spelling of the goal
        ("geodesic_distance", pa.float64()),  # L*, smoothed A* length, m
        ("optimal_time", pa.float64()),  # T* = L* / 0.5 m/s
        ("path", pa.list_(pa.list_(pa.float64(), 2))),
        ("path_length", pa.float64()),
        ("n_turns", pa.int32()),
        ("n_encounters", pa.int32()),
        ("corridor_width", pa.float64()),
        ("bin_length", pa.int8()),
        ("bin_turns", pa.int8()),
        ("bin_encounters", pa.int8()),
        ("bin_width", pa.int8()),
        ("score", pa.int8()),
        ("n_pedestrians", pa.int32()),
        ("pedestrian_ids", pa.list_(pa.int32())),
        ("config_sha256", pa.string()),
        ("split", pa.string()),  # schema ≥ 1.3: train | val | test … (whole scenes per split; before 1.3: test)
        ("reference_ped_id", pa.int32()),  # schema ≥ 1.3: the pedestrian the mode is about (-1: random)
        ("encounter_time", pa.float64()),  # schema ≥ 1.3: predicted time of the closest pass with it, s (null: none)
    ]
)

PEDESTRIANS = pa.schema([("scene_id", pa.string()), *CROWD_COLUMNS])  # the run's crowd table + its scene

AVATARS = pa.schema(
    [
        ("scene_id", pa.string()),
        ("ped_id", pa.int32()),
        ("avatar_id", pa.string()),
        ("activity", pa.string()),
        ("height_m", pa.float64()),
        ("cache", BLOB_REF),  # compact LBS cache (binding)
        ("asset", BLOB_REF),  # avatar asset (canonical Gaussians + skinning)
        ("amass", BLOB_REF),  # AMASS motion file
        ("materialized", BLOB_REF),  # optional paper-form FP16 cache
    ]
)

SCENES = pa.schema(
    [
        ("scene_id", pa.string()),
        ("source", pa.string()),
        ("source_sha256", pa.string()),  # sha256 of semantic_map.json
        ("venue_type", pa.string()),
        ("navigable_area_m2", pa.float64()),
        ("licence", pa.string()),
        ("resolution", pa.float64()),
        ("origin", pa.list_(pa.float64(), 2)),
        ("semantic_map", BLOB_REF),
        ("occupancy", BLOB_REF),
        ("gaussians", BLOB_REF),
        ("usd", BLOB_REF),
    ]
)

MANIFEST = pa.schema(
    [
        ("path", pa.string()),
        ("sha256", pa.string()),
        ("bytes", pa.int64()),
        ("rows", pa.int64()),  # null for non-Parquet files
    ]
)

TABLES = {"episodes": EPISODES, "pedestrians": PEDESTRIANS, "avatars": AVATARS, "scenes": SCENES, "manifest": MANIFEST}


def schema_major(version: str) -> int:
    """Major number of a semver string (``"1.2.0"`` → 1)."""
    return int(version.split(".", 1)[0])
