"""Shared fixtures: a factory for tiny valid scene packages (two rooms joined by a door)."""

from __future__ import annotations

import functools
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from song.datasets.scenes import Region, SceneObject, SemanticMap, write_scene_package
from song.datasets.scenes.model import OccupancySpec

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SHARED_HOUSES = SHARED / "sample_scenes" / "procthor_houses"  # three real ProcTHOR houses (Apache-2.0)
GUITAR = SHARED / "sample_scenes" / "playcanvas_splat" / "guitar.compressed.ply"  # a real SuperSplat file
BIKER = SHARED / "sample_scenes" / "playcanvas_splat" / "biker.compressed.ply"


def shared_file(path: Path) -> Path:
    """``path`` under ../shared, or skip the test with the reason (a user's clone has no ../shared)."""
    if not path.exists():
        pytest.skip(f"{path} is absent: third-party fixtures live in ../shared beside the checkout")
    return path


@functools.lru_cache(maxsize=1)
def splat_file() -> Path:
    """A 90 k-splat compressed PLY (made once per session) for tests that damage a real-sized file."""
    return synthetic_ply(Path(tempfile.mkdtemp(prefix="song-splat-")) / "splat.compressed.ply", 90_854)


def synthetic_ply(path: Path, n: int = 5000, seed: int = 0) -> Path:
    """A SuperSplat compressed PLY of ``n`` random splats written by our own writer."""
    from song.datasets.scenes.ply import GaussianCloud, write_compressed_ply

    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    cloud = GaussianCloud(
        means=rng.uniform(-1, 1, (n, 3)).astype(np.float32),
        quats=(q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32),
        log_scales=rng.uniform(-5, -2, (n, 3)).astype(np.float32),
        opacity_logits=rng.normal(0, 2, n).astype(np.float32),
        sh_dc=rng.normal(0, 1, (n, 3)).astype(np.float32),
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    write_compressed_ply(path, cloud)
    return path


def build_two_room_scene(root: Path, scene_id: str = "tiny", resolution: float = 0.05, door: float = 1.0) -> Path:
    """An 8 m × 4 m scene: two 4 m rooms, a ``door`` m wide door (centred at y = 2 m) in the dividing wall, a few objects.

    Walls are 0.1 m thick around the border and between the rooms (x = 4 m).
    """
    width, height = 8.0, 4.0
    cols, rows = round(width / resolution), round(height / resolution)
    cells = np.full((rows, cols), 255, dtype=np.uint8)
    wall = max(1, round(0.1 / resolution))
    cells[:wall, :] = cells[-wall:, :] = 0
    cells[:, :wall] = cells[:, -wall:] = 0
    mid = cols // 2
    cells[:, mid - wall // 2 - 1 : mid + wall // 2 + 1] = 0
    door_lo, door_hi = round((2.0 - door / 2) / resolution), round((2.0 + door / 2) / resolution)
    cells[rows - door_hi : rows - door_lo, mid - wall // 2 - 1 : mid + wall // 2 + 1] = 255
    # a desk in room A and a sofa in room B, rasterised as occupied
    desk = [(1.0, 0.5), (2.0, 0.5), (2.0, 1.0), (1.0, 1.0)]
    sofa = [(6.0, 3.0), (7.2, 3.0), (7.2, 3.5), (6.0, 3.5)]
    for (x0, y0), _, (x1, y1), _ in (desk, sofa):
        c0, c1 = round(x0 / resolution), round(x1 / resolution)
        r0, r1 = rows - round(y1 / resolution), rows - round(y0 / resolution)
        cells[r0:r1, c0:c1] = 0
    smap = SemanticMap(
        scene_id=scene_id,
        venue_type="office",
        source="procedural",
        bounds=(0.0, 0.0, width, height),
        occupancy=OccupancySpec(resolution=resolution, origin=(0.0, 0.0)),
        regions=[
            Region(id="room_a", type="open_office", polygon=[(0, 0), (4, 0), (4, 4), (0, 4)]),
            Region(id="room_b", type="lounge", polygon=[(4, 0), (8, 0), (8, 4), (4, 4)]),
        ],
        objects=[
            SceneObject(id="desk_1", label="desk", category="workstation", footprint=desk, z_max=0.75, region="room_a"),
            SceneObject(id="sofa_1", label="sofa", category="seating", footprint=sofa, z_max=0.8, region="room_b"),
            SceneObject(
                id="printer_1",
                label="printer",
                category="equipment",
                footprint=[(0.2, 3.2), (0.7, 3.2), (0.7, 3.7), (0.2, 3.7)],
                z_max=1.0,
                region="room_a",
            ),
        ],
    )
    return write_scene_package(root / scene_id, smap, cells)


@pytest.fixture(autouse=True, scope="session")
def _private_song_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Generated avatar pools go to a scratch cache, never to the user's ~/.cache (inherited by subprocesses)."""
    os.environ["SONG_CACHE_DIR"] = str(tmp_path_factory.mktemp("song_cache"))


@pytest.fixture
def make_scene(tmp_path: Path) -> Callable[..., Path]:
    """Factory: ``make_scene(scene_id="tiny", resolution=0.05, door=1.0) -> Path`` of a valid package."""

    def factory(scene_id: str = "tiny", resolution: float = 0.05, root: Path | None = None, door: float = 1.0) -> Path:
        return build_two_room_scene(root or tmp_path / "scenes", scene_id, resolution, door)

    return factory


SAMPLES = Path(__file__).resolve().parents[1] / "datasets" / "sample_scenes"


@pytest.fixture(scope="session")
def sample_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """intents + crowd on the three shipped ProcTHOR houses (one synth run shared by the session)."""
    from song.config import SongConfig
    from song.pipeline.chain import iter_run

    run = tmp_path_factory.mktemp("sample") / "run"
    results = list(iter_run(SAMPLES, run, SongConfig(seed=1), ["intents", "crowd"], executor="serial"))
    assert all(r.status == "ok" for r in results), [r.error for r in results]
    return run


def _outside_snapshot(tmp_path: Path) -> tuple:
    """What a hostile case must leave alone: the folders beside its own, the checkout's top level, the golden release."""
    root = Path(__file__).resolve().parents[1]
    golden = root / "tests" / "artifacts"
    return (
        sorted(p.name for p in tmp_path.parent.iterdir()),
        sorted(p.name for p in root.iterdir()),
        sorted((str(p.relative_to(golden)), p.stat().st_size, p.stat().st_mtime_ns) for p in golden.rglob("*")),
    )


@pytest.fixture
def nothing_written_outside(tmp_path: Path):
    """Fails the test when anything outside its ``tmp_path`` appeared, vanished or changed (see the snapshot)."""
    before = _outside_snapshot(tmp_path)
    yield
    assert _outside_snapshot(tmp_path) == before, "a hostile case wrote outside its output folder"
