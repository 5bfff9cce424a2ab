"""The motion stage on a synthetic crowd.parquet: output contract, determinism, CLI, errors."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from song.config import MotionConfig, SongConfig
from song.datasets.run import CROWD_SCHEMA as SCHEMA  # the crowd.parquet contract
from song.datasets.scenes import load_scene_package
from song.errors import FormatError, StageError
from song.geometry.fk import forward_kinematics
from song.pipeline.chain import StageContext, load_stages
from song.pipeline.motion import load_motion, read_trajectories, run_motion
from song.pipeline.motion.amass import from_amass, read_amass
from song.pipeline.motion.generators import make_generator
from song.pipeline.motion.synthetic import synthetic_trajectories


def write_crowd(scene_dir: Path, names=("straight_1.0", "turn_on_spot", "stop_and_go")) -> dict[int, object]:
    plans = synthetic_trajectories(6.0)
    rows = {k: [] for k in SCHEMA.names}
    chosen = {}
    for ped_id, name in enumerate(names):
        traj = plans[name]
        start = 15 * ped_id  # departures at different frames, as in a crowd
        frame = traj.frame + start
        chosen[ped_id] = traj
        rows["ped_id"].append(np.full(len(frame), ped_id, dtype=np.int32))
        rows["frame"].append(frame.astype(np.int32))
        rows["t"].append(frame / 30.0)
        rows["x"].append(traj.xy[:, 0] + 1.0)
        rows["y"].append(traj.xy[:, 1] + 2.0)
        rows["yaw"].append(traj.yaw)
        rows["speed"].append(traj.speed)
    table = pa.table({k: np.concatenate(v) for k, v in rows.items()}, schema=SCHEMA)
    scene_dir.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    pq.write_table(table, buffer)
    (scene_dir / "crowd.parquet").write_bytes(buffer.getvalue())
    return chosen


def _ctx(make_scene, tmp_path: Path, run: str = "run", **motion) -> StageContext:
    scene = load_scene_package(make_scene())
    config = SongConfig(seed=3, motion=MotionConfig(**motion))
    scene_dir = tmp_path / run / "scenes" / scene.scene_id
    return StageContext(scene=scene, scene_dir=scene_dir, run_dir=tmp_path / run, config=config, stage="motion")


def test_stage_writes_the_contract(make_scene, tmp_path):
    ctx = _ctx(make_scene, tmp_path)
    write_crowd(ctx.scene_dir)
    written = run_motion(ctx)
    assert len(written) == 9 and all((ctx.scene_dir / w).exists() for w in written)
    trajs = {t.ped_id: t for t in read_trajectories(ctx.scene_dir / "crowd.parquet")}
    for ped_id, traj in trajs.items():
        folder = ctx.scene_dir / "human_amass" / f"traj_{ped_id}"
        with np.load(folder / "motion.npz") as data:
            arrays = {k: data[k] for k in data.files}
        n = traj.n_frames
        expected = {
            "t": ((n,), np.float64),
            "frame": ((n,), np.int32),
            "height_m": ((), np.float64),
            "rest_joints": ((24, 3), np.float32),
            "local_quats": ((n, 24, 4), np.float32),
            "root_pos": ((n, 3), np.float32),
            "joints": ((n, 24, 3), np.float32),
            "contacts": ((n, 2), np.bool_),
        }
        for key, (shape, dtype) in expected.items():
            assert arrays[key].shape == shape and arrays[key].dtype == dtype, key
        assert np.array_equal(arrays["frame"], traj.frame) and np.array_equal(arrays["t"], traj.t)
        fk = forward_kinematics(
            arrays["rest_joints"].astype(np.float64),
            arrays["local_quats"].astype(np.float64),
            arrays["root_pos"].astype(np.float64),
        )[0]
        assert np.abs(fk - arrays["joints"]).max() < 1e-5
        # AMASS decodes to the same joints within 1 mm
        q, root = from_amass(read_amass(folder / "motion_amass.npz"))
        assert np.abs(forward_kinematics(arrays["rest_joints"].astype(np.float64), q, root)[0] - fk).max() < 1e-3
        loaded = load_motion(folder)
        assert loaded.meta["ped_id"] == ped_id and 1.5 <= loaded.height_m <= 1.95
        meta = loaded.meta
        assert meta["generator"]["name"] == "procedural" and meta["generator"]["fallback"] is True
        assert meta["generator"]["fallback_reason"]
        q = meta["quality"]
        assert q["foot_skating_ratio"] <= 0.02 and q["root_error_max_m"] <= 0.05
        assert np.linalg.norm(arrays["root_pos"][:, :2] - traj.xy, axis=1).max() < 0.05
        assert meta["amass"]["J0"] == pytest.approx([-0.001795, -0.223333, 0.028219])  # SMPL neutral, zero betas


def test_stage_is_deterministic_and_removes_stale(make_scene, tmp_path):
    outputs = []
    for run in ("a", "b"):
        ctx = _ctx(make_scene, tmp_path, run=run)
        write_crowd(ctx.scene_dir)
        (ctx.scene_dir / "human_amass" / "traj_99").mkdir(parents=True)
        written = run_motion(ctx)
        assert not (ctx.scene_dir / "human_amass" / "traj_99").exists()
        outputs.append({w: (ctx.scene_dir / w).read_bytes() for w in written})
    assert outputs[0] == outputs[1]


def test_explicit_kimodo_without_weights_fails_clearly(make_scene, tmp_path):
    with pytest.raises(StageError, match="Kimodo is unavailable"):
        make_generator(MotionConfig(generator="kimodo"))
    generator, reason = make_generator(MotionConfig(generator="auto"))
    assert generator.name == "procedural" and reason


def test_bad_inputs(tmp_path):
    (tmp_path / "crowd.parquet").write_bytes(b"not parquet")
    with pytest.raises(FormatError, match="crowd.parquet"):
        read_trajectories(tmp_path / "crowd.parquet")
    (tmp_path / "t").mkdir()
    with pytest.raises(FormatError, match="motion.npz"):
        load_motion(tmp_path / "t")


def test_stage_registered_and_cli(make_scene, tmp_path):
    import song.pipeline.motion  # noqa: F401  (registers the stage)

    assert "motion" in {s.name for s in load_stages()}
    from typer.testing import CliRunner

    from song.cli import app

    result = CliRunner().invoke(app, ["rerun", "--help"])
    assert result.exit_code == 0 and "motion.generator=kimodo" in " ".join(result.output.split())
    result = CliRunner().invoke(app, ["rerun", "motion", "--run", str(tmp_path / "missing")])
    assert result.exit_code != 0
    run = tmp_path / "run"
    ctx = _ctx(make_scene, tmp_path)
    from song.pipeline.chain import iter_run

    list(iter_run(ctx.scene.root.parent, run, ctx.config, ["intents"], executor="serial"))
    before = (run / "run.json").read_bytes()
    result = CliRunner().invoke(app, ["rerun", "motion", "--run", str(run), "--set", "motion.generator=bogus"])
    assert result.exit_code == 2 and "motion.generator" in result.output
    assert (run / "run.json").read_bytes() == before  # a bad override never reaches the run folder


@pytest.mark.slow
def test_motion_on_the_sample_run(sample_run):
    """The real chain: intents + crowd on the shipped samples, then motion; every pedestrian meets the targets."""
    import song.pipeline.motion  # noqa: F401  (registers the stage in this process)
    from song.pipeline.chain import iter_run, read_run

    scenes_dir, config = read_run(sample_run)
    results = list(iter_run(scenes_dir, sample_run, config, ["motion"], executor="serial"))
    assert results and all(r.status == "ok" for r in results), [r.error for r in results]
    metas = [load_motion(p.parent).meta for p in sorted(sample_run.glob("scenes/*/human_amass/*/motion.npz"))]
    assert metas
    for meta in metas:
        q = meta["quality"]
        assert q["foot_skating_ratio"] <= 0.02 and q["penetration_p99_m"] <= 0.01
        assert q["root_error_mean_m"] <= 0.02 and q["root_error_max_m"] <= 0.05
        assert q["knee_flexion_min_deg"] >= 0.0 and q["elbow_flexion_min_deg"] >= 0.0
