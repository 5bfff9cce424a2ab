"""The run folder's layout: every file name and path template of a run, in one place.

A run folder (``song synth --out RUN``) holds::

    RUN/run.json                          RunInfo: config, its sha256, the scenes folder, song version
    RUN/llm_cache/                        LLM replies keyed by (model, prompt, schema)
    RUN/manifest/episodes.parquet         graded episodes (song grade)
    RUN/manifest/summary.json             grading summary
    RUN/scenes/<scene_id>/stages.json     per-stage input hash, outputs + sha256, status
    RUN/scenes/<scene_id>/intents.json    IntentSet (song.datasets.run.intents)
    RUN/scenes/<scene_id>/crowd.parquet   30 FPS crowd table (song.datasets.run.crowd)
    RUN/scenes/<scene_id>/crowd_status.json
    RUN/scenes/<scene_id>/navmesh.npz
    RUN/scenes/<scene_id>/human_amass/traj_<id>/{motion.npz, motion_amass.npz, meta.json}
    RUN/scenes/<scene_id>/binding/{bindings.json, traj_<id>.npz, traj_<id>.materialized.npz}

Stage outputs are recorded in ``stages.json`` relative to the scene folder, so the per-scene names are
relative templates; :class:`SceneFolder` turns them into paths. docs/contracts.md describes the
contents of each file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from pydantic import ValidationError

from song.config import SongConfig
from song.errors import StageError
from song.util import write_json_atomic

RUN_FILE = "run.json"
SCENES_DIR = "scenes"
LLM_CACHE_DIR = "llm_cache"
MANIFEST_DIR = "manifest"
EPISODES_MANIFEST = "manifest/episodes.parquet"
GRADING_SUMMARY = "manifest/summary.json"
LOCK_FILE = ".song.lock"

# per scene, relative to RUN/scenes/<scene_id>/
STAGES_FILE = "stages.json"
INTENTS_FILE = "intents.json"
CROWD_FILE = "crowd.parquet"
CROWD_STATUS_FILE = "crowd_status.json"
NAVMESH_FILE = "navmesh.npz"
AMASS_DIR = "human_amass"
TRAJ_DIR = "human_amass/traj_{ped_id}"
MOTION_FILE = "motion.npz"
AMASS_FILE = "motion_amass.npz"
MOTION_META_FILE = "meta.json"
BINDING_DIR = "binding"
BINDINGS_FILE = "binding/bindings.json"
CACHE_FILE = "binding/traj_{ped_id}.npz"
MATERIALIZED_FILE = "binding/traj_{ped_id}.materialized.npz"


def traj_dir_name(ped_id: int) -> str:
    """``traj_<id>``: the folder name of one pedestrian's motion files."""
    return Path(TRAJ_DIR.format(ped_id=int(ped_id))).name


def traj_ped_id(traj_dir: Path) -> int:
    """The pedestrian id a ``traj_<id>`` folder is named after (the inverse of :func:`traj_dir_name`)."""
    return int(Path(traj_dir).name.split("_", 1)[1])


@dataclass(frozen=True)
class SceneFolder:
    """``RUN/scenes/<scene_id>/``: paths of one scene's artifacts."""

    root: Path

    @property
    def scene_id(self) -> str:
        """The scene id (the folder name)."""
        return self.root.name

    def path(self, rel: str) -> Path:
        """A path relative to the scene folder (as recorded in ``stages.json``)."""
        return self.root / rel

    @property
    def stages(self) -> Path:
        """``stages.json``."""
        return self.root / STAGES_FILE

    @property
    def intents(self) -> Path:
        """``intents.json``."""
        return self.root / INTENTS_FILE

    @property
    def crowd(self) -> Path:
        """``crowd.parquet``."""
        return self.root / CROWD_FILE

    @property
    def crowd_status(self) -> Path:
        """``crowd_status.json``."""
        return self.root / CROWD_STATUS_FILE

    @property
    def navmesh(self) -> Path:
        """``navmesh.npz``."""
        return self.root / NAVMESH_FILE

    @property
    def amass_dir(self) -> Path:
        """``human_amass/``."""
        return self.root / AMASS_DIR

    def traj_dir(self, ped_id: int) -> Path:
        """``human_amass/traj_<id>/``."""
        return self.root / TRAJ_DIR.format(ped_id=int(ped_id))

    def motion_dirs(self) -> list[Path]:
        """Every ``human_amass/traj_<id>/`` holding a motion file, by pedestrian id."""
        found = [p for p in self.amass_dir.glob("traj_*") if (p / MOTION_FILE).is_file()]
        return sorted(found, key=traj_ped_id)

    @property
    def binding_dir(self) -> Path:
        """``binding/``."""
        return self.root / BINDING_DIR

    @property
    def bindings(self) -> Path:
        """``binding/bindings.json``."""
        return self.root / BINDINGS_FILE


@dataclass(frozen=True)
class RunFolder:
    """A run folder: run-level files and the scene folders under ``scenes/``."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def info_file(self) -> Path:
        """``run.json``."""
        return self.root / RUN_FILE

    @property
    def scenes_root(self) -> Path:
        """``scenes/``."""
        return self.root / SCENES_DIR

    @property
    def llm_cache(self) -> Path:
        """``llm_cache/``."""
        return self.root / LLM_CACHE_DIR

    @property
    def episodes_manifest(self) -> Path:
        """``manifest/episodes.parquet``."""
        return self.root / EPISODES_MANIFEST

    @property
    def grading_summary(self) -> Path:
        """``manifest/summary.json``."""
        return self.root / GRADING_SUMMARY

    @property
    def lock_file(self) -> Path:
        """``.song.lock``: held while a synth run writes into the folder."""
        return self.root / LOCK_FILE

    def scene(self, scene_id: str) -> SceneFolder:
        """The folder of one scene."""
        return SceneFolder(self.scenes_root / scene_id)

    def scene_ids(self, having: str | None = None) -> list[str]:
        """Scene ids under ``scenes/``, sorted; only those holding the file ``having`` when given."""
        if not self.scenes_root.is_dir():
            return []
        folders = (p for p in self.scenes_root.iterdir() if p.is_dir())
        return sorted(p.name for p in folders if having is None or (p / having).is_file())


@dataclass(frozen=True)
class RunInfo:
    """``run.json``: what a run was made with.

    Attributes:
        scenes_dir: the scene packages folder (absolute).
        config: the run configuration.
        config_sha256: sha256 of the configuration's canonical JSON.
        song_version: the package version that wrote the run.
    """

    scenes_dir: Path
    config: SongConfig
    config_sha256: str
    song_version: str


def write_run_info(run: RunFolder, info: RunInfo) -> None:
    """Write ``run.json`` atomically."""
    write_json_atomic(
        run.info_file,
        {
            "config": info.config.model_dump(mode="json"),
            "config_sha256": info.config_sha256,
            "scenes_dir": str(info.scenes_dir),
            "song": info.song_version,
        },
    )


def read_run_info(run_dir: str | Path) -> RunInfo:
    """Read ``run.json``; :class:`StageError` naming the file when it is missing or malformed."""
    path = RunFolder(Path(run_dir)).info_file
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return RunInfo(
            scenes_dir=Path(data["scenes_dir"]),
            config=SongConfig.model_validate(data["config"]),
            config_sha256=str(data["config_sha256"]),
            song_version=str(data.get("song", "")),
        )
    except (OSError, ValueError, KeyError, TypeError, ValidationError) as exc:
        raise StageError(f"{path}: not a run folder (run.json missing or unreadable): {exc}") from exc
