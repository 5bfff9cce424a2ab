"""Recorded rollouts as a LeRobot dataset: codebase v3.0 (what LeRobot's current release reads), or v2.1.

v3.0 (the default) packs episodes into shared files, as ``lerobot``'s own writer does
(``lerobot/datasets/lerobot_dataset.py`` and ``utils.py`` at v0.4.4 define the layout read here):

    DS/meta/info.json                                   features, fps, counts, path templates, file size limits
    DS/meta/stats.json                                  statistics of every feature over the whole dataset
    DS/meta/tasks.parquet                               task strings (the index) → task_index
    DS/meta/episodes/chunk-000/file-000.parquet         one row per episode: length, tasks, where its rows and
                                                        video frames are (file indices, frame range, timestamps),
                                                        its statistics (``stats/<feature>/<stat>``), SONG's
                                                        episode id, outcome and difficulty
    DS/data/chunk-000/file-000.parquet                  the steps of consecutive episodes (≤ 100 MB a file)
    DS/videos/<key>/chunk-000/file-000.mp4              their frames, one H.264 stream (≤ 200 MB a file);
                                                        an episode starts at its ``from_timestamp``

A file index rolls over to the next chunk after 1,000 files. v2.1 (``--format v2.1``, for older
stacks) keeps one Parquet file and one video per episode with ``meta/*.jsonl``.

Depth is stored as RealSense drivers and LeRobot's RealSense camera deliver it: ``uint16``
millimetres, (height, width), 0 where there is no depth. Lossless at the sensor's 1 mm step, half
the bytes of float32, and what a model trained here meets on the real robot's recordings.
Statistics follow LeRobot: per dimension for vectors, per channel in [0, 1] with shape (3, 1, 1) for
videos; depth gets one scalar set (in mm), which broadcasts over the image.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from song.util import write_json_atomic, write_text_atomic

FORMATS = ("v3.0", "v2.1")
PARTIAL_DIR = ".partial"  # the dataset is written here and moved into place when whole
TASK = "navigate to the goal among pedestrians"
ROBOT_TYPE = "song_differential_drive"
CHUNK_SIZE = 1000  # files per chunk folder
DATA_FILE_MB = 100  # LeRobot's default limits on one shared file
VIDEO_FILE_MB = 200
V30 = {
    "data": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
    "video": "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
    "episodes": "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
}
V21 = {
    "data": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
    "video": "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4",
}


def features(plans: list[Any]) -> dict[str, dict]:
    """LeRobot feature declarations: the sensors' (from their spaces), then the action, rewards and indices."""
    out: dict[str, dict] = {plan.key: plan.spec for plan in plans}
    out["action"] = {"dtype": "float32", "shape": [2], "names": ["v", "omega"]}
    for name in ("next.reward", "reward.progress", "reward.terminal", "timestamp"):
        out[name] = {"dtype": "float32", "shape": [1], "names": None}
    for name in ("next.done", "next.success"):
        out[name] = {"dtype": "bool", "shape": [1], "names": None}
    for name in ("frame_index", "episode_index", "index", "task_index"):
        out[name] = {"dtype": "int64", "shape": [1], "names": None}
    return out


def episode_table(episode: dict[str, Any], episode_index: int, first_index: int, fps: float):
    """One rollout's steps as a Parquet table (every feature but the videos)."""
    import pyarrow as pa

    n = episode["steps"]
    success = episode["outcome"] == "success"
    cols: dict[str, Any] = {}
    for plan in episode["plans"]:
        if plan.kind == "vector":
            values = episode[plan.key]
            cols[plan.key] = pa.FixedSizeListArray.from_arrays(pa.array(values.ravel()), values.shape[1])
        elif plan.kind == "depth":  # (n, H, W) uint16: a list of rows per step, as LeRobot's Array2D
            values = episode[plan.key]
            rows = pa.FixedSizeListArray.from_arrays(pa.array(values.ravel()), values.shape[2])
            cols[plan.key] = pa.FixedSizeListArray.from_arrays(rows, values.shape[1])
    cols["action"] = pa.FixedSizeListArray.from_arrays(pa.array(episode["action"].ravel()), 2)
    progress = np.asarray(episode["progress"], np.float32)
    terminal = np.asarray(episode["terminal"], np.float32)
    cols["next.reward"] = progress + terminal
    cols["reward.progress"] = progress
    cols["reward.terminal"] = terminal
    done = np.zeros(n, bool)
    done[-1] = True
    cols["next.done"] = done
    cols["next.success"] = done & success
    cols["timestamp"] = (np.arange(n) / fps).astype(np.float32)
    cols["frame_index"] = np.arange(n, dtype=np.int64)
    cols["episode_index"] = np.full(n, episode_index, np.int64)
    cols["index"] = first_index + np.arange(n, dtype=np.int64)
    cols["task_index"] = np.zeros(n, np.int64)
    return pa.table(cols)


def _moments(values: np.ndarray, axis: tuple[int, ...], keep: tuple[int, ...] | None = None) -> dict[str, Any]:
    """min, max, mean, std over ``axis`` (float64), reshaped to ``keep`` when given; count = samples."""
    stats = {
        "min": values.min(axis=axis),
        "max": values.max(axis=axis),
        "mean": values.mean(axis=axis),
        "std": values.std(axis=axis),
    }
    out = {k: (np.reshape(v, keep) if keep else np.atleast_1d(v)).tolist() for k, v in stats.items()}
    out["count"] = [int(values.shape[0])]
    return out


def episode_stats(episode: dict[str, Any], table) -> dict[str, dict]:
    """LeRobot's per-episode statistics of every feature (see the module's note for images and depth)."""
    out = {}
    for name in table.column_names:
        values = np.asarray(table.column(name).to_pylist(), dtype=np.float64)
        if values.ndim == 1:
            values = values[:, None]
        if values.ndim == 3:  # depth: one scalar set over every pixel of every step
            values = values.reshape(len(values), -1)
            out[name] = _moments(values, (0, 1), (1,))
            continue
        out[name] = _moments(values, (0,))
    for plan in (p for p in episode["plans"] if p.kind == "video"):
        frames = np.asarray(episode[plan.key], np.float64) / 255.0  # (n, H, W, 3)
        out[plan.key] = _moments(frames, (0, 1, 2), (3, 1, 1))
    return out


def aggregate_stats(per_episode: list[dict[str, dict]]) -> dict[str, dict]:
    """The whole dataset's statistics from the episodes' (pooled mean and variance, as LeRobot's)."""
    out = {}
    for key in per_episode[0] if per_episode else ():
        parts = [s[key] for s in per_episode]
        counts = np.array([p["count"][0] for p in parts], np.float64)
        shape = np.asarray(parts[0]["mean"]).shape
        weights = (counts / counts.sum()).reshape((-1,) + (1,) * len(shape))
        means = np.array([p["mean"] for p in parts])
        mean = (weights * means).sum(axis=0)
        variance = (weights * (np.array([p["std"] for p in parts]) ** 2 + (means - mean) ** 2)).sum(axis=0)
        out[key] = {
            "min": np.min([p["min"] for p in parts], axis=0).tolist(),
            "max": np.max([p["max"] for p in parts], axis=0).tolist(),
            "mean": mean.tolist(),
            "std": np.sqrt(variance).tolist(),
            "count": [int(counts.sum())],
        }
    return out


def _song_fields(result: dict[str, Any]) -> dict[str, str]:
    """SONG's own per-episode fields (beside LeRobot's)."""
    return {"song_episode_id": result["episode_id"], "outcome": result["outcome"], "difficulty": result["difficulty"]}


def _fps_value(fps: float) -> int | float:
    return int(fps) if float(fps).is_integer() else float(fps)


def _info(version: str, kept: list[dict[str, Any]], frames: int, fps: float, split: str, about: dict) -> dict:
    info: dict[str, Any] = {
        "codebase_version": version,
        "robot_type": ROBOT_TYPE,
        "total_episodes": len(kept),
        "total_frames": frames,
        "total_tasks": 1,
        "chunks_size": CHUNK_SIZE,
    }
    plans = kept[0]["plans"] if kept else []
    videos = sum(p.kind == "video" for p in plans)  # video features: one file each per episode in v2.1
    if version == "v3.0":
        info |= {"data_files_size_in_mb": DATA_FILE_MB, "video_files_size_in_mb": VIDEO_FILE_MB}
        paths = V30
    else:
        info |= {"total_videos": videos * len(kept), "total_chunks": max(1, (len(kept) - 1) // CHUNK_SIZE + 1)}
        paths = V21
    info |= {
        "fps": _fps_value(fps),
        "splits": {split: f"0:{len(kept)}"},
        "data_path": paths["data"],
        "video_path": paths["video"] if videos else None,
        "features": features(plans),
        "song": about,
    }
    return info


def _empty_episodes():
    import pyarrow as pa

    columns = {"episode_index": pa.int64(), "tasks": pa.list_(pa.string()), "length": pa.int64()}
    columns |= dict.fromkeys(("data/chunk_index", "data/file_index", "dataset_from_index", "dataset_to_index",
                              "meta/episodes/chunk_index", "meta/episodes/file_index"), pa.int64())  # fmt: skip
    return pa.schema(columns | dict.fromkeys(("song_episode_id", "outcome", "difficulty"), pa.string()))


def _next_file(chunk: int, file: int) -> tuple[int, int]:
    return (chunk + 1, 0) if file + 1 >= CHUNK_SIZE else (chunk, file + 1)


def _tasks_table():
    """``meta/tasks.parquet`` as pandas writes ``DataFrame({"task_index": [0]}, index=[TASK])``.

    LeRobot reads it with ``pandas.read_parquet`` and looks tasks up by the index; pandas is not a
    dependency of SONG, so the table carries the metadata pandas would write.
    """
    import pyarrow as pa

    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64",
             "metadata": None},
            {"name": None, "field_name": "__index_level_0__", "pandas_type": "unicode", "numpy_type": "object",
             "metadata": None},
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }  # fmt: skip
    table = pa.table({"task_index": pa.array([0], pa.int64()), "__index_level_0__": pa.array([TASK])})
    return table.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})


def write_v30(out: Path, kept: list[dict[str, Any]], fps: float, split: str, about: dict) -> int:
    """Write the v3.0 layout into ``out`` (an empty folder); returns the frames written."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from song.render.video import Mp4Writer

    rows: list[dict[str, Any]] = []
    stats: list[dict[str, dict]] = []
    data_file, data_tables, data_bytes = (0, 0), [], 0
    video_keys = [p.key for p in (kept[0]["plans"] if kept else []) if p.kind == "video"]
    videos: dict[str, Any] = {}  # key → open Mp4Writer
    video_file = dict.fromkeys(video_keys, (0, 0))
    frames = 0

    def flush_data() -> None:
        path = out / V30["data"].format(chunk_index=data_file[0], file_index=data_file[1])
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.concat_tables(data_tables), path, compression="zstd")

    for index, result in enumerate(kept):
        table = episode_table(result, index, frames, fps)
        if data_tables and data_bytes + table.nbytes > DATA_FILE_MB * 1e6:
            flush_data()
            data_file, data_tables, data_bytes = _next_file(*data_file), [], 0
        data_tables.append(table)
        data_bytes += table.nbytes
        row: dict[str, Any] = {
            "episode_index": index, "tasks": [TASK], "length": result["steps"],
            "data/chunk_index": data_file[0], "data/file_index": data_file[1],
            "dataset_from_index": frames, "dataset_to_index": frames + result["steps"],
        }  # fmt: skip
        for key in video_keys:
            writer = videos.get(key)
            if writer is not None and writer.size_bytes >= VIDEO_FILE_MB * 1e6:
                writer.close()
                video_file[key], writer = _next_file(*video_file[key]), None
            if writer is None:
                chunk, file = video_file[key]
                path = out / V30["video"].format(video_key=key, chunk_index=chunk, file_index=file)
                path.parent.mkdir(parents=True, exist_ok=True)
                writer = videos[key] = Mp4Writer(path, fps)
            start = writer.frames / fps
            writer.write(result[key])
            row |= {f"videos/{key}/chunk_index": video_file[key][0], f"videos/{key}/file_index": video_file[key][1],
                    f"videos/{key}/from_timestamp": start, f"videos/{key}/to_timestamp": writer.frames / fps}  # fmt: skip
        row |= {"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0}
        episode = episode_stats(result, table)
        stats.append(episode)
        for feature, values in episode.items():
            for name, value in values.items():
                row[f"stats/{feature}/{name}"] = value
        row |= _song_fields(result)
        rows.append(row)
        frames += result["steps"]
    if data_tables:
        flush_data()
    for writer in videos.values():
        writer.close()
    meta = out / "meta"
    path = out / V30["episodes"].format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pylist(rows, schema=None if rows else _empty_episodes()), path)
    meta.mkdir(parents=True, exist_ok=True)
    pq.write_table(_tasks_table(), meta / "tasks.parquet")
    write_json_atomic(meta / "stats.json", aggregate_stats(stats))
    write_json_atomic(meta / "info.json", _info("v3.0", kept, frames, fps, split, about))
    return frames


def write_v21(out: Path, kept: list[dict[str, Any]], fps: float, split: str, about: dict) -> int:
    """Write the v2.1 layout (one Parquet file and one video per episode, ``meta/*.jsonl``)."""
    import pyarrow.parquet as pq

    from song.render.video import write_mp4

    frames, stats = 0, []
    for index, result in enumerate(kept):
        chunk = index // CHUNK_SIZE
        table = episode_table(result, index, frames, fps)
        path = out / V21["data"].format(episode_chunk=chunk, episode_index=index)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path, compression="zstd")
        for plan in (p for p in result["plans"] if p.kind == "video"):
            video = out / V21["video"].format(episode_chunk=chunk, video_key=plan.key, episode_index=index)
            video.parent.mkdir(parents=True, exist_ok=True)
            write_mp4(video, result[plan.key], fps)
        stats.append({"episode_index": index, "stats": episode_stats(result, table)})
        frames += result["steps"]
    lines = [{"episode_index": i, "tasks": [TASK], "length": r["steps"]} | _song_fields(r) for i, r in enumerate(kept)]
    meta = out / "meta"
    meta.mkdir(parents=True, exist_ok=True)
    write_json_atomic(meta / "info.json", _info("v2.1", kept, frames, fps, split, about))
    write_text_atomic(meta / "episodes.jsonl", "".join(json.dumps(x, sort_keys=True) + "\n" for x in lines))
    write_text_atomic(meta / "episodes_stats.jsonl", "".join(json.dumps(x, sort_keys=True) + "\n" for x in stats))
    write_text_atomic(meta / "tasks.jsonl", json.dumps({"task_index": 0, "task": TASK}) + "\n")
    return frames


def write_dataset(
    out: Path, kept: list[dict[str, Any]], fps: float, split: str, about: dict[str, Any], version: str = "v3.0"
) -> int:
    """Write recorded rollouts as a LeRobot dataset in ``out``; returns the frames written.

    Built in ``out/.partial``, then moved in: ``data``, ``videos``, then ``meta`` (the index) last. The
    caller holds ``out``'s lock.
    """
    partial = out / PARTIAL_DIR
    partial.mkdir(parents=True, exist_ok=True)
    written = (write_v30 if version == "v3.0" else write_v21)(partial, kept, fps, split, about)
    for name in ("data", "videos", "meta"):
        if (partial / name).exists():
            os.replace(partial / name, out / name)
    partial.rmdir()
    return written
