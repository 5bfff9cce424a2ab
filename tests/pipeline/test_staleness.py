"""Stages are never silently stale: rerun re-runs what is downstream, grade and export refuse stale inputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from song.cli import app
from song.config import SongConfig
from song.datasets.run import RunFolder
from song.datasets.run.integrity import stale_stages
from song.pipeline.chain import iter_run

STAGES = "intents,crowd"


def _cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, " ".join(result.output.split())  # rich wraps long lines


def _pedestrians(run: Path, scene: str = "tiny") -> int:
    return len(json.loads((run / "scenes" / scene / "intents.json").read_text())["intents"])


def _crowd_ids(run: Path, scene: str = "tiny") -> set[int]:
    status = json.loads((run / "scenes" / scene / "crowd_status.json").read_text())
    return {int(k) for k in status.get("pedestrians", status)}


@pytest.fixture
def synthesised(make_scene, tmp_path: Path) -> tuple[Path, Path]:
    scenes = make_scene().parent
    run = tmp_path / "run"
    code, out = _cli("synth", "--scenes", scenes, "--out", run, "--stages", STAGES, "-j", "1")
    assert code == 0, out
    assert _pedestrians(run) > 1
    return scenes, run


def test_rerun_reruns_every_stage_made_from_the_changed_one(synthesised) -> None:
    scenes, run = synthesised
    code, out = _cli("rerun", "intents", "--run", run, "--set", "intents.max_pedestrians=1", "-j", "1")
    assert code == 0, out
    assert _pedestrians(run) == 1
    assert len(_crowd_ids(run)) == 1  # the crowd was made again from the new intents
    record = json.loads((run / "scenes" / "tiny" / "stages.json").read_text())
    assert record["intents"]["settings"]["intents"]["max_pedestrians"] == 1  # the settings that made it
    assert not stale_stages(RunFolder(run).scene("tiny"), SongConfig(intents={"max_pedestrians": 1}))


def test_grade_refuses_a_crowd_made_from_older_intents(synthesised) -> None:
    scenes, run = synthesised
    config = SongConfig(intents={"max_pedestrians": 1})
    results = list(iter_run(scenes, run, config, ["intents"], executor="serial"))  # intents alone, as before
    assert [r.status for r in results] == ["ok"]
    stale = stale_stages(RunFolder(run).scene("tiny"), config)
    assert list(stale) == ["crowd"] and "'intents' stage re-ran after it" in stale["crowd"]
    code, out = _cli("grade", "--run", run, "--episodes", "4")
    assert code != 0
    assert "the 'crowd' stage is stale" in out and "song synth" in out
    assert not (run / "manifest" / "episodes.parquet").exists()


def test_synth_after_a_rerun_set_names_the_settings_it_would_revert(synthesised) -> None:
    scenes, run = synthesised
    assert _cli("rerun", "intents", "--run", run, "--set", "intents.max_pedestrians=1", "-j", "1")[0] == 0
    code, out = _cli("synth", "--scenes", scenes, "--out", run, "--stages", STAGES, "-j", "1")
    assert code != 0
    assert "intents.max_pedestrians=1" in out and "--replace-settings" in out
    assert _pedestrians(run) == 1  # nothing was reverted
    code, out = _cli(
        "synth", "--scenes", scenes, "--out", run, "--stages", STAGES, "-j", "1", "--set", "intents.max_pedestrians=1"
    )
    assert code == 0 and "0 ok, 1 unchanged" in out, out
    code, out = _cli("synth", "--scenes", scenes, "--out", run, "--stages", STAGES, "-j", "1", "--replace-settings")
    assert code == 0 and _pedestrians(run) > 1


def test_export_refuses_episodes_graded_before_the_map_changed(synthesised, tmp_path: Path) -> None:
    scenes, run = synthesised
    assert _cli("grade", "--run", run, "--episodes", "4")[0] == 0
    png = scenes / "tiny" / "occupancy.png"
    cells = np.array(Image.open(png))
    cells[:, cells.shape[1] // 4] = 0  # a new wall across the left room
    Image.fromarray(cells).save(png)
    code, out = _cli("export-bench", "--run", run, "--bench", tmp_path / "bench", "--version", "1.0.0")
    assert code != 0 and "changed since" in out  # the stages read another map
    assert _cli("synth", "--scenes", scenes, "--out", run, "--stages", STAGES, "-j", "1")[0] == 0
    code, out = _cli("export-bench", "--run", run, "--bench", tmp_path / "bench", "--version", "1.0.0")
    assert code != 0 and "were graded from other stage outputs" in out and "song grade" in out
    assert not (tmp_path / "bench" / "1.0.0").exists()
    assert _cli("grade", "--run", run, "--episodes", "4")[0] == 0
    code, out = _cli("export-bench", "--run", run, "--bench", tmp_path / "bench", "--version", "1.0.0")
    assert code == 0, out
