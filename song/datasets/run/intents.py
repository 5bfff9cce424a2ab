"""The intents stage's artifact: ``intents.json``.

CONTRACT: later stages, the release export and the pictures read it with :func:`read_intents`; the
fields below are stable within ``schema_version``.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from song.datasets.run.layout import INTENTS_FILE
from song.errors import StageError

INTENTS_SCHEMA_VERSION = 3  # 2: routines of several legs with dwell times; 3: departures before t = 0


class Provenance(BaseModel):
    """Who proposed an intent."""

    model_config = ConfigDict(extra="forbid")
    provider: str = Field(description="offline, or the `llm` plugin that proposed the routines (gemini, openai, ...)")
    model: str
    fallback: bool = Field(False, description="True when the LLM failed and the offline model was used")
    prompt_sha256: str = ""


class Leg(BaseModel):
    """One walk of a routine: to an object, then a stay there."""

    model_config = ConfigDict(extra="forbid")
    activity: str
    goal_object: str
    goal_xy: tuple[float, float]
    geodesic_m: float = Field(0.0, ge=0.0, description="grid shortest-path length from the previous stop, m")
    dwell_s: float = Field(0.0, ge=0.0, description="time spent at the goal before the next leg (0 on the last), s")


class Intent(BaseModel):
    """One executable pedestrian routine. Points are world metres (Z-up), times seconds.

    ``legs`` is the whole routine, in order; ``activity``, ``goal_object``, ``goal_xy`` and
    ``geodesic_m`` repeat its first leg. After its last leg a pedestrian stands at that goal.
    """

    model_config = ConfigDict(extra="forbid")
    id: int = Field(..., ge=0, description="pedestrian id within the scene")
    activity: str
    start_object: str
    goal_object: str
    start_xy: tuple[float, float]
    goal_xy: tuple[float, float]
    speed: float = Field(..., gt=0.0, description="preferred walking speed, m/s")
    depart_time: float = Field(
        ..., ge=-600.0, description="departure time, s from the scenario's start (< 0: already on its way at t = 0)"
    )
    geodesic_m: float = Field(0.0, ge=0.0, description="grid shortest-path length start→goal, m")
    provenance: Provenance
    legs: list[Leg] = Field(default_factory=list, description="the routine's legs, the first one included")
    group: int | None = Field(
        None, ge=0, description="id of the pedestrian this one walks with (its group's leader; the leader's own id)"
    )

    def route(self) -> list[Leg]:
        """The legs of the routine (a single leg built from the fields above when ``legs`` is empty)."""
        if self.legs:
            return list(self.legs)
        return [
            Leg(activity=self.activity, goal_object=self.goal_object, goal_xy=self.goal_xy, geodesic_m=self.geodesic_m)
        ]


class RejectedIntent(BaseModel):
    """A raw proposal that did not become an intent, with a reason code."""

    model_config = ConfigDict(extra="forbid")
    activity: str = ""
    start_object: str = ""
    goal_object: str = ""
    reason: str = Field(..., description="unknown_object | unreachable | too_short | too_long | duplicate | ...")
    detail: str = ""


class IntentSet(BaseModel):
    """Everything the intents stage decided for one scene."""

    model_config = ConfigDict(extra="forbid")
    schema_version: int = INTENTS_SCHEMA_VERSION
    scene_id: str
    provenance: Provenance
    description: str = Field("", description="prompt A's human-centric scene description")
    intents: list[Intent]
    rejected: list[RejectedIntent] = []
    llm_error: str = Field("", description="why the LLM path fell back to the offline model, if it did")
    notes: list[str] = Field(
        [], description="why the scene yields no (or fewer) pedestrians, when it is the scene's fault"
    )

    def by_id(self) -> dict[int, Intent]:
        """Kept intents keyed by pedestrian id."""
        return {intent.id: intent for intent in self.intents}


def read_intents(path: str | Path) -> IntentSet:
    """Read ``intents.json`` (a file, or the scene folder holding it).

    Raises:
        StageError: unreadable, malformed, or written by another schema version (with what to do).
    """
    import json

    path = Path(path)
    if path.is_dir():
        path = path / INTENTS_FILE
    try:
        raw = path.read_bytes()
        version = json.loads(raw).get("schema_version")
    except (OSError, ValueError, AttributeError) as exc:
        raise StageError(f"{path}: cannot read intents: {exc}") from exc
    if version != INTENTS_SCHEMA_VERSION:
        raise StageError(
            f"{path}: intents schema_version {version} is not {INTENTS_SCHEMA_VERSION} (departures before the "
            "scenario start since 3); re-run the intents stage: `song rerun intents --run RUN` (or `song synth`, it resumes)"
        )
    try:
        return IntentSet.model_validate_json(raw)
    except ValueError as exc:
        raise StageError(f"{path}: cannot read intents: {exc}") from exc
