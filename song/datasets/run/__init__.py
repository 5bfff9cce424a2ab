"""The run folder as a typed contract: paths, the crowd table, and typed readers of every artifact.

Stages write these files; later stages, grading, the release export and the pictures read them back
through the readers here, so each name and schema is defined once (docs/contracts.md).
"""

from song.datasets.run.bindings import BindingRecord, Bindings, read_bindings, write_bindings
from song.datasets.run.crowd import (
    CROWD_COLUMNS,
    CROWD_SCHEMA,
    CrowdTracks,
    PedestrianStatus,
    crowd_table,
    read_crowd,
    read_crowd_status,
    read_crowd_table,
    write_crowd,
    write_crowd_status,
)
from song.datasets.run.intents import Intent, IntentSet, Leg, Provenance, RejectedIntent, read_intents
from song.datasets.run.layout import RunFolder, RunInfo, SceneFolder, read_run_info, traj_dir_name, write_run_info

__all__ = [
    "CROWD_COLUMNS",
    "CROWD_SCHEMA",
    "BindingRecord",
    "Bindings",
    "CrowdTracks",
    "Intent",
    "IntentSet",
    "Leg",
    "PedestrianStatus",
    "Provenance",
    "RejectedIntent",
    "RunFolder",
    "RunInfo",
    "SceneFolder",
    "crowd_table",
    "read_bindings",
    "read_crowd",
    "read_crowd_status",
    "read_crowd_table",
    "read_intents",
    "read_run_info",
    "traj_dir_name",
    "write_bindings",
    "write_crowd",
    "write_crowd_status",
    "write_run_info",
]
