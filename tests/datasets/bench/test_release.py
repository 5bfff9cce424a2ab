"""Releases: round trip, immutability, verify, diff, plain-Parquet readability, Habitat projection."""

from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import song.datasets.bench as bench
from song.datasets.bench.export import export_bench
from song.datasets.bench.habitat import from_habitat_point, to_habitat_point, to_habitat_rotation
from song.datasets.bench.release import diff_releases, list_versions, verify_release
from song.datasets.bench.schema import EPISODES_PATH, META_DATASET_VERSION, META_SCHEMA_VERSION
from song.errors import BenchmarkError, SchemaVersionError


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(autouse=True)
def _fixed_clock(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")


def test_round_trip_matches_run(graded_run, tmp_path: Path) -> None:
    run = graded_run()
    result = export_bench(run, tmp_path / "bench", "1.0.0", notes="first")
    opened = bench.open(tmp_path / "bench")
    assert opened.version == "1.0.0" and len(opened) == 10 == result.n_episodes
    source = {row["episode_id"]: row for row in pq.read_table(run / "manifest/episodes.parquet").to_pylist()}
    assert opened.episode_ids() == sorted(source)
    for episode in opened.episodes():
        row = source[episode.episode_id]
        np.testing.assert_allclose(episode.start_xy, [row["start_x"], row["start_y"]])
        np.testing.assert_allclose(episode.goal_xy, [row["goal_x"], row["goal_y"]])
        np.testing.assert_allclose(episode.path, row["path"])
        assert (episode.difficulty, episode.mode, episode.seed) == (row["difficulty"], row["mode"], row["seed"])
        assert episode.geodesic_distance == row["geodesic_distance"] and episode.t0 == row["t0"]
        assert episode.factors["n_encounters"] == row["n_encounters"] and episode.goal_radius == 1.0
        crowd = pq.read_table(run / "scenes" / episode.scene_id / "crowd.parquet").to_pandas()
        assert [t.ped_id for t in episode.pedestrians] == sorted(crowd.ped_id.unique())
        for track in episode.pedestrians:
            mine = crowd[crowd.ped_id == track.ped_id]
            np.testing.assert_array_equal(track.t, mine.t.to_numpy())
            np.testing.assert_array_equal(track.xy[:, 0], mine.x.to_numpy())
        assert episode.static_map.cells.shape == (80, 160) and episode.static_map.resolution == 0.05
    hard = list(opened.episodes(difficulty="hard"))
    assert hard and all(e.difficulty == "hard" for e in hard)
    assert {e.scene_id for e in opened.episodes(scene="scene_1")} == {"scene_1"}


def test_identical_inputs_identical_bytes_and_refuse_existing(graded_run, tmp_path: Path) -> None:
    run = graded_run()
    a = export_bench(run, tmp_path / "x", "1.0.0")
    b = export_bench(run, tmp_path / "y", "1.0.0")
    assert a.fingerprint == b.fingerprint and _files(a.path) == _files(b.path)
    before = _files(a.path)
    with pytest.raises(BenchmarkError, match="already exists"):
        export_bench(run, tmp_path / "x", "1.0.0")
    assert _files(a.path) == before and list_versions(tmp_path / "x") == ["1.0.0"]
    # a new version of the same run: only the version stamps differ
    c = export_bench(run, tmp_path / "x", "1.1.0", parent="1.0.0")
    assert c.fingerprint != a.fingerprint
    old = pq.read_table(a.path / EPISODES_PATH.format(part=0))
    new = pq.read_table(c.path / EPISODES_PATH.format(part=0))
    assert old.replace_schema_metadata(None).equals(new.replace_schema_metadata(None))
    assert new.schema.metadata[META_DATASET_VERSION] == b"1.1.0"
    assert {p for p in _files(a.path) if p.startswith("blobs/")} == {
        p for p in _files(c.path) if p.startswith("blobs/")
    }
    assert diff_releases(a.path, c.path)["unchanged"] == 10


def test_interrupted_export_leaves_nothing(graded_run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = graded_run()
    import song.datasets.bench.export as export_module

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(export_module, "fingerprint_of", boom)
    with pytest.raises(KeyboardInterrupt):
        export_bench(run, tmp_path / "bench", "1.0.0")
    assert list((tmp_path / "bench").iterdir()) == []


@pytest.mark.parametrize("damage", ["parquet_byte", "blob_byte", "delete", "add"])
def test_verify_catches_damage(graded_run, tmp_path: Path, damage: str) -> None:
    release = export_bench(graded_run(), tmp_path / "bench", "1.0.0").path
    assert verify_release(release).ok
    episodes = release / EPISODES_PATH.format(part=0)
    blob = sorted((release / "blobs").rglob("*.png"))[0]
    if damage == "parquet_byte" or damage == "blob_byte":
        target = episodes if damage == "parquet_byte" else blob
        data = bytearray(target.read_bytes())
        data[len(data) // 2] ^= 0xFF
        target.write_bytes(bytes(data))
        expected = ("altered", target)
    elif damage == "delete":
        blob.unlink()
        expected = ("missing", blob)
    else:
        extra = release / "data" / "notes.txt"
        extra.write_text("hello")
        expected = ("extra", extra)
    report = verify_release(release)
    assert not report.ok
    assert getattr(report, expected[0]) == [expected[1].relative_to(release).as_posix()]


def test_diff_reports_added_removed_changed(graded_run, tmp_path: Path) -> None:
    a = export_bench(graded_run("a", n_scenes=2), tmp_path / "bench", "1.0.0").path
    b = export_bench(graded_run("b", n_scenes=3, shift=0.5), tmp_path / "bench", "2.0.0").path
    diff = diff_releases(a, b)
    assert diff["added"] == [f"scene_2-{e:03d}" for e in range(5)]
    assert diff["removed"] == [] and len(diff["changed"]) == 10
    assert diff["content_changes"] == {}


def test_diff_reports_columns_that_gained_values(graded_run, tmp_path: Path) -> None:
    """A later version that fills a column the earlier left empty (as --amass does) is reported."""
    run = graded_run("a")
    manifest = run / "manifest" / "episodes.parquet"
    full = pq.read_table(manifest)
    pq.write_table(full.drop_columns(["encounter_time"]), manifest)  # graded before encounter times existed
    a = export_bench(run, tmp_path / "bench", "1.0.0").path
    pq.write_table(full, manifest)
    b = export_bench(run, tmp_path / "bench", "1.1.0").path
    diff = diff_releases(a, b)
    assert diff["schema_changes"] == {} and diff["content_changes"] == {
        "episodes": {"filled": ["encounter_time"], "emptied": []}
    }
    assert diff_releases(b, a)["content_changes"]["episodes"] == {"filled": [], "emptied": ["encounter_time"]}


def test_plain_parquet_and_duckdb_query(graded_run, tmp_path: Path) -> None:
    release = export_bench(graded_run(), tmp_path / "bench", "1.0.0").path
    import pandas as pd

    episodes = release / EPISODES_PATH.format(part=0)
    frame = pd.read_parquet(episodes)
    assert set(frame.columns) >= {"episode_id", "scene_id", "difficulty", "start_rotation", "goals"}
    assert (frame.difficulty == "hard").sum() == 2
    duckdb = pytest.importorskip("duckdb")
    count = duckdb.sql(f"SELECT count(*) FROM '{episodes}' WHERE difficulty = 'hard'").fetchall()[0][0]
    assert count == 2


def test_schema_major_checked_both_ways(graded_run, tmp_path: Path) -> None:
    release = export_bench(graded_run(), tmp_path / "bench", "1.0.0").path
    info_path = release / "meta/info.json"
    info = json.loads(info_path.read_text())
    for found, hint in (("2.0.0", "upgrade"), ("0.9.0", "re-export")):
        info["schema_version"] = found
        info_path.write_text(json.dumps(info))
        with pytest.raises(SchemaVersionError, match=hint):
            bench.open(release)
    # and inside a Parquet file
    info["schema_version"] = "1.0.0"
    info_path.write_text(json.dumps(info))
    episodes = release / EPISODES_PATH.format(part=0)
    table = pq.read_table(episodes)
    meta = dict(table.schema.metadata)
    meta[META_SCHEMA_VERSION] = b"9.0.0"
    pq.write_table(table.replace_schema_metadata(meta), episodes)
    with pytest.raises(SchemaVersionError, match=str(episodes)):
        bench.open(release)


def test_open_errors_are_actionable(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(BenchmarkError, match="export-bench"):
        bench.open(tmp_path / "empty")
    with pytest.raises(BenchmarkError, match="missing"):
        bench.open(tmp_path / "nowhere")


def test_habitat_projection(graded_run, tmp_path: Path) -> None:
    release = export_bench(graded_run(), tmp_path / "bench", "1.0.0").path
    from song.datasets.bench.habitat import export_habitat

    out = export_habitat(bench.open(release), tmp_path / "hab.json.gz")
    episodes = json.loads(gzip.decompress(out.read_bytes()))["episodes"]
    assert len(episodes) == 10
    first = bench.open(release).episode(episodes[0]["episode_id"])
    np.testing.assert_allclose(from_habitat_point(np.array(episodes[0]["start_position"]))[:2], first.start_xy)
    # the scene asset: the collision proxy and floor as a Y-up GLB, the start on the floor inside it
    import trimesh

    glb = trimesh.load(tmp_path / episodes[0]["scene_id"], force="scene")
    lo, hi = glb.bounds
    assert lo[1] == pytest.approx(0.0, abs=0.05) and 2.0 < hi[1] < 4.0  # floor at y = 0, walls up +Y
    start = np.array(episodes[0]["start_position"])
    assert (lo[[0, 2]] <= start[[0, 2]]).all() and (start[[0, 2]] <= hi[[0, 2]]).all()
    walls = first.static_map  # the proxy's footprint matches the release's map
    assert hi[0] - lo[0] == pytest.approx(walls.cells.shape[1] * walls.resolution, abs=0.2)
    # pedestrians beside it, in Habitat's frame, equal to the release's tracks
    info = episodes[0]["info"]
    assert info["song_t0"] == first.t0 and info["song_scene_id"] == first.scene_id
    tracks = json.loads(gzip.decompress((tmp_path / info["song_pedestrians"]).read_bytes()))["pedestrians"]
    assert len(tracks) == len(first.pedestrians) > 0
    ours = first.pedestrians[0]
    np.testing.assert_allclose(from_habitat_point(np.array(tracks[0]["position"]))[:, :2], ours.xy, atol=1e-4)
    pts = np.random.default_rng(0).normal(size=(20, 3))
    np.testing.assert_allclose(from_habitat_point(to_habitat_point(pts)), pts)
    # heading θ = 0 (our +x) must map to Habitat's +x direction: rotate −Z by the quaternion
    x, y, z, w = to_habitat_rotation(0.0)
    angle = 2 * np.arctan2(y, w)
    forward = np.array([-np.sin(angle), 0.0, -np.cos(angle)])
    np.testing.assert_allclose(forward, [1.0, 0.0, 0.0], atol=1e-12)
    shutil.rmtree(release)


def _scene_1_for_training(run: Path) -> Path:
    """The graded run with scene_1's episodes moved to the train split (scene_0's stay test)."""
    manifest = run / "manifest" / "episodes.parquet"
    table = pq.read_table(manifest)
    split = ["train" if s == "scene_1" else "test" for s in table.column("scene_id").to_pylist()]
    pq.write_table(table.append_column("split", pa.array(split)), manifest)
    return run


def test_splits_in_the_release_and_eval_defaults_to_test(graded_run, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from song.cli import app

    run = _scene_1_for_training(graded_run())
    release = bench.open(export_bench(run, tmp_path / "bench", "1.0.0").path)
    assert release.splits() == {"train", "test"}
    assert {e.scene_id for e in release.episodes(split="train")} == {"scene_1"}
    assert {e.split for e in release.episodes(split="test")} == {"test"}
    with pytest.raises(BenchmarkError, match="no split 'val'"):
        list(release.episodes(split="val"))
    out = tmp_path / "eval"
    result = CliRunner().invoke(app, ["eval", "--bench", str(release.root), "--policy", "straight", "--out", str(out)])
    assert result.exit_code == 0, result.output
    evaluated = pq.read_table(next(out.rglob("*.parquet"))).column("episode_id").to_pylist()
    assert evaluated and all(e.startswith("scene_0") for e in evaluated)  # test split only
    from song.datasets.bench.habitat import export_habitat

    folder = export_habitat(release, tmp_path / "habitat")
    for name, scene in (("train", "scene_1"), ("test", "scene_0")):  # Habitat's <split>/<split>.json.gz
        episodes = json.loads(gzip.decompress((folder / name / f"{name}.json.gz").read_bytes()))["episodes"]
        assert episodes and {e["info"]["song_scene_id"] for e in episodes} == {scene}
        assert {e["scene_id"] for e in episodes} == {f"scenes/{scene}.glb"}
        assert (folder / "scenes" / f"{scene}.glb").is_file()


def test_next_export_removes_a_killed_exports_temporary_folder(graded_run, tmp_path: Path) -> None:
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    leftover = tmp_path / "bench" / f".0.9.0.tmp-{int(dead.stdout)}"  # as kill -9 during export leaves it
    (leftover / "data").mkdir(parents=True)
    export_bench(graded_run(), tmp_path / "bench", "1.0.0")
    assert not leftover.exists()
    assert [p.name for p in (tmp_path / "bench").iterdir()] == ["1.0.0"]


def test_collect_small_round_trip(graded_run, tmp_path: Path) -> None:
    """One episode, state only: the dataset's actions, replayed, give its recorded states and outcome."""
    from typer.testing import CliRunner

    from song.cli import app
    from song.runtime.avatars import make_collider
    from song.runtime.loop import EpisodeRunner

    release = export_bench(_scene_1_for_training(graded_run()), tmp_path / "bench", "1.0.0").path
    out = tmp_path / "dataset"
    args = ["collect", "--bench", str(release), "--out", str(out), "--limit", "1", "--keep", "all", "-j", "1"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    info = json.loads((out / "meta" / "info.json").read_text())
    (e,) = pq.read_table(out / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pylist()
    data = pq.read_table(out / info["data_path"].format(chunk_index=0, file_index=0))
    assert data.num_rows == e["length"] == info["total_frames"]
    episode = bench.open(release).episode(e["song_episode_id"])
    runner = EpisodeRunner(episode, make_collider(episode))
    for state, action in zip(
        data.column("observation.state").to_pylist(), data.column("action").to_pylist(), strict=True
    ):
        np.testing.assert_allclose([runner.pose.x, runner.pose.y], state[:2], atol=1e-5)
        runner.step(*action)
    assert runner.outcome == e["outcome"]


@pytest.mark.slow
def test_collect_writes_a_lerobot_dataset_from_the_training_split(graded_run, tmp_path: Path) -> None:
    """Round trip: the dataset's actions, replayed, give its recorded states and outcomes; frames match
    steps; the same options give the same bytes with one or two workers; --keep success filters."""
    import av
    from typer.testing import CliRunner

    from song.cli import app
    from song.runtime.avatars import make_collider
    from song.runtime.loop import EpisodeRunner

    run = _scene_1_for_training(graded_run())
    release = export_bench(run, tmp_path / "bench", "1.0.0").path
    outs = []
    for name, workers in (("dataset_a", "1"), ("dataset_b", "2")):
        out = tmp_path / name
        args = ["collect", "--bench", str(release), "--out", str(out), "--policy", "social", "--limit", "3"]
        args += ["--sensors", "state,depth,rgb", "--resolution", "64x48", "--keep", "all", "--workers", workers]
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        outs.append(out)
    assert _files(outs[0]) == _files(outs[1])  # deterministic, whatever the worker count
    out = outs[0]
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["total_episodes"] == 3 and info["splits"] == {"train": "0:3"}
    features = info["features"]
    assert features["observation.state"]["shape"] == [10] and features["action"]["names"] == ["v", "omega"]
    assert features["observation.images.rgb"]["dtype"] == "video" and features["observation.depth"]["shape"] == [48, 64]
    episodes = pq.read_table(out / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pylist()
    data = pq.read_table(out / info["data_path"].format(chunk_index=0, file_index=0))
    bench_release = bench.open(release)
    frames = 0
    for e in episodes:
        rows = data.slice(e["dataset_from_index"], e["length"])
        assert rows.column("next.done").to_pylist()[-1] is True
        assert rows.column("index").to_pylist()[0] == frames  # the global frame index runs across episodes
        rewards = np.array(rows.column("next.reward").to_pylist())
        parts = np.array(rows.column("reward.progress").to_pylist()) + np.array(
            rows.column("reward.terminal").to_pylist()
        )
        np.testing.assert_allclose(rewards, parts, atol=1e-6)
        episode = bench_release.episode(e["song_episode_id"])
        runner = EpisodeRunner(episode, make_collider(episode))
        states = np.array(rows.column("observation.state").to_pylist())
        for state, action in zip(states, rows.column("action").to_pylist(), strict=True):
            np.testing.assert_allclose([runner.pose.x, runner.pose.y], state[:2], atol=1e-5)
            runner.step(*action)
        assert runner.outcome == e["outcome"]
        frames += e["length"]
    video = out / info["video_path"].format(video_key="observation.images.rgb", chunk_index=0, file_index=0)
    with av.open(str(video)) as container:
        assert sum(1 for _ in container.decode(video=0)) == frames  # the episodes share one video
    assert info["total_frames"] == frames
    success = tmp_path / "dataset_success"
    result = CliRunner().invoke(app, ["collect", "--bench", str(release), "--out", str(success), "--limit", "3"])
    assert result.exit_code == 0, result.output
    kept = pq.read_table(success / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pylist()
    assert [k["song_episode_id"] for k in kept] == [e["song_episode_id"] for e in episodes if e["outcome"] == "success"]
    again = CliRunner().invoke(app, ["collect", "--bench", str(release), "--out", str(out)])
    assert again.exit_code != 0 and "not empty" in again.output


def test_habitat_export_refuses_an_episode_it_cannot_write(graded_run, tmp_path: Path) -> None:
    from song.datasets.bench.habitat import _write_habitat
    from song.errors import BenchmarkError

    release = bench.open(export_bench(graded_run(), tmp_path / "bench", "1.0.0").path)
    rows = release.episodes_table.to_pylist()
    rows[0]["geodesic_distance"] = float("nan")
    with pytest.raises(BenchmarkError, match=rf"episode '{rows[0]['episode_id']}': geodesic_distance is not finite"):
        _write_habitat(release, rows, tmp_path / "hab.json.gz")
    assert not (tmp_path / "hab.json.gz").exists()
