"""``song eval``: run a policy over a release's episodes; per-episode Parquet + summary.

Every result file records what produced it: the release (version, schema, fingerprint), the policy,
the sensors with their parameters, the runtime parameters used, and any override of the release's
recorded parameters (results with overrides are marked ``"official": false``).
"""

from __future__ import annotations

import dataclasses
import io
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from song import plugins
from song.datasets.bench import Benchmark, Episode, open_benchmark
from song.datasets.bench.schema import DIFFICULTIES
from song.datasets.bench.types import RuntimeParams
from song.parallel import parallel_map
from song.runtime.ablation import without_avatars
from song.runtime.guard import DEFAULT_STEP_TIMEOUT_S
from song.runtime.isolate import IsolatedPolicy
from song.runtime.loop import EpisodeResult, reactive_setup, run_episode
from song.runtime.metrics import aggregate, markdown_table
from song.runtime.policies import load_policy, policy_info, policy_sensors
from song.runtime.sensors import SensorSuite, parse_sensor_names
from song.util import write_bytes_atomic, write_json_atomic, write_text_atomic

ABLATION_SUFFIX = " (no avatars)"  # how an avatar-free ablation's rows are labelled beside their policy's
REACTIVE_SUFFIX = " (reactive pedestrians)"  # and the rows of a run with reactive pedestrians
RESULTS_SCHEMA = pa.schema(
    [
        ("episode_id", pa.string()),
        ("scene_id", pa.string()),
        ("difficulty", pa.string()),
        ("policy", pa.string()),
        ("outcome", pa.string()),
        ("steps", pa.int32()),
        ("time", pa.float64()),
        ("length", pa.float64()),
        ("optimal_length", pa.float64()),
        ("optimal_time", pa.float64()),
        ("obstacle_collisions", pa.int32()),
        ("max_gaussian_count", pa.int32()),
        ("psc", pa.float64()),
        ("min_distance", pa.float64()),
        ("jerk", pa.float64()),
        ("trajectory", pa.list_(pa.list_(pa.float64(), 3))),
        ("events", pa.list_(pa.struct([("step", pa.int32()), ("kind", pa.string())]))),
        ("error", pa.string()),
    ]
)


@dataclass(frozen=True)
class EvalSetup:
    """How a policy is evaluated: its sensors and the runtime parameters (with what was overridden).

    Attributes:
        policy: a baseline name or ``module:Class``.
        sensors: the sensor names the policy receives.
        params: the effective runtime parameters.
        overrides: ``{"robot.max_speed_mps": [release value, used value], ...}``; empty for official runs.
        sensor_options: per-sensor keyword options.
        step_timeout_s: the longest one ``reset``/``act`` call may take before its episode fails.
        isolate: run the policy in a process of its own (:mod:`song.runtime.isolate`).
        no_avatars: the avatar-free ablation: the same episodes without pedestrians (neither rendered
            nor colliding; results are not official).
        policy_info: how the policy is driven (its kind, and a waypoint policy's rate and tracker).
        reactive: pedestrians near the robot avoid it (:mod:`song.runtime.reactive`): not a replay, so
            not the official protocol; results record the mode.
    """

    policy: str
    sensors: tuple[str, ...]
    params: RuntimeParams
    overrides: dict[str, list[Any]] = field(default_factory=dict)
    sensor_options: dict[str, dict] = field(default_factory=dict)
    step_timeout_s: float = DEFAULT_STEP_TIMEOUT_S
    isolate: bool = False
    no_avatars: bool = False
    policy_info: dict[str, Any] = field(default_factory=dict)
    reactive: bool = False

    @property
    def label(self) -> str:
        """The name results are filed under: the policy, marked for the ablation and for reactive pedestrians."""
        return self.policy + (ABLATION_SUFFIX if self.no_avatars else "") + (REACTIVE_SUFFIX if self.reactive else "")


def make_setup(
    bench: Benchmark,
    policy: str,
    sensors: str | list[str] | None = None,
    params: RuntimeParams | None = None,
    overrides: dict[str, list[Any]] | None = None,
    camera: dict[str, Any] | None = None,
    step_timeout_s: float = DEFAULT_STEP_TIMEOUT_S,
    allow_modified: bool = False,
    isolate: bool = False,
    no_avatars: bool = False,
    reactive: bool = False,
) -> EvalSetup:
    """The setup of one policy; a release that no longer matches its fingerprint is refused first.

    Args:
        bench: the opened release.
        policy: a baseline name or ``module:Class``.
        sensors: extra sensors shown to the policy besides the ones it declares.
        params: runtime parameters (default: the release's).
        overrides: what ``params`` changed from the release, as recorded.
        camera: options shared by the camera sensors: ``width``, ``height``, ``backend``.
        step_timeout_s: per-call time limit of the policy (its episode fails past it).
        allow_modified: run on a release that fails :attr:`Benchmark.integrity` (results unofficial).
        isolate: run the policy in a process of its own; its code never runs in this one.
        no_avatars: run the avatar-free ablation (:func:`song.runtime.ablation.without_avatars`).
        reactive: pedestrians near the robot avoid it (:mod:`song.runtime.reactive`; not official).
    """
    bench.require_intact(allow_modified)
    if isolate:  # the policy's code (its module too) runs only in its own process
        probe = IsolatedPolicy(policy, step_timeout_s)
        declared, info, _ = probe.sensors, probe.info, probe.close()
    else:
        loaded = load_policy(policy)
        declared, info = policy_sensors(loaded), policy_info(loaded)
    names = parse_sensor_names([*declared, *parse_sensor_names(sensors or [])])
    options = {"camera": dict(camera)} if camera else {}
    plugins.check_name("render_backend", options.get("camera", {}).get("backend", "auto"), extra=("auto",))
    params = params or bench.params
    model = options.get("camera", {}).get("model") or params.camera.model
    plugins.check_name("camera_model", model)
    overrides = dict(overrides or {})
    if model != bench.params.camera.model:  # another sensor than the release's: not the official protocol
        overrides["camera.model"] = [bench.params.camera.model, model]
    return EvalSetup(policy, names, params, overrides, options, step_timeout_s, isolate, no_avatars, info, reactive)


@dataclass(frozen=True)
class EvalJob:
    """One episode of one policy (picklable for worker processes)."""

    bench: str
    episode_id: str
    setup: EvalSetup


def _run_job(job: EvalJob, cache: dict[str, Benchmark] = {}) -> EpisodeResult:  # noqa: B006 - per-process cache
    if job.bench not in cache:
        cache[job.bench] = open_benchmark(job.bench)
    bench = cache[job.bench]
    setup = job.setup
    episode = dataclasses.replace(bench.episode(job.episode_id), params=setup.params)
    if setup.no_avatars:
        episode = without_avatars(episode)
    if setup.isolate:  # the child enforces the step limit itself (and is killed past it)
        policy, limit = _isolated(setup), None
    else:
        policy, limit = load_policy(setup.policy), setup.step_timeout_s  # first: it may register its sensors
    sensors = SensorSuite.build(setup.sensors, setup.params, bench.max_pedestrians, setup.sensor_options)
    episode, collider, crowd = reactive_setup(episode, setup.reactive)
    return run_episode(episode, policy, collider, sensors, step_timeout_s=limit, crowd=crowd)


_ISOLATED: dict[tuple[str, float], IsolatedPolicy] = {}


def _isolated(setup: EvalSetup) -> IsolatedPolicy:
    """This worker's child process for the policy (kept across episodes; restarted after a kill)."""
    key = (setup.policy, setup.step_timeout_s)
    if key not in _ISOLATED:
        _ISOLATED[key] = IsolatedPolicy(setup.policy, setup.step_timeout_s)
    return _ISOLATED[key]


def iter_eval(
    bench: Benchmark, setup: EvalSetup | str, episodes: list[Episode] | None = None, workers: int = 1
) -> Iterator[EpisodeResult]:
    """Evaluate a policy on every episode (or ``episodes``); results stream in completion order."""
    setup = make_setup(bench, setup) if isinstance(setup, str) else setup
    ids = [e.episode_id for e in episodes] if episodes is not None else bench.episode_ids()
    jobs = [EvalJob(str(bench.root), eid, setup) for eid in ids]
    yield from parallel_map(_run_job, jobs, workers)


def results_table(results: list[EpisodeResult], policy: str) -> pa.Table:
    """Per-episode results, sorted by episode id (deterministic bytes for a deterministic policy)."""
    rows = []
    for r in sorted(results, key=lambda r: r.episode_id):
        m = r.metrics
        rows.append(
            {
                "episode_id": r.episode_id,
                "scene_id": r.scene_id,
                "difficulty": r.difficulty,
                "policy": policy,
                "outcome": r.outcome,
                "steps": r.steps,
                "time": m.time,
                "length": m.length,
                "optimal_length": m.optimal_length,
                "optimal_time": m.optimal_time,
                "obstacle_collisions": r.obstacle_collisions,
                "max_gaussian_count": r.max_gaussian_count,
                "psc": m.psc,
                "min_distance": m.min_distance,
                "jerk": m.jerk,
                "trajectory": r.trajectory.tolist(),
                "events": [{"step": step, "kind": kind} for step, kind in r.events],
                "error": r.error,
            }
        )
    return pa.Table.from_pylist(rows, RESULTS_SCHEMA)


def summarize(results: list[EpisodeResult]) -> dict[str, dict[str, float]]:
    """The metric row per difficulty (easy, medium, hard) and overall."""
    by = {}
    for difficulty in DIFFICULTIES:
        subset = [r.metrics for r in results if r.difficulty == difficulty]
        if subset:
            by[difficulty] = aggregate(subset)
    by["all"] = aggregate([r.metrics for r in results])
    return by


def provenance(bench: Benchmark, setup: EvalSetup) -> dict[str, Any]:
    """What produced a set of results: release, policy, sensors, parameters, overrides."""
    sensors = SensorSuite.build(setup.sensors, setup.params, bench.max_pedestrians, setup.sensor_options)
    return {
        "release": {
            "path": str(bench.root),
            "version": bench.version,
            "schema_version": bench.info.schema_version,
            "fingerprint": bench.info.fingerprint,
        },
        "policy": setup.policy,
        **(setup.policy_info or {"policy_kind": "commands"}),
        "sensors": sensors.describe(),
        "privileged": sensors.privileged,  # any sensor a real robot could not have (other agents' true states)
        "params": setup.params.to_json(),
        "overrides": setup.overrides,
        "official": not setup.overrides and not bench.integrity and not setup.no_avatars and not setup.reactive,
        "ablation": "no_avatars" if setup.no_avatars else None,
        "pedestrians": "reactive" if setup.reactive else "replay",
        "release_check": bench.integrity or "ok",  # the fingerprint, info.json and the tables, checked at open
        "step_timeout_s": setup.step_timeout_s,
        "policy_process": "isolated" if setup.isolate else "in-process",
    }


def results_stem(policy: str, no_avatars: bool = False, reactive: bool = False) -> str:
    """The file name (without extension) a policy's results go to: marked for the ablation and for reactive pedestrians."""
    return (
        policy.replace(":", "_").replace("/", "_")
        + ("-no-avatars" if no_avatars else "")
        + ("-reactive" if reactive else "")
    )


def write_results(out_dir: Path, setup: EvalSetup, results: list[EpisodeResult], bench: Benchmark) -> dict[str, Any]:
    """Write ``<policy>.parquet``, ``<policy>.json`` and ``<policy>.md`` into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    safe = results_stem(setup.policy, setup.no_avatars, setup.reactive)
    about = provenance(bench, setup)
    table = results_table(results, setup.label)
    table = table.replace_schema_metadata({b"song.eval": json.dumps(about, sort_keys=True).encode()})
    buffer = io.BytesIO()
    pq.write_table(table, buffer, compression="zstd")
    write_bytes_atomic(out_dir / f"{safe}.parquet", buffer.getvalue())
    summary = {**about, "benchmark": str(bench.root), "version": bench.version, "metrics": summarize(results)}
    write_json_atomic(out_dir / f"{safe}.json", summary)  # strict JSON: non-finite metrics are null
    write_text_atomic(out_dir / f"{safe}.md", markdown_table({setup.label: summary["metrics"]}))
    return summary


def results_in(out_dir: Path, latest: dict[str, dict] | None = None) -> dict[str, dict]:
    """The metric rows of every results file in ``out_dir`` (plus ``latest``), each variant after its main row.

    A file that is not a results summary is skipped; ``latest`` wins over a file of the same label.
    """
    rows: dict[str, dict] = {}
    for path in sorted(out_dir.glob("*.json")):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            label = data["policy"] + (ABLATION_SUFFIX if data.get("ablation") == "no_avatars" else "")
            label += REACTIVE_SUFFIX if data.get("pedestrians") == "reactive" else ""
            rows[label] = {  # strict JSON stores a non-finite metric as null
                d: {k: float("nan") if v is None else v for k, v in row.items()} for d, row in data["metrics"].items()
            }
        except (OSError, ValueError, KeyError, TypeError):
            continue
    rows.update(latest or {})
    order = {d: k for k, d in enumerate((*DIFFICULTIES, "all"))}
    ordered = {
        label: dict(sorted(by.items(), key=lambda kv: order.get(kv[0], len(order)))) for label, by in rows.items()
    }

    def key(label: str) -> tuple[str, bool, bool]:
        base = label.removesuffix(REACTIVE_SUFFIX)
        return base.removesuffix(ABLATION_SUFFIX), base.endswith(ABLATION_SUFFIX), label.endswith(REACTIVE_SUFFIX)

    return dict(sorted(ordered.items(), key=lambda kv: key(kv[0])))
