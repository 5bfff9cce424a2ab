"""Projection of a release onto Habitat's PointNav episode format (``json.gz``).

Frame conversion (ours: right-handed, Z up; Habitat: right-handed, Y up, agent looks along −Z):
a point (x, y, z) becomes (x, z, −y). Our heading θ (CCW from +x about +z) becomes a rotation by
φ = θ − π/2 about Habitat's +Y, because Habitat's identity agent faces −Z, which is our +y (θ = π/2).
Rotations are written [x, y, z, w] as Habitat expects.

Layout of an export folder (``habitat.dataset.data_path`` = ``<out>/{split}/{split}.json.gz``,
``habitat.dataset.scenes_dir`` = ``<out>``)::

    <split>/<split>.json.gz           PointNav episodes (NavigationEpisode fields + info)
    scenes/<scene_id>.glb             the scene's collision proxy and floor, Y-up (trimesh; from the
                                      occupancy map, 2.5 m walls, when the scene has no proxy), with
                                      flat normals and a PBR material per mesh (the proxy's albedos)
    scenes/<scene_id>.3dgs.ply        the scene's Gaussians as the release has them (for Habitat-GS
                                      users; SONG's Z-up frame), when the scene has them
    scenes/<scene_id>.pedestrians.json.gz   the scene's pedestrian tracks, Habitat frame, 30 FPS
    stages/<scene_id>.stage_config.json     habitat-sim's stage attributes (the GLB as render and
                                      collision asset, Y up, -Z front, metres)
    song.scene_dataset_config.json    the scene dataset config that lists the stages

A ``.navmesh`` needs habitat-sim's Recast build, which is not a dependency here: load the dataset
config in habitat-sim and call ``sim.recompute_navmesh(sim.pathfinder, NavMeshSettings())`` (agent
radius and height as SONG's robot), then ``sim.pathfinder.save_nav_mesh(path)``.

Each episode's ``scene_id`` is ``scenes/<scene_id>.glb`` (joined to ``scenes_dir`` by Habitat);
``info`` carries SONG's grading fields, the robot's start time ``song_t0`` in the scenario and the
path of the pedestrians file. Habitat ignores ``info``: it loads the static scene only, so moving
people exist for a Habitat agent only if the user's code reads them from that file.
"""

from __future__ import annotations

import gzip
import io
import json
from pathlib import Path

import numpy as np

from song.datasets.bench.load import Benchmark
from song.datasets.bench.types import StaticMap
from song.datasets.scenes.usd import ProxyBox, ProxyMesh, box_mesh
from song.errors import BenchmarkError
from song.util import check_id, write_bytes_atomic

SCENES_DIR = "scenes"
STAGES_DIR = "stages"
WALL_HEIGHT_M = 2.5  # blocked cells become solids this tall for a scene without a USD proxy


def to_habitat_point(xyz: np.ndarray) -> np.ndarray:
    """(..., 3) Z-up points → Habitat Y-up points."""
    xyz = np.asarray(xyz, dtype=np.float64)
    return np.stack([xyz[..., 0], xyz[..., 2], -xyz[..., 1]], axis=-1)


def from_habitat_point(xyz: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_habitat_point`."""
    xyz = np.asarray(xyz, dtype=np.float64)
    return np.stack([xyz[..., 0], -xyz[..., 2], xyz[..., 1]], axis=-1)


def to_habitat_rotation(yaw: float) -> list[float]:
    """Our yaw (rad) → Habitat agent rotation quaternion [x, y, z, w] about +Y."""
    phi = yaw - np.pi / 2
    return [0.0, float(np.sin(phi / 2)), 0.0, float(np.cos(phi / 2))]


def export_habitat(bench: Benchmark, out: str | Path) -> Path:
    """Habitat PointNav episodes plus one GLB and one pedestrian file per scene; gzip mtime 0.

    ``out`` ending in ``.json.gz``: one file with every episode (the scenes go beside it, in
    ``scenes/``). Otherwise a folder laid out as Habitat's datasets are, one ``<split>/<split>.json.gz``
    per split of the release (``test`` only for releases before schema 1.3). Returns the file or the
    folder.

    Raises:
        MissingDependencyError: usd-core (the ``usd`` extra) is needed to read a scene's USD proxy.
    """
    out = Path(out)
    rows = bench.episodes_table.to_pylist()
    root = out.parent if out.name.endswith(".json.gz") else out
    scene_ids = sorted({check_id(row["scene_id"], "scene id") for row in rows})  # ids from the release name files
    for scene_id in scene_ids:
        write_scene_glb(bench, scene_id, root / SCENES_DIR / f"{scene_id}.glb")
        _write_gzip_json(root / SCENES_DIR / f"{scene_id}.pedestrians.json.gz", _pedestrians(bench, scene_id))
        gaussians = bench.blob(bench._scenes[scene_id].get("gaussians"))
        if gaussians is not None:
            write_bytes_atomic(root / SCENES_DIR / f"{scene_id}.3dgs.ply", Path(gaussians).read_bytes())
        stage = {
            "render_asset": f"../{SCENES_DIR}/{scene_id}.glb",
            "collision_asset": f"../{SCENES_DIR}/{scene_id}.glb",
            "up": [0.0, 1.0, 0.0],
            "front": [0.0, 0.0, -1.0],
            "units_to_meters": 1.0,
            "requires_lighting": True,
        }
        write_bytes_atomic(root / STAGES_DIR / f"{scene_id}.stage_config.json", json.dumps(stage, indent=1).encode())
    dataset = {"stages": {"paths": {".json": [f"{STAGES_DIR}/"]}}}
    write_bytes_atomic(root / "song.scene_dataset_config.json", json.dumps(dataset, indent=1).encode())
    if out.name.endswith(".json.gz"):
        return _write_habitat(bench, rows, out)
    for split in sorted(check_id(s, "split") for s in bench.splits()):
        chosen = [r for r in rows if (r.get("split") or "test") == split]
        _write_habitat(bench, chosen, out / split / f"{split}.json.gz")
    return out


def write_scene_glb(bench: Benchmark, scene_id: str, path: Path) -> Path:
    """The scene's static geometry as one Y-up binary glTF (trimesh).

    From the release's USD proxy (collision solids, floor and ceiling) when the scene has one; else
    from its occupancy map (:func:`occupancy_meshes`).
    """
    usd = bench.blob(bench._scenes[scene_id].get("usd"))
    if usd is not None:
        from song.datasets.scenes.usd import read_usd_proxy, read_usd_surfaces

        meshes = [*read_usd_proxy(usd), *read_usd_surfaces(usd)]
    else:
        meshes = occupancy_meshes(bench.static_map(scene_id))
    write_bytes_atomic(path, glb_bytes(meshes))
    return path


def glb_bytes(meshes: list[ProxyMesh]) -> bytes:
    """Z-up meshes as the bytes of one Y-up binary glTF, a node per mesh (its name kept).

    Each mesh gets flat normals (its vertices unshared per face) and a PBR material: the base albedo of
    its material (glTF's ``baseColorFactor`` is linear, so converted from sRGB), roughness 0.8, not
    metallic; a mesh without one is light grey.
    """
    import trimesh

    from song.datasets.scenes.materials import material_of, srgb_to_linear

    scene = trimesh.Scene()
    looks: dict[str, object] = {}
    for mesh in meshes:
        name = mesh.material or "grey"
        if name not in looks:
            base = np.array(material_of(mesh.material).base) if mesh.material else np.full(3, 0.8)
            linear = srgb_to_linear(base)
            looks[name] = trimesh.visual.material.PBRMaterial(
                name=name, baseColorFactor=[*linear.tolist(), 1.0], metallicFactor=0.0, roughnessFactor=0.8
            )
        faces = np.asarray(mesh.faces, dtype=np.int64)
        vertices = to_habitat_point(mesh.vertices)[faces.reshape(-1)]  # one vertex per corner: flat normals
        geometry = trimesh.Trimesh(vertices, np.arange(len(vertices)).reshape(-1, 3), process=False)
        geometry.visual = trimesh.visual.TextureVisuals(material=looks[name])
        scene.add_geometry(geometry, node_name=mesh.name, geom_name=mesh.name)
    return scene.export(file_type="glb", include_normals=True)


def occupancy_meshes(static_map: StaticMap, height: float = WALL_HEIGHT_M) -> list[ProxyMesh]:
    """Blocked cells (occupied or unknown) as boxes ``height`` tall, merged into rectangles, and a floor."""
    blocked = ~static_map.free
    rows, cols = blocked.shape
    res, (ox, oy) = static_map.resolution, static_map.origin
    rects, growing = [], {}  # growing: (c0, c1) column run → first row of the rectangle it extends
    for r in range(rows + 1):
        runs = set()
        if r < rows:
            edges = np.flatnonzero(np.diff(np.concatenate([[0], blocked[r].astype(np.int8), [0]])))
            runs = {(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)}
        for run in sorted(set(growing) - runs):
            rects.append((growing.pop(run), r, *run))
        for run in sorted(runs - set(growing)):
            growing[run] = r
    meshes = []
    for k, (r0, r1, c0, c1) in enumerate(sorted(rects)):
        x0, x1 = ox + c0 * res, ox + c1 * res
        y0, y1 = oy + (rows - r1) * res, oy + (rows - r0) * res
        footprint = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        meshes.append(box_mesh(k, ProxyBox(f"blocked_{k}", footprint, 0.0, height)))
    x1, y1 = ox + cols * res, oy + rows * res
    floor = np.array([[ox, oy, 0.0], [x1, oy, 0.0], [x1, y1, 0.0], [ox, y1, 0.0]])
    meshes.append(ProxyMesh("floor", floor, np.array([[0, 1, 2], [0, 2, 3]])))
    return meshes


def _pedestrians(bench: Benchmark, scene_id: str) -> dict:
    """The scene's pedestrian tracks in Habitat's frame (positions at hip height 0 on the floor)."""
    tracks = []
    for track in bench.pedestrians(scene_id):
        xyz = np.column_stack([track.xy, np.zeros(len(track.xy))])
        tracks.append(
            {
                "ped_id": track.ped_id,
                "t": np.round(track.t, 4).tolist(),
                "position": np.round(to_habitat_point(xyz), 4).tolist(),
                "rotation": [to_habitat_rotation(float(yaw)) for yaw in track.yaw],
            }
        )
    return {"scene_id": scene_id, "frame": "habitat (Y up)", "pedestrians": tracks}


def _write_gzip_json(path: Path, payload: object) -> None:
    data = json.dumps(payload, sort_keys=True, allow_nan=False).encode("utf-8")
    buffer = io.BytesIO()
    with gzip.GzipFile(fileobj=buffer, mode="wb", mtime=0, filename="") as handle:
        handle.write(data)
    write_bytes_atomic(path, buffer.getvalue())


def _check_finite(row: dict) -> None:
    """Refuse an episode whose numbers Habitat's JSON cannot hold (NaN, inf), naming it and the field."""
    for field in (
        "start_position",
        "goal_position",
        "start_yaw",
        "goal_radius",
        "geodesic_distance",
        "optimal_time",
        "t0",
    ):
        values = np.asarray(row.get(field), dtype=np.float64)
        if values.size == 0 or not np.isfinite(values).all():
            raise BenchmarkError(f"episode {row.get('episode_id')!r}: {field} is not finite ({row.get(field)!r})")


def _write_habitat(bench: Benchmark, rows: list[dict], out: Path) -> Path:
    episodes = []
    for row in rows:
        _check_finite(row)
        start = to_habitat_point(np.asarray(row["start_position"]))
        goal = to_habitat_point(np.asarray(row["goal_position"]))
        episodes.append(
            {
                "episode_id": row["episode_id"],
                "scene_id": f"{SCENES_DIR}/{row['scene_id']}.glb",
                "start_position": start.tolist(),
                "start_rotation": to_habitat_rotation(row["start_yaw"]),
                "goals": [{"position": goal.tolist(), "radius": row["goal_radius"]}],
                "info": {
                    "geodesic_distance": row["geodesic_distance"],
                    "difficulty": row["difficulty"],
                    "optimal_time": row["optimal_time"],
                    "song_version": bench.version,
                    "song_scene_id": row["scene_id"],
                    "song_t0": row["t0"],
                    "song_pedestrians": f"{SCENES_DIR}/{row['scene_id']}.pedestrians.json.gz",
                },
            }
        )
    _write_gzip_json(out, {"episodes": episodes})
    return out
