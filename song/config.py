"""Typed configuration for every stage; defaults are the paper's values.

One pydantic model per stage, ``extra="forbid"``, every field with a description, a unit and bounds.
:func:`load_config` reads TOML or YAML; :func:`config_hash` is recorded in every output.
Stage owners extend their own section; keep units in field names (``_m``, ``_s``, ``_deg``).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from song.errors import ConfigError

SURFEL_SPACING_M = 0.035  # default Gaussian surfel spacing of synthesised scenes: ~300 k–1 M per indoor scene
DEFAULT_FPS = 30  # pedestrian trajectories and motion (paper: 30 FPS); releases record the value used


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ScenesConfig(_Section):
    """Scene package validation and generation."""

    min_free_area_m2: float = Field(4.0, ge=0.0, description="smallest connected free area, m²")
    min_resolution_m: float = Field(0.01, gt=0.0, description="finest occupancy cell, m")
    max_resolution_m: float = Field(0.5, gt=0.0, description="coarsest occupancy cell, m")
    resolution_m: float = Field(0.05, ge=0.01, le=0.5, description="cell size written by importers, m")
    wall_thickness_m: float = Field(0.1, gt=0.0, le=0.5, description="thickness of imported walls, m")


class IntentsConfig(_Section):
    """Semantic intent generation (paper: "Semantic intent generation")."""

    llm: str = Field(
        "auto",
        description="auto (gemini when a key is set, else offline), offline, or an `llm` plugin (gemini, openai)",
    )
    gemini_model: str = Field(
        "gemini-3.5-flash",
        description="a stable Gemini model id of the v1beta API (docs/quickstart.md, Intents with an LLM)",
    )
    openai_base_url: str = Field("http://127.0.0.1:8000/v1", description="OpenAI-compatible server")
    openai_model: str = Field("local-model", description="model name sent to the OpenAI-compatible server")
    timeout_s: float = Field(60.0, gt=0.0, description="per-request timeout, s")
    max_retries: int = Field(4, ge=0, le=10, description="retries on 408/429/5xx/timeouts")
    backoff_base_s: float = Field(1.0, ge=0.0, description="first back-off delay, s (doubles, with jitter)")
    max_concurrency: int = Field(4, ge=1, le=64, description="simultaneous LLM requests across scenes")
    density_per_m2: float = Field(0.05, gt=0.0, description="pedestrians per m² of navigable area")
    min_pedestrians: int = Field(2, ge=1, description="fewest pedestrians per scene")
    max_pedestrians: int = Field(12, ge=1, le=256, description="most pedestrians per scene")
    min_path_m: float = Field(2.0, ge=0.0, description="shortest accepted geodesic route, m")
    max_path_m: float = Field(40.0, gt=0.0, description="longest accepted geodesic route, m")
    min_spawn_separation_m: float = Field(0.8, ge=0.0, description="no two starts closer than this, m")
    speed_profile: Literal["paper", "human"] = Field(
        "paper", description="paper: uniform in [speed_min, speed_max]; human: normal(1.3, 0.2) clipped to 0.8-1.8 m/s"
    )
    speed_min_mps: float = Field(0.5, gt=0.0, description="pedestrian speed lower bound, m/s (paper)")
    speed_max_mps: float = Field(1.0, gt=0.0, description="pedestrian speed upper bound, m/s (paper)")
    lead_in_s: float = Field(
        12.0, ge=0.0, le=60.0, description="first departures drawn from -this on: at t = 0 some are already walking, s"
    )
    max_depart_s: float = Field(8.0, ge=0.0, description="first departures drawn in [-lead_in_s, this], s")
    scenario_s: float = Field(60.0, gt=0.0, description="routines are chained to keep people busy this long, s")
    max_legs: int = Field(4, ge=1, le=8, description="most legs (object-to-object walks) in one routine")
    group_share: float = Field(
        0.0,
        ge=0.0,
        lt=1.0,
        description="share of pedestrians walking with others, in groups of 2-4 (0: everyone alone; docs/crowd.md)",
    )


class CrowdConfig(_Section):
    """Navmesh + ORCA crowd planning (paper: Recast/DetourCrowd)."""

    fps: int = Field(DEFAULT_FPS, ge=1, le=240, description="simulation and output rate, frames/s (paper: 30)")
    avoidance: str = Field(
        "orca",
        description="local-avoidance model: an `avoidance` plugin (orca, social_force, or module:Class; docs/crowd.md)",
    )
    agent_radius_m: float = Field(
        0.25,
        gt=0.0,
        le=1.0,
        description="navmesh clearance from walls and the largest body radius, m (everyone's body radius when "
        "radius_from_avatar is false)",
    )
    radius_from_avatar: bool = Field(
        True,
        description="each pedestrian keeps others clear by its own avatar's body radius, scaled to its height "
        "(at most agent_radius_m; docs/crowd.md)",
    )
    comfort_distance_m: float = Field(
        1.0, ge=0.0, le=3.0, description="centre distance people keep when passing in open space, m (≥ 2 × radius)"
    )
    wall_comfort_m: float = Field(
        0.1, ge=0.0, le=1.0, description="extra distance kept from walls when there is room, m"
    )
    neighbor_dist_m: float = Field(5.0, gt=0.0, description="ORCA neighbour search distance, m")
    max_neighbors: int = Field(10, ge=1, description="ORCA neighbours considered per agent")
    time_horizon_s: float = Field(
        2.0, gt=0.0, description="ORCA agent time horizon: collisions of personal space kept out this long, s"
    )
    anticipation_s: float = Field(
        4.0, gt=0.0, description="how far ahead walkers predict passes and start to swerve, s (docs/crowd.md)"
    )
    time_horizon_obst_s: float = Field(1.0, gt=0.0, description="ORCA obstacle time horizon, s")
    max_accel_mps2: float = Field(
        2.0, gt=0.0, description="acceleration limit of the speed (setting off, stopping, turning back), m/s²"
    )
    turn_accel_mps2: float = Field(
        1.0, gt=0.0, description="sideways acceleration limit in a turn of up to 90°, m/s² (docs/crowd.md)"
    )
    max_duration_s: float = Field(120.0, gt=0.0, description="longest simulated scenario, s")
    stall_time_s: float = Field(2.0, gt=0.0, description="no progress for this long = stalled, s")
    start_jitter_m: float = Field(0.03, ge=0.0, le=0.2, description="start jitter breaking symmetry, m")
    contour_error_m: float = Field(0.05, ge=0.0, description="contour simplification tolerance, m")
    give_up_in_hindsight: bool = Field(
        True,
        description="a walker that gives a stop up does so at its first stall on the way there, not after "
        "its tries (the plan is simulated again with that decision; docs/crowd.md)",
    )
    queue_at_passages: bool = Field(
        False,
        description="wait clear of a passage too narrow to pass in while it is used the other way (docs/crowd.md)",
    )


class MotionConfig(_Section):
    """Full-body motion (paper: Kimodo + trajectory-consistency post-processing)."""

    generator: str = Field(
        "auto", description="auto (kimodo when usable, else procedural) or a `motion_generator` plugin"
    )
    prompt: str = Field(
        "A person is casually walking forward at a natural pace with minimal waist sway",
        description="Kimodo text prompt (paper appendix)",
    )
    walk_ratio_m_s: float = Field(
        0.38, ge=0.3, le=0.45, description="walk ratio WR = L/f, m·s, of a person of the mean height (1.71 m)"
    )
    min_cadence_spm: float = Field(85.0, gt=0.0, description="lowest cadence, steps/min")
    height_min_m: float = Field(1.50, ge=1.0, description="smallest body height, m")
    height_max_m: float = Field(1.95, le=2.3, description="largest body height, m")
    contact_height_m: float = Field(0.05, gt=0.0, description="foot contact height threshold, m")
    contact_speed_mps: float = Field(0.2, gt=0.0, description="foot contact speed threshold, m/s")
    smoothing_sigma_frames: float = Field(
        1.0, ge=0.0, le=10.0, description="post-processing Gaussian smoothing of root and rotations, frames"
    )
    lock_blend_frames: int = Field(4, ge=0, le=15, description="foot-lock blend in/out around a contact, frames")
    kimodo_model: str = Field("kimodo-soma-rp", description="Kimodo model name (short key or display name)")
    kimodo_steps: int = Field(100, ge=1, le=1000, description="Kimodo DDIM denoising steps")
    kimodo_batch_size: int = Field(16, ge=1, le=256, description="pedestrians per batched Kimodo call")
    kimodo_max_frames: int = Field(
        300,
        ge=30,
        le=300,
        description="longest generated Kimodo window, frames (its 10 s limit); longer tracks use multi-prompt",
    )
    kimodo_postprocess: bool = Field(True, description="also run Kimodo's own foot-skate post-processing")
    kimodo_embedding_cache: str = Field(
        "", description="folder of cached prompt embeddings (empty: $SONG_KIMODO_EMBEDDINGS or ~/.cache/song)"
    )


class BindingConfig(_Section):
    """Avatar pool and LBS caches (paper: motion and avatar binding)."""

    n_gaussians: int = Field(40_000, ge=5_000, le=100_000, description="Gaussians per procedural avatar")
    pool_size: int = Field(128, ge=1, description="identities in the default (generated, cached) avatar pool")
    pool_seed: int = Field(0, description="seed of the default avatar pool")
    avatars_dir: str = Field(
        "", description="folder of *.avatar.npz assets to bind (empty: the default pool under $SONG_CACHE_DIR)"
    )
    materialize: bool = Field(False, description="also write the paper's FP16 per-frame Gaussian cache")


class GradingConfig(_Section):
    """Episode sampling and difficulty grading (paper: episode generation and difficulty grading)."""

    n_episodes: int = Field(500, ge=1, description="episodes in the benchmark (paper: 500)")
    hard_fraction: float = Field(0.2, ge=0.0, le=1.0, description="paper: 100 of 500")
    medium_fraction: float = Field(0.4, ge=0.0, le=1.0, description="paper: 200 of 500")
    robot_radius_m: float = Field(0.2, gt=0.0, description="robot radius for traversability, m")
    path_margin_m: float = Field(
        0.1, ge=0.0, description="extra clearance kept by the A* path beyond the robot radius, m"
    )
    start_clearance_m: float = Field(1.0, ge=0.0, description="no pedestrian this close to the start at t0, m")
    robot_speed_mps: float = Field(0.5, gt=0.0, description="nominal robot speed for T* and encounters, m/s")
    near_ped_m: float = Field(2.0, gt=0.0, description="co/counter-directional endpoint distance, m")
    encounter_pass_m: float = Field(1.0, gt=0.0, description="encounter mode: closest pass, m")
    min_angle_deg: float = Field(90.0, ge=0.0, le=180.0, description="subtended angle at circle centre, deg")
    turn_threshold_deg: float = Field(40.0, gt=0.0, description="significant heading change, deg")
    encounter_radius_m: float = Field(3.0, gt=0.0, description="encounter factor radius, m")
    width_sample_m: float = Field(0.1, gt=0.0, description="corridor-width sampling step, m")
    max_tries: int = Field(200, ge=1, description="rejection-sampling attempts per episode and mode")
    min_path_m: float = Field(2.0, ge=0.0, description="shortest episode path L*, m")
    max_path_m: float = Field(7.0, gt=0.0, description="longest L*, m (T* = 14 s leaves slack within T_max = 20 s)")


class RobotConfig(_Section):
    """Robot and evaluation loop (paper: Setup)."""

    max_speed_mps: float = Field(0.5, gt=0.0, description="linear speed limit, m/s")
    max_yaw_rate_deg_s: float = Field(45.0, gt=0.0, description="angular speed limit, deg/s")
    control_hz: float = Field(10.0, gt=0.0, description="control rate, Hz")
    max_steps: int = Field(200, ge=1, description="T_max, steps")
    goal_radius_m: float = Field(1.0, gt=0.0, description="success distance, m")
    max_obstacle_collisions: int = Field(5, ge=1, description="δ_obs: failure at this many, count")
    radius_m: float = Field(0.2, gt=0.0, description="collision radius, m")
    collision_height_m: float = Field(0.8, ge=0.0, description="centre height of the collision volume, m")
    collision_volume: Literal["sphere", "cylinder"] = Field("sphere", description="avatar collision volume")
    eta_col: int = Field(5, ge=0, description="η_col: collision when Gaussian count exceeds this")
    psc_threshold_m: float = Field(0.5, gt=0.0, description="personal-space threshold, m")
    stuck_steps: int = Field(10, ge=1, description="no motion for this many steps = stuck, steps")
    fov_deg: float = Field(70.0, gt=0.0, le=360.0, description="horizontal field of view, deg")


class CameraConfig(_Section):
    """RGB-D camera of the paper's setup (declared for a renderer backend)."""

    height_m: float = Field(0.8, ge=0.0, description="camera height, m")
    hfov_deg: float = Field(70.0, gt=0.0, lt=180.0, description="horizontal field of view, deg")
    near_m: float = Field(0.01, gt=0.0, description="near plane, m")
    far_m: float = Field(100.0, gt=0.0, description="far plane, m")
    width_px: int = Field(960, ge=1, description="image width, px")
    height_px: int = Field(540, ge=1, description="image height, px")
    model: str = Field("ideal", description="camera model: ideal (the paper) | d435i | a camera_model plugin")


class SongConfig(_Section):
    """Everything a run needs. ``seed`` is the one run seed."""

    seed: int = Field(0, ge=0, description="run seed")
    scenes: ScenesConfig = ScenesConfig()
    intents: IntentsConfig = IntentsConfig()
    crowd: CrowdConfig = CrowdConfig()
    motion: MotionConfig = MotionConfig()
    binding: BindingConfig = BindingConfig()
    grading: GradingConfig = GradingConfig()
    robot: RobotConfig = RobotConfig()
    camera: CameraConfig = CameraConfig()


def config_value(config: BaseModel, key: str) -> Any:
    """The JSON value of a dotted config key (``"crowd"`` or ``"crowd.agent_radius_m"``).

    Raises:
        ConfigError: no such section or field.
    """
    value: Any = config
    for part in key.split("."):
        if not isinstance(value, BaseModel) or part not in type(value).model_fields:
            raise ConfigError("<config>", key, "no such config section or field")
        value = getattr(value, part)
    return value.model_dump(mode="json") if isinstance(value, BaseModel) else value


def config_differences(old: BaseModel, new: BaseModel) -> list[tuple[str, Any, Any]]:
    """``(dotted key, old value, new value)`` for every leaf setting that differs, sorted by key."""

    def leaves(data: Any, prefix: str = "") -> dict[str, Any]:
        if isinstance(data, dict):
            out: dict[str, Any] = {}
            for key, value in data.items():
                out.update(leaves(value, f"{prefix}{key}."))
            return out
        return {prefix[:-1]: data}

    a, b = leaves(old.model_dump(mode="json")), leaves(new.model_dump(mode="json"))
    return [(k, a.get(k), b.get(k)) for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]


def config_hash(config: BaseModel) -> str:
    """sha256 of a config's canonical JSON; written into every output that the config shaped."""
    from song.util import sha256_json  # numpy and friends: not needed to read a config

    return sha256_json(config.model_dump(mode="json"))


def read_config_mapping(path: str | Path) -> dict[str, Any]:
    """The raw mapping of a TOML/YAML config file (not validated: :func:`load_config` does that)."""
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(path, "", f"cannot read config: {exc}") from exc
    try:
        if suffix == ".toml":
            data = tomllib.loads(text)
        elif suffix in (".yaml", ".yml"):
            import yaml

            data = yaml.safe_load(text) or {}
        else:
            raise ConfigError(path, "", "expected a .toml, .yaml or .yml file")
    except ConfigError:
        raise
    except Exception as exc:  # tomllib / yaml parse errors
        raise ConfigError(path, "", f"not valid {suffix[1:].upper()}: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(path, "", "expected a mapping at the top level")
    return data


def parse_assignments(assignments: list[str]) -> dict[str, Any]:
    """``["crowd.agent_radius_m=0.3", "intents.llm=offline"]`` → ``{"crowd": {"agent_radius_m": 0.3}, ...}``.

    Values are read as JSON when they parse (numbers, booleans, lists), else kept as strings. Nothing is
    validated here beyond the form; :func:`load_config` validates the merged result.

    Raises:
        ConfigError: an assignment is not ``section.key=value`` or ``key=value``.
    """
    import json

    out: dict[str, Any] = {}
    for text in assignments:
        key, sep, raw = text.partition("=")
        parts = key.strip().split(".")
        if not sep or not all(p.isidentifier() for p in parts) or len(parts) > 2:
            raise ConfigError("--set", text, "expected SECTION.KEY=VALUE (e.g. crowd.agent_radius_m=0.3)")
        try:
            value = json.loads(raw)
        except ValueError:
            value = raw
        if len(parts) == 1:
            out[parts[0]] = value
        else:
            section = out.setdefault(parts[0], {})
            if not isinstance(section, dict):
                raise ConfigError("--set", text, f"'{parts[0]}' is set both as a value and as a section")
            section[parts[1]] = value
    return out


def load_config(path: str | Path | None = None, **overrides: Any) -> SongConfig:
    """Load a :class:`SongConfig` from TOML/YAML (or defaults when ``path`` is None).

    ``overrides`` are top-level keys (``seed=3``) or ``section={...}`` dicts merged over the file.
    Raises :class:`ConfigError` naming the file and the first bad field.
    """
    data: dict[str, Any] = {} if path is None else read_config_mapping(path)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    try:
        return SongConfig.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        field = ".".join(str(part) for part in first["loc"])
        raise ConfigError(path or "<config>", field, first["msg"]) from exc
