"""Synthesised Gaussian scenes: on the map's surfaces, agreeing with the USD proxy, without holes, deterministic."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from song.datasets.scenes import load_scene_package
from song.datasets.scenes.dressing import DressingHints, build_dressing
from song.datasets.scenes.generate import generate_scene
from song.datasets.scenes.package import GAUSSIANS, USD_PROXY
from song.datasets.scenes.ply import read_gaussian_ply
from song.datasets.scenes.splat import dress_package
from song.datasets.scenes.usd import read_usd_dressing, read_usd_proxy, read_usd_surfaces
from song.geometry.freespace import clearance_field
from song.render import render, robot_camera
from song.render.mesh_depth import mesh_depth
from song.runtime.vision import scene_gaussians
from tests.conftest import GUITAR, shared_file

CAMERA_HEIGHT_M, HFOV_DEG = 0.8, 70.0


@pytest.fixture(scope="module")
def office(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A procedural office at the default density, with its Gaussians and USD proxy."""
    return generate_scene("office_0000", "office", 3, tmp_path_factory.mktemp("splat"), splat=True)


def _normals(quats: np.ndarray) -> np.ndarray:
    """(N, 3) third column of each wxyz rotation: a surfel's normal."""
    w, x, y, z = quats.T
    return np.column_stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def _cells(grid, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) of points and whether they fall on the grid."""
    rc = grid.to_cell(xy)
    inside = (rc[:, 0] >= 0) & (rc[:, 0] < grid.shape[0]) & (rc[:, 1] >= 0) & (rc[:, 1] < grid.shape[1])
    return np.clip(rc, 0, np.array(grid.shape) - 1), inside


def test_gaussians_lie_on_the_map(office: Path) -> None:
    package = load_scene_package(office)
    grid = package.occupancy
    cloud = read_gaussian_ply(office / GAUSSIANS)
    assert 300_000 <= len(cloud) <= 1_000_000
    z, normal = cloud.means[:, 2], _normals(cloud.quats.astype(np.float64))
    floor = (np.abs(z) < 1e-3) & (normal[:, 2] > 0.99)
    ceiling = normal[:, 2] < -0.99
    dressing = build_dressing(
        package.semantic_map, grid, DressingHints.from_json(read_usd_dressing(office / USD_PROXY))
    )
    # floor: over free or object cells, to within the compressed PLY's quantisation of positions (a
    # surfel laid a few µm inside a floor cell may come back a few µm over its edge)
    xy = cloud.means[floor, :2].astype(np.float64)
    on_floor = np.zeros(len(xy), bool)
    for dx, dy in ((0, 0), (2e-3, 0), (-2e-3, 0), (0, 2e-3), (0, -2e-3)):
        rc, inside = _cells(grid, xy + [dx, dy])
        on_floor |= inside & dressing.floor_mask[rc[:, 0], rc[:, 1]]
    assert on_floor.all()
    # every other surfel below head height (the map is a slice at body height; lintels span doorways)
    # sits on an obstacle: half a cell behind it, into the solid, is an occupied cell (walls are traced
    # from the cells and simplified within half a cell)
    solid = ~floor & ~ceiling & (z > 1e-3) & (z < 2.0)
    behind = cloud.means[solid, :2] - (0.5 * grid.resolution + 0.001) * normal[solid, :2]
    rc, inside = _cells(grid, behind.astype(np.float64))
    occupied = inside & (grid.cells[rc[:, 0], rc[:, 1]] != 255)
    doors = _door_leaf_mask(dressing, cloud.means[solid])
    assert occupied[~doors].mean() >= 0.99, occupied[~doors].mean()
    # surfels are thin along their normal and near-opaque
    scales = np.exp(cloud.log_scales)
    assert (scales[:, 2] <= 0.15 * scales[:, :2].min(axis=1)).all()  # THIN_FACTOR / WIDTH_FACTOR = 0.1, quantised
    assert (1 / (1 + np.exp(-cloud.opacity_logits)) > 0.99).all()


def _door_leaf_mask(dressing, points: np.ndarray) -> np.ndarray:
    """Points on the closed doors drawn just outside entrances (seen, but outside the map's obstacles)."""
    out = np.zeros(len(points), bool)
    for part in dressing.parts:
        if part.group == "door":
            c, s = np.cos(part.yaw), np.sin(part.yaw)
            d = points[:, :2] - np.asarray(part.centre)
            u, v = d @ [c, s], d @ [-s, c]
            out |= (np.abs(u) <= part.half[0] + 1e-3) & (np.abs(v) <= part.half[1] + 1e-3)
    return out


def test_walls_follow_the_occupancy_map(office: Path) -> None:
    """Every wall cell facing the floor carries wall surfels (the map's walls, not an approximation)."""
    package = load_scene_package(office)
    grid = package.occupancy
    cloud = read_gaussian_ply(office / GAUSSIANS)
    normal = _normals(cloud.quats.astype(np.float64))
    wall = (np.abs(normal[:, 2]) < 0.01) & (cloud.means[:, 2] > 1.0) & (cloud.means[:, 2] < 2.0)  # above furniture
    behind = cloud.means[wall, :2] - (0.5 * grid.resolution + 0.001) * normal[wall, :2]
    rc, inside = _cells(grid, behind.astype(np.float64))
    has = np.zeros(grid.shape, bool)
    has[rc[inside, 0], rc[inside, 1]] = True
    dressing = build_dressing(package.semantic_map, grid)
    facing = dressing.wall_mask.copy()
    facing[1:-1, 1:-1] &= (
        dressing.floor_mask[:-2, 1:-1]
        | dressing.floor_mask[2:, 1:-1]
        | dressing.floor_mask[1:-1, :-2]
        | dressing.floor_mask[1:-1, 2:]
    )
    facing[[0, -1], :] = facing[:, [0, -1]] = False
    assert has[facing].mean() >= 0.98, has[facing].mean()


def test_usd_proxy_is_closed_valid_and_on_the_map(office: Path) -> None:
    from pxr import Usd, UsdValidation

    registry = UsdValidation.ValidationRegistry()
    validators = [registry.GetOrLoadValidatorByName(m.name) for m in registry.GetAllValidatorMetadata()]
    errors = UsdValidation.ValidationContext(validators).Validate(Usd.Stage.Open(str(office / USD_PROXY)))
    assert [e.GetErrorAsString() for e in errors] == []
    grid = load_scene_package(office).occupancy
    solids = read_usd_proxy(office / USD_PROXY)
    assert len(solids) > 40
    inward = []
    for mesh in solids:
        edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        assert (counts == 2).all(), f"{mesh.name} is not closed"
        t = mesh.vertices[mesh.faces]
        volume = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6
        assert volume > 0, f"{mesh.name} faces inward"
        cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        side = np.abs(cross[:, 2]) < 1e-9 * np.linalg.norm(cross, axis=1).max()  # vertical faces
        n = cross[side] / np.linalg.norm(cross[side], axis=1, keepdims=True)
        # lintels and trims span doorways, above head height; pictures and signs stand 2 cm off the walls
        if not mesh.name.startswith(("opening", "decor")):
            inward.append(t[side].mean(axis=1)[:, :2] - (0.5 * grid.resolution + 0.001) * n[:, :2])
    rc, inside = _cells(grid, np.vstack(inward))
    assert (inside & (grid.cells[rc[:, 0], rc[:, 1]] != 255)).mean() >= 0.99
    assert {m.name.split("_")[0] for m in read_usd_surfaces(office / USD_PROXY)} >= {"floor", "ceiling"}


def _poses(grid, count: int, clearance_m: float, seed: int) -> np.ndarray:
    clear = clearance_field(grid.free, grid.resolution)
    cells = np.argwhere(clear > clearance_m)
    rng = np.random.default_rng(seed)
    xy = grid.to_world(cells[rng.integers(len(cells), size=count)])
    return np.column_stack([xy, rng.uniform(-np.pi, np.pi, count)])


def test_rendered_depth_matches_the_proxy(office: Path) -> None:
    """From 50 random robot poses: the splats cover what the proxy says is there, at the proxy's depth."""
    grid = load_scene_package(office).occupancy
    gaussians = scene_gaussians(office / GAUSSIANS)
    meshes = read_usd_proxy(office / USD_PROXY) + read_usd_surfaces(office / USD_PROXY)
    from scipy.ndimage import binary_dilation

    errors, inside, covered, seen = [], [], 0, 0
    for x, y, yaw in _poses(grid, 50, 0.3, seed=0):
        camera = robot_camera(x, y, yaw, CAMERA_HEIGHT_M, HFOV_DEG, 320, 240)
        out = render(gaussians, camera)
        truth = mesh_depth(meshes, camera)
        surface = np.isfinite(truth)
        hit = surface & (out.alpha > 0.5)
        seen, covered = seen + surface.sum(), covered + hit.sum()
        errors.append(np.abs(out.depth[hit] - truth[hit]))
        # alpha blending mixes the depths of both sides of a silhouette: away from depth steps the
        # surfaces themselves must be where the proxy says
        t = np.where(surface, truth, 100.0)
        step = np.zeros(t.shape, bool)
        step[:, 1:] |= np.abs(np.diff(t, axis=1)) > 0.1
        step[1:, :] |= np.abs(np.diff(t, axis=0)) > 0.1
        away = hit & ~binary_dilation(step, iterations=2)
        inside.append(np.abs(out.depth[away] - truth[away]))
    errors, inside = np.concatenate(errors), np.concatenate(inside)
    assert covered / seen >= 0.98, covered / seen
    assert np.median(errors) <= 0.03, np.median(errors)
    assert np.percentile(inside, 95) <= 0.06, np.percentile(inside, 95)
    assert np.percentile(errors, 95) <= 0.15, np.percentile(errors, 95)  # silhouettes included


def test_no_holes_from_30_cm(office: Path) -> None:
    """Facing the nearest obstacle from 0.3 m, every pixel is covered."""
    grid = load_scene_package(office).occupancy
    gaussians = scene_gaussians(office / GAUSSIANS)
    clear = clearance_field(grid.free, grid.resolution)
    gy, gx = np.gradient(clear)
    cells = np.argwhere((clear > 0.29) & (clear < 0.31))
    rng = np.random.default_rng(1)
    for r, c in cells[rng.integers(len(cells), size=12)]:
        x, y = grid.to_world(np.array([[r, c]]))[0]
        yaw = np.arctan2(gy[r, c], -gx[r, c])  # down the clearance gradient (rows grow toward −y)
        out = render(gaussians, robot_camera(x, y, yaw, CAMERA_HEIGHT_M, HFOV_DEG, 160, 120))
        assert out.alpha.min() > 0.5, (x, y, yaw, out.alpha.min())


def test_mesh_depth_of_a_plane() -> None:
    """The proxy z-buffer itself: a wall 2 m ahead, seen straight on and across the near plane."""
    from song.datasets.scenes.usd import ProxyMesh

    wall = ProxyMesh(
        "wall", np.array([[2.0, -5, 0], [2.0, 5, 0], [2.0, 5, 3], [2.0, -5, 3]]), np.array([[0, 1, 2], [0, 2, 3]])
    )
    floor = ProxyMesh(
        "floor", np.array([[-5.0, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]]), np.array([[0, 1, 2], [0, 2, 3]])
    )
    camera = robot_camera(0.0, 0.0, 0.0, 0.8, 90.0, 64, 48)
    depth = mesh_depth([wall, floor], camera)
    assert np.isfinite(depth).all()
    np.testing.assert_allclose(depth[:20], 2.0, rtol=1e-5)  # above the horizon: the wall, planar depth 2 m
    # below: the floor until it meets the wall (the floor spans behind the camera: clipped at the near plane)
    row = 47
    v = (row + 0.5 - camera.cy) / camera.fy
    assert depth[row, 32] == pytest.approx(min(2.0, 0.8 / v), rel=1e-5)


def test_same_seed_same_bytes_and_a_supersplat_file(office: Path, tmp_path: Path) -> None:
    import shutil

    for name in ("a", "b"):
        shutil.copytree(office, tmp_path / name / office.name)
        dress_package(tmp_path / name / office.name)
    a, b = tmp_path / "a" / office.name, tmp_path / "b" / office.name
    for file in (GAUSSIANS, USD_PROXY):
        assert (a / file).read_bytes() == (b / file).read_bytes() == (office / file).read_bytes()
    dress_package(b, seed=1)
    assert (a / GAUSSIANS).read_bytes() != (b / GAUSSIANS).read_bytes()
    # the header is SuperSplat's, element for element and property for property
    ours = _header(office / GAUSSIANS)
    theirs = _header(shared_file(GUITAR))
    assert [line for line in ours if not line.startswith("element")] == [
        line for line in theirs if not line.startswith("element")
    ]
    assert [line.split()[1] for line in ours if line.startswith("element")] == [
        line.split()[1] for line in theirs if line.startswith("element")
    ]


def _header(path: Path) -> list[str]:
    head = path.read_bytes()[:4096]
    return [line for line in head[: head.index(b"end_header")].decode().splitlines() if not line.startswith("comment")]


def test_a_spacing_that_would_exhaust_memory_is_refused_before_any_surfel(make_scene, monkeypatch) -> None:
    from song.datasets.scenes.splat import dress_package
    from song.errors import SceneError

    root = make_scene()
    with pytest.raises(SceneError, match="spacing: 0.005 m spacing makes at least .* exceeds the limit max_splats"):
        monkeypatch.setenv("SONG_MAX_SPLATS", "1000000")
        dress_package(root, spacing=0.005)
    assert not (root / "3dgs_compressed.ply").exists()


def test_splat_out_never_copies_through_a_symbolic_link(make_scene, tmp_path) -> None:
    from typer.testing import CliRunner

    from song.cli import app

    root = make_scene()
    secret = tmp_path / "secret.txt"
    secret.write_text("not yours")
    (root / "scene_flat.usda").unlink(missing_ok=True)
    (root / "scene_flat.usda").symlink_to(secret)
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["scenes", "splat", str(root.parent), "--out", str(out)])
    assert result.exit_code != 0 and "symbolic link" in " ".join(result.output.split())
    assert not any(p.is_file() and p.read_bytes() == b"not yours" for p in out.rglob("*")) if out.exists() else True


def test_usd_proxy_is_ready_for_a_simulator(office: Path) -> None:
    """Static colliders, gravity along -Z, albedo materials and semantic classes per object and room."""
    from pxr import Usd, UsdGeom, UsdPhysics, UsdSemantics, UsdShade

    from song.datasets.scenes.materials import material_of

    stage = Usd.Stage.Open(str(office / USD_PROXY))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    scene = UsdPhysics.Scene(stage.GetPrimAtPath("/World/physicsScene"))
    assert tuple(scene.GetGravityDirectionAttr().Get()) == (0.0, 0.0, -1.0)
    package = load_scene_package(office)
    categories = {o.category for o in package.semantic_map.objects}
    labels = set()
    for prim in stage.GetPrimAtPath("/World/collision").GetChildren():
        assert prim.HasAPI(UsdPhysics.CollisionAPI) and not prim.HasAPI(UsdPhysics.RigidBodyAPI)  # static
        approximation = UsdPhysics.MeshCollisionAPI(prim).GetApproximationAttr().Get()
        assert approximation == ("none" if prim.GetName().startswith("wall") else "convexHull")
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        shader = UsdShade.Shader(stage.GetPrimAtPath(f"{material.GetPath()}/surface"))
        colour = np.array(shader.GetInput("diffuseColor").Get())
        base = np.array(material_of(material.GetPrim().GetName()).base)
        linear = np.where(base <= 0.04045, base / 12.92, ((base + 0.055) / 1.055) ** 2.4)
        np.testing.assert_allclose(colour, linear, atol=1e-6)
        labels.update(UsdSemantics.LabelsAPI(prim, "class").GetLabelsAttr().Get() or [])
    from song.datasets.scenes.dressing import PASSAGE_CATEGORIES

    assert "wall" in labels and categories - set(PASSAGE_CATEGORIES) <= labels  # every furnished category
    rooms = stage.GetPrimAtPath("/World/rooms").GetChildren()
    assert len(rooms) == len(package.semantic_map.regions)
    assert {UsdSemantics.LabelsAPI(r, "class").GetLabelsAttr().Get()[0] for r in rooms} == {
        r.type for r in package.semantic_map.regions
    }
    assert all(UsdGeom.Imageable(r).GetPurposeAttr().Get() == "guide" for r in rooms)


def test_instances_of_one_material_differ_and_one_instance_is_one_tone(office: Path) -> None:
    """The desks of an office are not one colour: each object takes the variant its id hashes to, every
    part of it the same one; the unvaried material stays what the flat (reference-render) colours use."""
    from song.datasets.scenes.materials import VARIANTS, material_of, variant
    from song.datasets.scenes.splat import _instance_material

    package = load_scene_package(office)
    hints = DressingHints.from_json(read_usd_dressing(office / USD_PROXY))
    dressing = build_dressing(package.semantic_map, package.occupancy, hints)
    by_object: dict[str, set[str]] = {}
    for part in dressing.parts:
        if part.group not in ("lintel", "frame", "door"):
            by_object.setdefault(part.group, set()).add(_instance_material(part))
    assert all(len({name.split("~")[1] for name in names}) == 1 for names in by_object.values())  # one variant each
    materials: dict[str, set[str]] = {}
    for part in dressing.parts:
        materials.setdefault(part.material, set()).add(_instance_material(part))
    shared = [names for names in materials.values() if len(names) > 1]
    assert shared  # several instances of one material took different variants
    bases = {material_of(variant("wood_medium", k)).base for k in range(VARIANTS)}
    assert len(bases) == VARIANTS and material_of(variant("wood_medium", 0)).base == material_of("wood_medium").base
    tiles = [material_of(variant("tiles_grey", k)).scale for k in range(VARIANTS)]
    assert min(tiles) == 0.8 and max(tiles) == 1.25


def test_inside_corners_have_no_seam(office: Path) -> None:
    """Seen from 1 m, the line where two walls meet is covered as well as the walls around it.

    Both walls' sheets run on past an inside corner behind the other, so where their last jittered
    columns leave the corner line thin the other fills it (a dark seam of background showed there).
    """
    from song.render import render, robot_camera
    from song.runtime.vision import scene_gaussians

    package = load_scene_package(office)
    dressing = build_dressing(
        package.semantic_map, package.occupancy, DressingHints.from_json(read_usd_dressing(office / USD_PROXY))
    )
    corners = []
    for poly in dressing.walls:
        for ring in (poly.exterior, *poly.interiors):
            pts = np.asarray(ring.coords)[:-1]
            e_in, e_out = pts - np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0) - pts
            turn = e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0]
            for k in np.flatnonzero(turn < -1e-9):
                a, b = -e_in[k] / np.linalg.norm(e_in[k]), e_out[k] / np.linalg.norm(e_out[k])
                if abs(a @ b) < 0.1 and min(np.linalg.norm(e_in[k]), np.linalg.norm(e_out[k])) > 2.0:
                    corners.append((pts[k], a + b))  # a right angle between two long walls: into the room
    assert corners
    gaussians = scene_gaussians(office / GAUSSIANS)
    worst = []
    for corner, into in corners[:4]:
        into = into / np.linalg.norm(into)
        eye = corner + into * 1.0
        yaw = float(np.arctan2(-into[1], -into[0]))
        out = render(gaussians, robot_camera(*eye, yaw, 1.2, 70.0, 320, 240), background=(0, 0, 0))
        strip = out.alpha[60:180, 157:163]
        if np.median(out.depth[60:180, 157:163]) < 1.6:  # the corner itself in view (no furniture before it)
            worst.append(float(strip.min()))
    assert worst and min(worst) >= 0.8, worst


def _coverage(s, points: np.ndarray) -> np.ndarray:
    """Alpha of the surfels ``s`` (one face in the z = 0 plane, axis-aligned) at points (M, 2), as the renderer composes it."""
    from song.datasets.scenes.splat import OPACITY_LOGIT

    o = 1.0 / (1.0 + np.exp(-OPACITY_LOGIT))
    d = points[:, None, :] - s.pos[None, :, :2]
    a = np.minimum(0.999, o * np.exp(-0.5 * ((d[..., 0] / s.s1) ** 2 + (d[..., 1] / s.s2) ** 2)))
    return 1.0 - np.prod(1.0 - np.where(a >= 1 / 255, a, 0.0), axis=1)


def test_an_objects_outline_does_not_bleed_past_its_edge() -> None:
    """A face's outermost surfels are narrower across its edge: α near ½ on the edge (a true edge covers half a
    pixel there), nearly none half a spacing outside it; walls keep full-width surfels (they meet other surfaces)."""
    from song.datasets.scenes.splat import SPACING_M, _faces

    rng = np.random.default_rng(0)
    args = (np.zeros((1, 3)), np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]), np.array([0.7]), np.array([0.7]),
            np.array(["wood_medium"], object), np.array([False]), SPACING_M)  # fmt: skip
    sharp, full = _faces(*args, rng), _faces(*args, np.random.default_rng(0), sharp=False)
    h = SPACING_M
    line = np.column_stack([np.linspace(-h, h, 41), np.full(41, 0.35)])  # across the edge at u = 0
    cover = _coverage(sharp, line)
    assert 0.3 <= cover[20] <= 0.6  # on the edge
    assert cover[10] <= 0.05  # half a spacing outside
    assert cover[30:].min() >= 0.85  # from half a spacing in: no seam along the edge row (a surface lets ~5 % through)
    bleed = _coverage(full, line)
    assert bleed[10] > 0.15 and bleed[20] > 0.6  # full-width surfels (walls) do bleed: the rule is what fixes objects


def test_compiled_face_sampling_matches_its_numpy_twin() -> None:
    """Jittered grid samples on rectangles: the compiled loop equals the numpy expression bit for bit."""
    from song.datasets.scenes import splat

    rng = np.random.default_rng(3)
    f = 40
    origin = rng.uniform(-5, 5, (f, 3))
    eu = rng.normal(size=(f, 3))
    eu /= np.linalg.norm(eu, axis=1, keepdims=True)
    ev = np.cross(eu, rng.normal(size=(f, 3)))
    ev /= np.linalg.norm(ev, axis=1, keepdims=True)
    lu, lv = rng.uniform(0.005, 2.0, f), rng.uniform(0.005, 1.0, f)  # some under a spacing: finer samples
    nu, nv = splat._face_grid(lu, lv, 0.035)
    total = int((nu * nv).sum())
    ju, jv = rng.uniform(-1, 1, total), rng.uniform(-1, 1, total)
    normal_f = np.cross(eu, ev)
    for sharp in (True, False):
        got = splat._face_samples(origin, eu, ev, normal_f, lu, lv, nu, nv, ju, jv, sharp)
        want = splat._face_samples_reference(origin, eu, ev, normal_f, lu, lv, nu, nv, ju, jv, sharp)
        for a, b in zip(got, want, strict=True):
            assert a.shape == b.shape and np.array_equal(a, b)
