"""Every extension point is one registry: a plugin defined outside ``song/`` is found by name in ``-j 2`` runs.

The plugins live in a temporary distribution with a ``song.plugins`` entry point (as ``pip install``
would leave it: a module plus a ``.dist-info`` folder on the path). Each plugin touches a marker file
named after its kind and process when it runs, so the tests see which ran, and that it ran in a worker.
"""

from __future__ import annotations

import importlib
import json
import os
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from song import plugins
from song.cli import app
from tests.conftest import build_two_room_scene

GOLDEN = Path(__file__).resolve().parent / "artifacts" / "bench_golden"
MODULE = "song_test_plugins"
TEST_NAMES = {"test_avoidance", "test_llm", "test_gait", "test_count", "test_sensor", "test_policy", "TEST",
              "test_backend", "test_camera"}  # fmt: skip
PLUGINS = textwrap.dedent(
    '''
    """Test plugins of every kind (see tests/test_plugins.py)."""
    import os
    import pathlib

    import numpy as np

    from song.pipeline.chain import Stage, StageOutput
    from song.pipeline.crowd.avoidance import OrcaAvoidance
    from song.pipeline.intents.llm import LLMRefusal
    from song.pipeline.motion.generators import ProceduralGait
    from song.plugins import add, register
    from song.render.render import _render_numba
    from song.runtime.sensors import Box, Sensor


    def mark(kind):
        pathlib.Path(os.environ["SONG_TEST_PLUGIN_MARKS"], f"{kind}-{os.getpid()}").touch()


    @register("avoidance", "test_avoidance")
    class TestAvoidance(OrcaAvoidance):
        def __init__(self, mesh, cfg):
            mark("avoidance")
            super().__init__(mesh, cfg)


    class TestClient:
        provider, model = "test_llm", "declines-everything"

        def request(self, prompt, schema):
            mark("llm")
            raise LLMRefusal("the test provider declines")


    add("llm", "test_llm", lambda config: TestClient())


    @register("motion_generator", "test_gait")
    class TestGait(ProceduralGait):
        def generate(self, trajectories, activities, seeds):
            mark("motion_generator")
            return super().generate(trajectories, activities, seeds)


    def count_pedestrians(ctx):
        mark("stage")
        text = (ctx.scene_dir / "crowd_status.json").read_text()
        (ctx.scene_dir / "test_count.json").write_text(str(len(text)))
        return StageOutput(["test_count.json"])


    add("stage", "test_count", Stage("test_count", count_pedestrians, depends=("crowd",)))


    @register("sensor", "test_sensor")
    class TestSensor(Sensor):
        name = "test_sensor"

        def space(self):
            return Box(0.0, 1.0, (1,), np.float32)

        def observe(self, view):
            mark("sensor")
            return np.ones(1, np.float32)


    @register("policy", "test_policy")
    class TestPolicy:
        sensors = ("state", "test_sensor", "depth")

        def reset(self, episode):
            mark("policy")

        def act(self, observation):
            assert observation["test_sensor"][0] == 1.0
            return (0.4, 0.0)


    @register("metric", "TEST")
    class TestMetric:
        name = "TEST"

        def value(self, episodes):
            mark("metric")
            return float(len(episodes))


    def test_backend(sets, camera, background, profile=None):
        mark("render_backend")
        return _render_numba(sets, camera, background, profile)


    add("render_backend", "test_backend", test_backend)


    @register("camera_model", "test_camera")
    class TestCamera:
        def __init__(self, params):
            self.params = params

        def apply(self, frame, context):
            mark("camera_model")
            return frame
    '''
)


@pytest.fixture
def installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The test plugins installed as a distribution with an entry point; the folder of their marks."""
    site = tmp_path / "site"
    (site / "song_test_plugins-0.1.dist-info").mkdir(parents=True)
    (site / f"{MODULE}.py").write_text(PLUGINS)
    info = site / "song_test_plugins-0.1.dist-info"
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: song-test-plugins\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[song.plugins]\ntest = {MODULE}\n")
    marks = tmp_path / "marks"
    marks.mkdir()
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.setenv("SONG_TEST_PLUGIN_MARKS", str(marks))
    importlib.invalidate_caches()
    loaded = set(plugins._LOADED_ENTRY_POINTS)
    yield marks
    for table in plugins._REGISTRY.values():  # other tests must not see these plugins
        for name in [n for n in table if n in TEST_NAMES]:
            del table[name]
    plugins._LOADED_ENTRY_POINTS.clear()
    plugins._LOADED_ENTRY_POINTS.update(loaded)
    sys.modules.pop(MODULE, None)


def _ran(marks: Path, kind: str) -> set[int]:
    """The processes in which plugins of ``kind`` ran."""
    return {int(p.name.rsplit("-", 1)[1]) for p in marks.glob(f"{kind}-*")}


def _cli(*args: object) -> str:
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


def test_pipeline_plugins_are_found_by_name_in_worker_processes(installed: Path, tmp_path: Path) -> None:
    scenes = tmp_path / "scenes"
    for name in ("a", "b"):
        build_two_room_scene(scenes, name)
    run = tmp_path / "run"
    _cli("synth", "--scenes", scenes, "--out", run, "-j", "2",
         "--set", "crowd.avoidance=test_avoidance", "--set", "intents.llm=test_llm",
         "--set", "motion.generator=test_gait")  # fmt: skip
    for kind in ("avoidance", "llm", "motion_generator", "stage"):
        assert _ran(installed, kind) and os.getpid() not in _ran(installed, kind), kind  # in the workers
    for scene in ("a", "b"):
        folder = run / "scenes" / scene
        assert (folder / "test_count.json").is_file()
        stages = json.loads((folder / "stages.json").read_text())
        assert stages["test_count"]["status"] == "ok" and "crowd" in stages["test_count"]["depends"]
        intents = json.loads((folder / "intents.json").read_text())
        assert intents["provenance"]["provider"] == "test_llm" and intents["provenance"]["fallback"]
        assert "the test provider declines" in intents["llm_error"]
        meta = json.loads(next((folder / "human_amass").glob("traj_*/meta.json")).read_text())
        assert meta["generator"]["requested"] == "test_gait"


def test_runtime_plugins_are_found_by_name_in_worker_processes(installed: Path, tmp_path: Path) -> None:
    out = tmp_path / "eval"
    _cli("eval", "--bench", GOLDEN, "--policy", "test_policy", "--render-backend", "test_backend",
         "--camera-model", "test_camera", "--resolution", "32x24", "--limit", "4", "-j", "2",
         "--out", out)  # fmt: skip
    for kind in ("policy", "sensor", "render_backend", "camera_model"):
        assert _ran(installed, kind) and os.getpid() not in _ran(installed, kind), kind
    assert _ran(installed, "metric")  # the summary is computed where the results are collected
    summary = json.loads((out / "test_policy.json").read_text())
    assert summary["metrics"]["all"]["TEST"] == 4.0
    assert "| TEST |" in (out / "results.md").read_text().splitlines()[0]
    cameras = [s for s in summary["sensors"] if s["name"] == "depth"]
    assert cameras[0]["camera_model"] == "test_camera"


@pytest.mark.parametrize(
    ("setting", "known"),
    [
        ("crowd.avoidance=nope", "orca, social_force"),
        ("intents.llm=nope", "auto, offline, gemini, openai"),
        ("motion.generator=nope", "auto, procedural, kimodo"),
    ],
)
def test_a_config_naming_an_unknown_plugin_fails_before_anything_is_written(tmp_path, setting, known) -> None:
    scenes = tmp_path / "scenes"
    build_two_room_scene(scenes, "a")
    run = tmp_path / "run"
    result = CliRunner().invoke(app, ["synth", "--scenes", str(scenes), "--out", str(run), "--set", setting])
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert setting.split("=")[0] in text and f"known: {known}" in text, text
    assert not run.exists()


def test_unknown_runtime_names_list_the_known_ones(tmp_path: Path) -> None:
    for args, known in (
        (["--policy", "nope"], "straight, astar, social, depth"),
        (["--render-backend", "nope"], "auto, numba, gsplat, reference"),
        (["--camera-model", "nope"], "ideal"),
        (["--sensors", "nope"], "state, scan, pedestrians, map, rgb, depth, rgbd"),
    ):
        result = CliRunner().invoke(app, ["eval", "--bench", str(GOLDEN), "--out", str(tmp_path / "e"), *args])
        text = " ".join(result.output.split())
        assert result.exit_code != 0 and f"known: {known}" in text, (args, text)
    assert not (tmp_path / "e").exists()


def test_a_plugin_from_a_file_path(tmp_path: Path) -> None:
    path = tmp_path / "my_avoidance.py"
    path.write_text("from song.pipeline.crowd.avoidance import SocialForceAvoidance as Model\n")
    scenes = tmp_path / "scenes"
    build_two_room_scene(scenes, "a")
    _cli("synth", "--scenes", scenes, "--out", tmp_path / "run", "--stages", "intents,crowd",
         "--set", f"crowd.avoidance={path}:Model")  # fmt: skip
    stages = json.loads((tmp_path / "run" / "scenes" / "a" / "stages.json").read_text())
    assert stages["crowd"]["settings"]["crowd"]["avoidance"] == f"{path}:Model"


def test_a_sensor_registered_by_the_policys_own_file_works_in_workers(tmp_path: Path) -> None:
    path = tmp_path / "my_policy.py"
    path.write_text(
        textwrap.dedent(
            """
            import numpy as np

            from song.plugins import register
            from song.runtime.sensors import Box, Sensor


            @register("sensor", "file_sensor")
            class FileSensor(Sensor):
                name = "file_sensor"

                def space(self):
                    return Box(0.0, 2.0, (1,), np.float32)

                def observe(self, view):
                    return np.full(1, 2.0, np.float32)


            class Policy:
                sensors = ("state", "file_sensor")

                def reset(self, episode):
                    pass

                def act(self, observation):
                    assert observation["file_sensor"][0] == 2.0
                    return (0.3, 0.0)
            """
        )
    )
    out = tmp_path / "eval"
    _cli("eval", "--bench", GOLDEN, "--policy", f"{path}:Policy", "--limit", "4", "-j", "2", "--out", out)
    summary = json.loads(next(out.glob("*.json")).read_text())
    assert summary["metrics"]["all"]["ERR"] == 0.0 and summary["metrics"]["all"]["n"] == 4
    plugins._REGISTRY["sensor"].pop("file_sensor", None)


def test_collect_records_any_sensor_as_its_declared_space_says(installed: Path, tmp_path: Path) -> None:
    """Features as data: a plugin sensor and a dict space holding images need no code in collect."""
    out = tmp_path / "dataset"
    _cli("collect", "--bench", GOLDEN, "--out", out, "--split", "test", "--policy", "astar", "--limit", "2",
         "--sensors", "state,test_sensor,rgbd", "--resolution", "32x24", "--keep", "all", "-j", "2")  # fmt: skip
    features = json.loads((out / "meta" / "info.json").read_text())["features"]
    assert features["observation.test_sensor"] == {"dtype": "float32", "shape": [1], "names": None}
    assert features["observation.state"]["names"][:3] == ["x", "y", "yaw"]
    assert features["observation.images.rgbd.rgb"]["dtype"] == "video"
    assert features["observation.rgbd.depth"] | {"names": None} == {
        "dtype": "uint16", "shape": [24, 32], "names": None, "info": {"unit": "mm", "no_depth": 0}
    }  # fmt: skip
    import pyarrow.parquet as pq

    table = pq.read_table(next((out / "data").rglob("*.parquet")))
    assert set(table.column("observation.test_sensor").to_pylist()[0]) == {1.0}
    assert np.array(table.column("observation.rgbd.depth").to_pylist()[0]).shape == (24, 32)
    assert len(list((out / "videos").rglob("*.mp4"))) == 1  # the episodes share one video file
