"""Hostile and careless inputs (docs/security.md): one test per threat, inputs built here, no network.

(The LLM key tests — a redirect carrying credentials, an echoed key — are in
tests/pipeline/intents/test_llm.py, next to the fake servers.)
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import textwrap
import time
import zlib
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from song.cli import app
from song.datasets.bench import open_benchmark
from song.datasets.bench.export import export_bench
from song.datasets.bench.release import verify_release
from song.datasets.bench.schema import SCENES_PATH
from song.errors import BenchmarkError, SongError, StageError
from song.util import check_id
from tests.datasets.bench.conftest import build_graded_run

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "artifacts" / "bench_golden" / "1.0.0"


@pytest.fixture(autouse=True)
def _confined(nothing_written_outside) -> None:
    """Every case here must leave everything outside its own tmp_path as it was."""


# 1. a release always matches what was synthesised ------------------------------------------------


def test_export_refuses_a_scene_changed_after_synthesis(tmp_path: Path) -> None:
    run = build_graded_run(tmp_path / "a")
    occupancy = tmp_path / "a" / "scenes" / "scene_1" / "occupancy.png"
    import cv2

    cells = cv2.imread(str(occupancy), cv2.IMREAD_UNCHANGED)
    cells[:, cells.shape[1] // 3] = 0  # a wall drawn across the map after synth and grade
    cv2.imwrite(str(occupancy), cells)
    with pytest.raises(StageError, match=r"scene_1/occupancy.png: changed since the 'crowd' stage") as info:
        export_bench(run, tmp_path / "bench", "1.0.0")
    assert "\n" not in str(info.value)
    assert not (tmp_path / "bench" / "1.0.0").exists() and not list((tmp_path / "bench").glob(".*"))


def test_verify_catches_an_edited_info_json(tmp_path: Path) -> None:
    copy = tmp_path / "1.0.0"
    shutil.copytree(GOLDEN, copy)
    assert verify_release(copy).ok
    info = json.loads((copy / "meta" / "info.json").read_text())
    info["robot"]["max_speed_mps"] = 5.0
    (copy / "meta" / "info.json").write_text(json.dumps(info))
    report = verify_release(copy)
    assert not report.ok and not report.fingerprint_ok


# 2. a hostile release never reads outside itself -------------------------------------------------


def _with_scene_ref(tmp_path: Path, column: str, path: str) -> Path:
    copy = tmp_path / "1.0.0"
    shutil.copytree(GOLDEN, copy)
    table = pq.read_table(copy / SCENES_PATH)
    rows = table.to_pylist()
    rows[0][column] = {**rows[0][column], "path": path}
    import pyarrow as pa

    pq.write_table(pa.Table.from_pylist(rows, table.schema), copy / SCENES_PATH)
    return copy


@pytest.mark.parametrize("path", ["/etc/passwd", "../../../../etc/passwd", "blobs/sha256/00/../../../../etc/passwd"])
def test_blob_paths_that_leave_the_release_are_refused(tmp_path: Path, path: str) -> None:
    release = open_benchmark(_with_scene_ref(tmp_path, "occupancy", path))
    with pytest.raises(BenchmarkError) as info:
        release.episode(release.episode_ids()[0])
    assert "is not the content address" in str(info.value) and "\n" not in str(info.value)


def test_a_symlinked_or_altered_blob_is_refused(tmp_path: Path) -> None:
    copy = tmp_path / "1.0.0"
    shutil.copytree(GOLDEN, copy)
    row = pq.read_table(copy / SCENES_PATH).to_pylist()[0]
    blob = copy / row["occupancy"]["path"]
    blob.unlink()
    blob.symlink_to("/etc/passwd")
    release = open_benchmark(copy)
    with pytest.raises(BenchmarkError, match="resolves outside the release"):
        release.episode(release.episode_ids()[0])
    report = verify_release(copy)
    assert not report.ok and any("outside the release" in item for item in report.altered)
    blob.unlink()
    shutil.copy(GOLDEN / row["occupancy"]["path"], blob)
    with blob.open("r+b") as handle:  # same size, one byte different
        handle.seek(40)
        byte = handle.read(1)
        handle.seek(40)
        handle.write(bytes([byte[0] ^ 0xFF]))
    release = open_benchmark(copy)
    with pytest.raises(BenchmarkError, match="missing or altered blob"):
        release.episode(release.episode_ids()[0])


# 3. a user policy cannot forge its score; a failing one fails only its episodes --------------------


class GoalForger:
    """Moves the goal onto the start, then stands still."""

    sensors = ("state",)

    def reset(self, episode) -> None:
        episode.goal_xy[:] = episode.start_xy

    def act(self, observation) -> tuple[float, float]:
        return 0.0, 0.0


class Flaky:
    """Fails differently per episode; succeeds at driving straight otherwise."""

    sensors = ("state",)

    def reset(self, episode) -> None:
        self.id = episode.episode_id

    def act(self, observation):
        if self.id == "scene_0-000":
            raise RuntimeError("boom")
        if self.id == "scene_0-001":
            time.sleep(5.0)
        if self.id == "scene_1-000":
            sys.exit(3)
        if self.id == "scene_1-001":
            return "fast"
        return 0.3, 0.0


def test_a_goal_forging_policy_scores_zero(tmp_path: Path) -> None:
    out = tmp_path / "ev"
    result = CliRunner().invoke(
        app, ["eval", "--bench", str(GOLDEN.parent), "--policy", "tests.test_security:GoalForger", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    rows = pq.read_table(out / "tests.test_security_GoalForger.parquet").to_pylist()
    assert rows and all(r["outcome"] == "error" and "read-only" in r["error"] for r in rows)
    summary = json.loads((out / "tests.test_security_GoalForger.json").read_text())
    assert summary["metrics"]["all"]["SR"] == 0.0


def test_a_failing_policy_fails_only_its_episodes(tmp_path: Path) -> None:
    out = tmp_path / "ev"
    args = ["eval", "--bench", str(GOLDEN.parent), "--policy", "tests.test_security:Flaky", "--step-timeout", "0.5"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    rows = {r["episode_id"]: r for r in pq.read_table(out / "tests.test_security_Flaky.parquet").to_pylist()}
    assert len(rows) == 6
    assert "raised RuntimeError: boom" in rows["scene_0-000"]["error"]
    assert "ran past the 0.5 s limit" in rows["scene_0-001"]["error"]
    assert "sys.exit(3)" in rows["scene_1-000"]["error"]
    assert "'fast'" in rows["scene_1-001"]["error"]
    for eid in ("scene_0-002", "scene_1-002"):
        assert rows[eid]["outcome"] != "error" and rows[eid]["error"] == ""
    assert "ERR" in (out / "tests.test_security_Flaky.md").read_text()


# 5. ids that become paths ------------------------------------------------------------------------


@pytest.mark.parametrize("bad", ["../../escape", "a/b", "scene\n", ".hidden", "", "x" * 129, "a..b", "C:\\x"])
def test_path_escaping_ids_are_refused(bad: str) -> None:
    with pytest.raises(SongError, match="must be 1-128"):
        check_id(bad, "id")


def test_avatar_import_cannot_write_outside_out(tmp_path: Path) -> None:
    from tests.conftest import synthetic_ply

    ply = synthetic_ply(tmp_path / "person.ply", 2000)
    out = tmp_path / "pool" / "inner"
    result = CliRunner().invoke(app, ["avatars", "import", str(ply), "--out", str(out), "--id", "../../escape_av"])
    assert result.exit_code != 0 and "must be 1-128" in " ".join(result.output.split())
    assert not list(tmp_path.rglob("escape_av*"))


# 6. resource bombs: refused within 2 s and 200 MB ---------------------------------------------------


def _png_header(width: int, height: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 4096)) + chunk(b"IEND", b"")
    )


def _bomb(kind: str, root: Path) -> str:
    """Build a hostile file; return the Python statement that reads it."""
    if kind in ("png_30k", "png_60k"):
        size = 30_000 if kind == "png_30k" else 60_000
        (root / "occupancy.png").write_bytes(_png_header(size, size))
        return f"read_occupancy_png({str(root / 'occupancy.png')!r}, 0.05, (0.0, 0.0))"
    if kind == "ply_vertices":
        header = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\nend_header\n"
        (root / "bomb.ply").write_bytes(header + b"\0" * 1024)
        return f"read_gaussian_ply({str(root / 'bomb.ply')!r})"
    if kind == "ply_list":
        header = b"ply\nformat binary_little_endian 1.0\nelement face 1000000000\nproperty list uchar int vertex_indices\nend_header\n"
        (root / "bomb.ply").write_bytes(header + b"\x03" + b"\0" * 12 * 1000)
        return f"check_gaussian_ply({str(root / 'bomb.ply')!r})"
    if kind == "json_nested":
        (root / "semantic_map.json").write_text("[" * 200_000 + "]" * 200_000)
        return f"parse_semantic_map(Path({str(root / 'semantic_map.json')!r}))"
    raise ValueError(kind)


BOMB_RUNNER = textwrap.dedent(
    """
    import json, resource, sys, time
    from pathlib import Path
    from song.datasets.scenes.occupancy import read_occupancy_png
    from song.datasets.scenes.package import parse_semantic_map
    from song.datasets.scenes.ply import check_gaussian_ply, read_gaussian_ply
    from song.errors import SongError
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    try:
        {statement}
        error = ""
    except SongError as exc:
        error = str(exc)
    seconds = time.perf_counter() - start
    grew = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    print(json.dumps({{"seconds": seconds, "grew_mb": grew, "error": error}}))
    """
)


@pytest.mark.parametrize("kind", ["png_30k", "png_60k", "ply_vertices", "ply_list", "json_nested"])
def test_resource_bombs_are_refused_fast_and_small(tmp_path: Path, kind: str) -> None:
    statement = _bomb(kind, tmp_path)
    proc = subprocess.run(
        [sys.executable, "-c", BOMB_RUNNER.format(statement=statement)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["error"] and "\n" not in result["error"], result
    assert result["seconds"] < 2.0 and result["grew_mb"] < 200, result


def test_limits_are_named_and_configurable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from song.datasets.scenes.occupancy import read_occupancy_png

    (tmp_path / "occupancy.png").write_bytes(_png_header(30_000, 30_000))
    with pytest.raises(SongError, match="max_image_pixels=100,000,000 .raise it with SONG_MAX_IMAGE_PIXELS"):
        read_occupancy_png(tmp_path / "occupancy.png", 0.05, (0.0, 0.0))
    monkeypatch.setenv("SONG_MAX_IMAGE_PIXELS", "10")
    import cv2

    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((4, 4), np.uint8))
    with pytest.raises(SongError, match="4 × 4 = 16 exceeds the limit max_image_pixels=10"):
        read_occupancy_png(tmp_path / "small.png", 0.05, (0.0, 0.0))


# 7. no orphans -----------------------------------------------------------------------------------

ORPHAN_PARENT = textwrap.dedent(
    """
    import os, sys, time
    from song.parallel import parallel_map

    def job(k):
        with open(os.path.join(sys.argv[1], f"worker-{os.getpid()}"), "w"):
            pass
        time.sleep(60)
        return k

    if __name__ == "__main__":
        list(parallel_map(job, list(range(4)), 2))
    """
)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is gone for our purposes
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def test_workers_exit_when_the_parent_is_killed(tmp_path: Path) -> None:
    script = tmp_path / "parent.py"
    script.write_text(ORPHAN_PARENT)
    parent = subprocess.Popen([sys.executable, str(script), str(tmp_path)], cwd=ROOT)
    try:
        deadline = time.time() + 60
        while len(list(tmp_path.glob("worker-*"))) < 2 and time.time() < deadline:
            time.sleep(0.1)
        workers = [int(p.name.split("-")[1]) for p in tmp_path.glob("worker-*")]
        assert len(workers) == 2
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        killed = time.time()
        while any(_alive(pid) for pid in workers) and time.time() - killed < 10:
            time.sleep(0.1)
        assert not any(_alive(pid) for pid in workers), "orphaned workers still running"
        assert time.time() - killed <= 5.0
    finally:
        for path in tmp_path.glob("worker-*"):
            pid = int(path.name.split("-")[1])
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
