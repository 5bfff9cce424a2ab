"""One rule each: strict results JSON, a malformed action ends the episode as ``error`` everywhere, one
writer per run folder."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from song.cli import app
from song.errors import SongError
from song.util import finite_json, folder_lock, write_json_atomic

GOLDEN = Path(__file__).resolve().parent / "artifacts" / "bench_golden"


@pytest.fixture(autouse=True)
def _confined(nothing_written_outside) -> None:
    """Every case here must leave everything outside its own tmp_path as it was."""


def _fail(name: str) -> None:
    raise AssertionError(f"non-standard JSON constant {name}")


def test_non_finite_numbers_become_null_and_strings_stay(tmp_path: Path) -> None:
    data = {"path": "/home/NaNa/-Infinity", "nan": float("nan"), "inf": [np.float32("inf"), 1.5], "n": np.int64(3)}
    write_json_atomic(tmp_path / "a.json", data)
    back = json.loads((tmp_path / "a.json").read_text(), parse_constant=_fail)
    assert back == {"path": "/home/NaNa/-Infinity", "nan": None, "inf": [None, 1.5], "n": 3}
    assert finite_json("NaN") == "NaN"


def test_results_json_of_a_policy_named_nans_in_a_folder_named_nan(tmp_path: Path) -> None:
    """A policy whose every command makes a NaN-free but odd run; the names must round-trip unchanged."""
    folder = tmp_path / "NaN-Infinity"
    shutil.copytree(GOLDEN, folder / "bench")
    module = folder / "evil.py"
    module.write_text(
        textwrap.dedent(
            """
            class NaNs:
                sensors = ("state",)

                def reset(self, episode):
                    pass

                def act(self, observation):
                    return (0.0, 0.0)  # stands still: every metric that divides by progress is not finite
            """
        )
    )
    out = folder / "out"
    result = CliRunner().invoke(
        app, ["eval", "--bench", str(folder / "bench"), "--policy", f"{module}:NaNs", "--out", str(out), "--limit", "2"]
    )
    assert result.exit_code == 0, result.output
    (written,) = out.glob("*.json")
    summary = json.loads(written.read_text(), parse_constant=_fail)
    assert summary["policy"] == f"{module}:NaNs" and summary["benchmark"].startswith(str(folder))


def test_a_nan_action_ends_the_env_episode_as_error_like_song_eval() -> None:
    pytest.importorskip("gymnasium")
    from song.runtime.env import SongNavEnv

    env = SongNavEnv(str(GOLDEN))
    env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(np.array([np.nan, 0.0], dtype=np.float32))
    assert terminated and not truncated and reward == 0.0
    assert info["outcome"] == "error" and "two finite numbers" in info["error"]


def _hold(lock: Path) -> subprocess.Popen:
    """Another process holding ``lock`` (flock), as a second writer would; returns once it holds it."""
    holder = subprocess.Popen(
        [sys.executable, "-c", f"import fcntl, time; f = open({str(lock)!r}, 'a+b'); "
         "fcntl.flock(f.fileno(), fcntl.LOCK_EX); print('held', flush=True); time.sleep(30)"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert holder.stdout.readline().strip() == "held"
    return holder


def test_one_writer_per_run_folder(tmp_path: Path) -> None:
    lock = tmp_path / "run" / ".song.lock"
    lock.parent.mkdir(parents=True)
    holder = _hold(lock)
    try:
        with pytest.raises(SongError, match="another song process is writing this run folder"):
            with folder_lock(lock, "run folder"):
                pass
    finally:
        holder.kill()
        holder.wait()
    with folder_lock(lock, "run folder"):  # the holder is gone: its lock went with it
        pass


def test_reset_hands_a_policy_only_what_its_sensors_entitle_it_to(tmp_path: Path) -> None:
    """The future is not in reset: no tracks, no avatars, no factors; the map only with the map sensor."""
    seen: dict[str, dict] = {}
    module = tmp_path / "peek.py"
    module.write_text(
        textwrap.dedent(
            """
            import json, os


            class Peek:
                sensors = SENSORS

                def reset(self, episode):
                    with open(os.environ["PEEK_OUT"], "w") as f:
                        json.dump({"pedestrians": len(episode.pedestrians), "avatars": len(episode.avatars),
                                   "factors": len(episode.factors), "map": list(episode.static_map.cells.shape),
                                   "path": len(episode.path), "goal": list(episode.goal_xy)}, f)

                def act(self, observation):
                    return (0.0, 0.0)
            """
        )
    )
    for name, sensors in (("plain", ("state",)), ("mapped", ("state", "map"))):
        path = tmp_path / f"{name}.py"
        path.write_text(module.read_text().replace("SENSORS", repr(sensors)))
        out = tmp_path / f"{name}.json"
        import os

        os.environ["PEEK_OUT"] = str(out)
        try:
            result = CliRunner().invoke(
                app, ["eval", "--bench", str(GOLDEN), "--policy", f"{path}:Peek", "--limit", "1", "-j", "1",
                      "--out", str(tmp_path / f"eval_{name}")],
            )  # fmt: skip
        finally:
            del os.environ["PEEK_OUT"]
        assert result.exit_code == 0, result.output
        seen[name] = json.loads(out.read_text())
        summary = json.loads(next((tmp_path / f"eval_{name}").glob("*.json")).read_text())
        assert summary["privileged"] is False
    assert seen["plain"]["pedestrians"] == seen["plain"]["avatars"] == seen["plain"]["factors"] == 0
    assert seen["plain"]["map"] == [1, 1] and seen["plain"]["path"] == 0 and len(seen["plain"]["goal"]) == 2
    assert seen["mapped"]["pedestrians"] == 0 and seen["mapped"]["map"] != [1, 1] and seen["mapped"]["path"] >= 2


def test_results_say_when_a_privileged_sensor_was_used(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    result = CliRunner().invoke(
        app, ["eval", "--bench", str(GOLDEN), "--policy", "social", "--limit", "1", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert json.loads((out / "social.json").read_text())["privileged"] is True


def _tampered(tmp_path: Path, how: str) -> Path:
    """A copy of the golden release with its robot speed edited, or an episode's goal moved to its start."""
    import pyarrow.parquet as pq

    release = tmp_path / "bench"
    shutil.copytree(GOLDEN / "1.0.0" if (GOLDEN / "1.0.0").is_dir() else GOLDEN, release)
    if how == "speed":
        info = json.loads((release / "meta" / "info.json").read_text())
        info["robot"]["max_speed_mps"] = 5.0
        (release / "meta" / "info.json").write_text(json.dumps(info))
    else:
        path = next((release / "data" / "episodes").glob("*.parquet"))
        table = pq.read_table(path)
        goals = table.column("goal_position").to_pylist()
        goals[0] = table.column("start_position").to_pylist()[0]
        import pyarrow as pa

        index = table.schema.get_field_index("goal_position")
        table = table.set_column(index, table.schema.field(index), pa.array(goals, table.schema.field(index).type))
        pq.write_table(table, path)
    return release


@pytest.mark.parametrize("how", ["speed", "goal"])
def test_a_release_edited_after_export_is_refused_where_it_is_used(tmp_path: Path, how: str) -> None:
    release = _tampered(tmp_path, how)
    out = tmp_path / "eval"
    result = CliRunner().invoke(app, ["eval", "--bench", str(release), "--policy", "astar", "--out", str(out)])
    text = " ".join(result.output.split())
    assert result.exit_code != 0 and "--allow-modified" in text and "edited" in text, text
    assert not out.exists()
    collect = CliRunner().invoke(
        app, ["collect", "--bench", str(release), "--out", str(tmp_path / "ds"), "--split", "test", "--limit", "1"]
    )
    assert collect.exit_code != 0 and "edited" in " ".join(collect.output.split())
    pytest.importorskip("gymnasium")
    from song.errors import BenchmarkError
    from song.runtime.env import SongNavEnv

    with pytest.raises(BenchmarkError, match="edited"):
        SongNavEnv(str(release))
    result = CliRunner().invoke(
        app,
        ["eval", "--bench", str(release), "--policy", "astar", "--out", str(out), "--limit", "2", "--allow-modified"],
    )
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "astar.json").read_text())
    assert summary["official"] is False and "edited" in summary["release_check"]


def _reseal(release: Path) -> None:
    """Rewrite the manifest's hashes and the fingerprint after editing files (what a forger would do)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from song.datasets.bench.info import fingerprint_of
    from song.util import sha256_file

    manifest_path = release / "meta" / "manifest.parquet"
    manifest = pq.read_table(manifest_path)
    rows = manifest.to_pylist()
    for row in rows:
        row["sha256"] = sha256_file(release / row["path"])
        row["bytes"] = (release / row["path"]).stat().st_size
    pq.write_table(pa.Table.from_pylist(rows, manifest.schema), manifest_path)
    info = json.loads((release / "meta" / "info.json").read_text())
    info["fingerprint"] = fingerprint_of(rows, info)
    (release / "meta" / "info.json").write_text(json.dumps(info))


def test_ids_from_a_hostile_release_never_become_paths_outside_out(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    release = tmp_path / "deep" / "er" / "bench"
    shutil.copytree(GOLDEN / "1.0.0", release)
    path = next((release / "data" / "episodes").glob("*.parquet"))
    table = pq.read_table(path)
    ids = table.column("episode_id").to_pylist()
    hostile = "../../escape"
    index = table.schema.get_field_index("episode_id")
    table = table.set_column(index, table.schema.field(index), pa.array([hostile, *ids[1:]], pa.string()))
    pq.write_table(table, path)
    _reseal(release)  # a consistent hostile release: its manifest and fingerprint match the edit
    before = sorted(p for p in tmp_path.rglob("*"))
    out = tmp_path / "deep" / "er" / "figs"
    for command in (["viz", "episode", "--bench", str(release), "--episode", hostile, "--out", str(out)],
                    ["viz", "pov", "--bench", str(release), "--episode", hostile, "--policy", "straight",
                     "--resolution", "32x24", "--out", str(out)]):  # fmt: skip
        result = CliRunner().invoke(app, command)
        text = " ".join(result.output.split())
        assert result.exit_code != 0 and "episode id '../../escape'" in text, text
    after = sorted(p for p in tmp_path.rglob("*") if not p.is_relative_to(out))
    assert after == before  # nothing written anywhere but --out (and nothing there either)


def test_a_second_writer_is_refused_and_a_foreign_folder_is_never_a_run(tmp_path: Path) -> None:
    from song.runtime.collect import LOCK_FILE, collect

    out = tmp_path / "dataset"
    out.mkdir()
    lock = out / LOCK_FILE
    holder = _hold(lock)
    try:
        with pytest.raises(SongError, match="another song process is writing this dataset folder"):
            collect(str(GOLDEN), "straight", out, split="test", limit=1)
    finally:
        holder.kill()
        holder.wait()
    assert [p.name for p in out.iterdir()] == [LOCK_FILE]  # the first writer's folder is untouched
    foreign = tmp_path / "notes"
    foreign.mkdir()
    (foreign / "run.json").write_text('{"mine": true}')
    from tests.conftest import build_two_room_scene

    build_two_room_scene(tmp_path / "scenes", "a")
    result = CliRunner().invoke(app, ["synth", "--scenes", str(tmp_path / "scenes"), "--out", str(foreign)])
    assert result.exit_code != 0 and "not a run folder" in " ".join(result.output.split())
    assert (foreign / "run.json").read_text() == '{"mine": true}'
    (foreign / "run.json").unlink()
    (foreign / "todo.txt").write_text("mine")
    result = CliRunner().invoke(app, ["synth", "--scenes", str(tmp_path / "scenes"), "--out", str(foreign)])
    assert result.exit_code != 0 and "not a song run" in " ".join(result.output.split())
    assert sorted(p.name for p in foreign.iterdir()) == ["todo.txt"]


POLICIES = {
    "syntax": ("class P:\n    def reset(self, episode)\n", "my.py:2:", "expected"),
    "init": ("class P:\n    def __init__(self):\n        raise RuntimeError('no GPU')\n", "cannot create policy", "no GPU"),
    "sensors": ("class P:\n    sensors = 5\n    def reset(self, e): pass\n    def act(self, o): return (0, 0)\n",
                "sensors must be a tuple", ""),
    "array": ("class Bad:\n    def __array__(self, *a, **k):\n        raise RuntimeError('boom')\n"
              "class P:\n    def reset(self, e): pass\n    def act(self, o): return Bad()\n", "", ""),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(POLICIES))
def test_a_broken_policy_is_one_line_never_a_traceback(tmp_path: Path, case: str) -> None:
    source, said, detail = POLICIES[case]
    path = tmp_path / "my.py"
    path.write_text(source)
    out = tmp_path / "eval"
    result = CliRunner().invoke(
        app, ["eval", "--bench", str(GOLDEN), "--policy", f"{path}:P", "--limit", "1", "--out", str(out)]
    )
    text = " ".join(result.output.split())
    assert "Traceback" not in text and not isinstance(result.exception, (AttributeError, TypeError, RuntimeError))
    if case == "array":  # a malformed command fails its episode, the run goes on and says so
        assert result.exit_code == 0, text
        assert json.loads(next(out.glob("*.json")).read_text())["metrics"]["all"]["ERR"] == 100.0
    else:
        assert result.exit_code != 0 and said in text and detail in text, text


@pytest.mark.parametrize(("value", "said"), [("²x²", "expected WIDTHxHEIGHT"), ("99999999999999999999x1", "1-8192")])
def test_impossible_image_sizes_are_one_line(tmp_path: Path, value: str, said: str) -> None:
    result = CliRunner().invoke(app, ["eval", "--bench", str(GOLDEN), "--policy", "depth", "--resolution", value,
                                      "--out", str(tmp_path / "e")])  # fmt: skip
    assert result.exit_code != 0 and said in " ".join(result.output.split()), result.output
    assert isinstance(result.exception, SystemExit)  # a clean exit, not an error escaping


def test_an_infinite_step_timeout_means_no_limit(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    result = CliRunner().invoke(app, ["eval", "--bench", str(GOLDEN), "--policy", "astar", "--limit", "2",
                                      "--step-timeout", "inf", "--out", str(out)])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert json.loads((out / "astar.json").read_text())["metrics"]["all"]["ERR"] == 0.0


@pytest.mark.parametrize("how", ["missing", "mistyped"])
def test_a_release_table_with_a_missing_or_mistyped_column_is_one_line(tmp_path: Path, how: str) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    release = tmp_path / "bench"
    shutil.copytree(GOLDEN / "1.0.0", release)
    path = next((release / "data" / "episodes").glob("*.parquet"))
    table = pq.read_table(path)
    index = table.schema.get_field_index("goal_radius")
    if how == "missing":
        table = table.remove_column(index)
    else:
        table = table.set_column(
            index, "goal_radius", pa.array([str(v) for v in table.column("goal_radius").to_pylist()])
        )
    pq.write_table(table, path)
    _reseal(release)  # consistent with its fingerprint: only the column is wrong
    result = CliRunner().invoke(
        app, ["eval", "--bench", str(release), "--policy", "astar", "--out", str(tmp_path / "e")]
    )
    text = " ".join(result.output.split())
    assert result.exit_code != 0 and "column 'goal_radius'" in text and "part-00000.parquet" in text, text
    assert isinstance(result.exception, SystemExit)


SNOOP = """
import gc


class Snoop:
    sensors = ("state",)

    def reset(self, episode):
        pass

    def act(self, observation):
        # an in-process policy can find the runner's own episode, pedestrians' futures and all
        seen = any(getattr(o, "pedestrians", None) for o in gc.get_objects() if type(o).__name__ == "Episode")
        return (float("nan"), 0.0) if seen else (0.3, 0.0)


class Stuck:
    def reset(self, episode):
        pass

    def act(self, observation):
        return (sum(range(10**13)), 0.0)  # a loop inside C: no signal handler runs until it ends
"""


def test_an_isolated_policy_cannot_reach_the_runner_and_is_stopped_when_stuck(tmp_path: Path) -> None:
    import time

    path = tmp_path / "hostile.py"
    path.write_text(SNOOP)
    runs = {}
    for mode in ("in-process", "isolated"):
        out = tmp_path / mode
        args = ["eval", "--bench", str(GOLDEN), "--policy", f"{path}:Snoop", "--limit", "2", "--out", str(out)]
        result = CliRunner().invoke(app, args + (["--isolate"] if mode == "isolated" else []))
        assert result.exit_code == 0, result.output
        runs[mode] = json.loads(next(out.glob("*.json")).read_text())
    assert runs["in-process"]["metrics"]["all"]["ERR"] == 100.0  # it found the pedestrians in memory
    assert runs["isolated"]["metrics"]["all"]["ERR"] == 0.0 and runs["isolated"]["policy_process"] == "isolated"
    started = time.perf_counter()
    out = tmp_path / "stuck"
    result = CliRunner().invoke(app, ["eval", "--bench", str(GOLDEN), "--policy", f"{path}:Stuck", "--limit", "2",
                                      "--isolate", "--step-timeout", "0.5", "--out", str(out)])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert time.perf_counter() - started < 30.0
    assert json.loads(next(out.glob("*.json")).read_text())["metrics"]["all"]["ERR"] == 100.0


def test_a_killed_collect_leaves_no_truncated_dataset_and_the_next_one_completes(tmp_path: Path) -> None:
    from song.runtime.collect import PARTIAL_DIR, collect

    out = tmp_path / "dataset"
    leftover = out / PARTIAL_DIR / "data" / "chunk-000"
    leftover.mkdir(parents=True)
    (leftover / "episode_000000.parquet").write_bytes(b"PAR1 truncated")  # what a kill mid-write leaves
    summary = collect(str(GOLDEN), "straight", out, split="test", limit=2, keep="all")
    assert summary.episodes == 2 and not (out / PARTIAL_DIR).exists()
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["data", "meta"]
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["total_episodes"] == 2


def test_a_ply_with_nan_colours_is_refused_in_one_line(tmp_path: Path) -> None:
    from song.datasets.scenes.ply import GaussianCloud, read_gaussian_ply, write_standard_ply
    from song.errors import FormatError

    n = 100
    cloud = GaussianCloud(
        means=np.zeros((n, 3), np.float32), quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
        log_scales=np.full((n, 3), -3, np.float32), opacity_logits=np.zeros(n, np.float32),
        sh_dc=np.zeros((n, 3), np.float32),
    )  # fmt: skip
    cloud.sh_dc[:95, 1] = np.nan
    write_standard_ply(tmp_path / "nan.ply", cloud)
    with pytest.raises(FormatError, match=r"nan.ply: vertex colour \(f_dc\): 95 of 100 splats hold NaN or inf"):
        read_gaussian_ply(tmp_path / "nan.ply")


def test_a_small_table_declaring_a_huge_decoded_size_is_refused_before_reading(tmp_path: Path, monkeypatch) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from song.datasets.bench import open_benchmark
    from song.errors import SongError

    release = tmp_path / "bench"
    shutil.copytree(GOLDEN / "1.0.0", release)
    path = next((release / "data" / "episodes").glob("*.parquet"))
    table = pq.read_table(path)
    index = table.schema.get_field_index("config_sha256")
    bomb = ["x" * (64 * 2**20)] + table.column("config_sha256").to_pylist()[1:]  # 64 MiB of one letter
    pq.write_table(table.set_column(index, "config_sha256", pa.array(bomb)), path, compression="zstd")
    assert path.stat().st_size < 2**20  # the file itself is small
    monkeypatch.setenv("SONG_MAX_ARRAY_BYTES", str(32 * 2**20))
    with pytest.raises(SongError, match="decoded size .* exceeds the limit max_array_bytes"):
        open_benchmark(release)


def _forged_npz(path: Path, name: str, shape: tuple[int, ...], dtype: str = "<f8", payload: bytes = b"\0" * 64) -> Path:
    import io
    import zipfile

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": dtype, "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(f"{name}.npy", header.getvalue() + payload)
    return path


def test_npz_with_a_forged_header_is_refused_before_numpy_allocates(tmp_path):
    from song.datasets.limits import read_npz

    bomb = _forged_npz(tmp_path / "motion.npz", "local_quats", (10**7, 10**5))  # 8 TB declared, 64 B present
    with pytest.raises(SongError, match=r"motion\.npz.*local_quats.*header declares 8,000,000,000,000 bytes"):
        read_npz(bomb)
    with pytest.raises(SongError, match="object arrays are not accepted"):
        read_npz(_forged_npz(tmp_path / "obj.npz", "x", (1,), dtype="|O"))
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(SongError, match=r"junk\.npz.*not a readable npz"):
        read_npz(tmp_path / "junk.npz")
    good = tmp_path / "good.npz"
    np.savez_compressed(good, a=np.arange(6.0).reshape(2, 3), b=np.array([1, 2], np.int32))
    arrays = read_npz(good)
    assert arrays["a"].shape == (2, 3) and arrays["b"].dtype == np.int32


def test_npz_member_over_max_array_bytes_is_refused(tmp_path, monkeypatch):
    from song.datasets.limits import read_npz

    path = tmp_path / "big.npz"
    np.savez_compressed(path, poses=np.zeros((1024, 156)))  # 1.2 MiB decoded, a few KiB on disk
    monkeypatch.setenv("SONG_MAX_ARRAY_BYTES", str(2**20))
    with pytest.raises(SongError, match=r"big\.npz.*poses.*uncompressed size .* exceeds the limit max_array_bytes"):
        read_npz(path)


def test_motion_and_navmesh_readers_refuse_a_forged_npz(tmp_path):
    from song.pipeline.crowd.navmesh import load_navmesh
    from song.pipeline.motion.io import load_motion

    traj = tmp_path / "traj"
    traj.mkdir()
    _forged_npz(traj / "motion.npz", "t", (2**40,))
    with pytest.raises(SongError, match=r"motion\.npz.*t.*header declares"):
        load_motion(traj)
    _forged_npz(tmp_path / "navmesh.npz", "verts", (2**30, 3))
    with pytest.raises(SongError, match=r"navmesh\.npz.*verts.*header declares"):
        load_navmesh(tmp_path / "navmesh.npz")
