"""Stage chain: skip when unchanged, rerun when inputs change, failure isolation, determinism."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from song.config import SongConfig
from song.pipeline.chain import iter_run

STAGES = ["dummy_first", "dummy_second"]


@pytest.fixture(autouse=True)
def _plugins(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SONG_STAGE_PLUGINS", "tests.pipeline._dummy_stages")


def _tree(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != "run.json"
    }


def _run(scenes: Path, run: Path, cfg: SongConfig, **kw) -> dict[str, object]:
    return {r.scene_id: r for r in iter_run(scenes, run, cfg, STAGES, **kw)}


def test_rerun_skips_and_changes_rerun(make_scene, tmp_path: Path) -> None:
    make_scene("a")
    make_scene("b")
    scenes, run = tmp_path / "scenes", tmp_path / "run"
    first = _run(scenes, run, SongConfig())
    assert {r.status for r in first.values()} == {"ok"}
    again = _run(scenes, run, SongConfig())
    assert all(r.stages == {"dummy_first": "skipped", "dummy_second": "skipped"} for r in again.values())
    # a damaged output is detected and rebuilt, downstream stays skipped because bytes are identical
    (run / "scenes/a/first.json").write_text("{}")
    repaired = _run(scenes, run, SongConfig())
    assert repaired["a"].stages == {"dummy_first": "ok", "dummy_second": "skipped"}
    # a new seed changes every stage's input hash
    reseeded = _run(scenes, run, SongConfig(seed=5))
    assert reseeded["b"].stages == {"dummy_first": "ok", "dummy_second": "ok"}
    record = json.loads((run / "scenes/b/stages.json").read_text())
    assert set(record) == set(STAGES) and record["dummy_second"]["outputs"].keys() == {"second.npz"}


def test_bad_scene_fails_alone(make_scene, tmp_path: Path) -> None:
    make_scene("good")
    bad = make_scene("broken")
    (bad / "semantic_map.json").write_text('{"format": "song.semantic_map", "version": 1}')
    library = make_scene("lib")
    text = (library / "semantic_map.json").read_text().replace('"office"', '"library"')
    (library / "semantic_map.json").write_text(text)
    results = _run(tmp_path / "scenes", tmp_path / "run", SongConfig())
    assert results["good"].status == "ok"
    assert results["broken"].status == "failed" and "semantic_map.json" in results["broken"].error
    assert results["lib"].status == "failed" and results["lib"].stages == {"dummy_first": "failed"}
    assert "venue_type" in results["lib"].error


def test_workers_do_not_change_bytes(make_scene, tmp_path: Path) -> None:
    for name in ("a", "b", "c"):
        make_scene(name)
    scenes = tmp_path / "scenes"
    _run(scenes, tmp_path / "serial", SongConfig(seed=3), executor="serial")
    _run(scenes, tmp_path / "pool", SongConfig(seed=3), executor="process", workers=2)
    assert _tree(tmp_path / "serial") == _tree(tmp_path / "pool")
    assert len(_tree(tmp_path / "serial")) == 10  # 3 scenes × (2 outputs + stages.json), run.json, .song.lock


def test_dask_local_cluster_gives_identical_bytes(make_scene, tmp_path: Path) -> None:
    pytest.importorskip("dask.distributed")
    for name in ("a", "b"):
        make_scene(name)
    scenes = tmp_path / "scenes"
    _run(scenes, tmp_path / "serial", SongConfig(seed=4), executor="serial")
    _run(scenes, tmp_path / "dask", SongConfig(seed=4), executor="dask", workers=2)
    assert _tree(tmp_path / "serial") == _tree(tmp_path / "dask")


def test_kill_and_resume_gives_identical_bytes(make_scene, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import os
    import signal
    import subprocess
    import sys
    import time

    for index in range(6):
        make_scene(f"s{index}")
    scenes = tmp_path / "scenes"
    _run(scenes, tmp_path / "clean", SongConfig(), executor="serial")
    env = {**os.environ, "SONG_DUMMY_SLEEP": "0.4", "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    command = [sys.executable, "-m", "song", "synth", "--scenes", str(scenes), "--out", str(tmp_path / "killed")]
    options = ["--workers", "1", "--quiet", "--stages", ",".join(STAGES)]
    proc = subprocess.Popen([*command, *options], env=env, stdout=subprocess.PIPE)
    deadline = time.time() + 60
    while time.time() < deadline and len(list((tmp_path / "killed").glob("scenes/*/first.json"))) < 2:
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = len(list((tmp_path / "killed").glob("scenes/*/second.npz")))
    assert 0 < done_before < 6
    resumed = _run(scenes, tmp_path / "killed", SongConfig(), executor="serial")
    assert sum(r.stages.get("dummy_first") == "skipped" for r in resumed.values()) >= done_before
    assert _tree(tmp_path / "clean") == _tree(tmp_path / "killed")


def test_real_stages_identical_across_executors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """intents + crowd on two sample houses: serial, 2 processes and Dask give the same bytes."""
    pytest.importorskip("dask.distributed")
    monkeypatch.delenv("SONG_STAGE_PLUGINS")
    from tests.conftest import SAMPLES

    ids = ["procthor_house_1", "procthor_house_6"]
    trees = []
    for executor, workers in (("serial", 1), ("process", 2), ("dask", 2)):
        run = tmp_path / executor
        results = list(
            iter_run(SAMPLES, run, SongConfig(seed=2), ["intents", "crowd"], workers, executor, scene_ids=ids)
        )
        assert {r.status for r in results} == {"ok"}
        trees.append(_tree(run))
    assert trees[0] == trees[1] == trees[2]
    assert any(name.endswith("crowd.parquet") for name in trees[0])


def test_changing_a_value_a_stage_reads_reruns_it(make_scene, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """intents reads crowd.agent_radius_m: changing it re-runs intents and crowd; a motion value re-runs neither."""
    monkeypatch.delenv("SONG_STAGE_PLUGINS")
    make_scene("a")
    scenes, run = tmp_path / "scenes", tmp_path / "run"
    base = SongConfig(seed=1)
    first = {r.scene_id: r for r in iter_run(scenes, run, base, ["intents", "crowd"], executor="serial")}
    assert first["a"].stages == {"intents": "ok", "crowd": "ok"}
    record = json.loads((run / "scenes/a/stages.json").read_text())
    other_motion = base.model_copy(update={"motion": base.motion.model_copy(update={"smoothing_sigma_frames": 2.0})})
    same = {r.scene_id: r for r in iter_run(scenes, run, other_motion, ["intents", "crowd"], executor="serial")}
    assert same["a"].stages == {"intents": "skipped", "crowd": "skipped"}
    wider = base.model_copy(update={"crowd": base.crowd.model_copy(update={"agent_radius_m": 0.3})})
    again = {r.scene_id: r for r in iter_run(scenes, run, wider, ["intents", "crowd"], executor="serial")}
    assert again["a"].stages == {"intents": "ok", "crowd": "ok"}
    after = json.loads((run / "scenes/a/stages.json").read_text())
    assert all(after[s]["input_hash"] != record[s]["input_hash"] for s in ("intents", "crowd"))


def test_stage_order_follows_dependencies() -> None:
    from song.errors import StageError
    from song.pipeline.chain import Stage, load_stages, stage_order

    def run(ctx):
        return []

    stages = [Stage("c", run, ("b",)), Stage("a", run), Stage("b", run, ("a",)), Stage("z", run)]
    assert [s.name for s in stage_order(stages)] == ["a", "b", "c", "z"]
    with pytest.raises(StageError, match="cycle"):
        stage_order([Stage("x", run, ("y",)), Stage("y", run, ("x",))])
    built_in = [s.name for s in load_stages() if not s.name.startswith("dummy")]
    assert built_in == ["intents", "crowd", "motion", "binding"]


def test_unknown_stage_name_is_refused(make_scene, tmp_path: Path) -> None:
    from song.errors import StageError

    make_scene("a")
    with pytest.raises(StageError, match="unknown stage 'bogus'"):
        list(iter_run(tmp_path / "scenes", tmp_path / "run", SongConfig(), ["bogus"]))
    assert not (tmp_path / "run" / "run.json").exists()
