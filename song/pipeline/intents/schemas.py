"""Response schemas of prompts A and B (structured LLM output), versioned with the prompts."""

from __future__ import annotations

from importlib import resources

from pydantic import BaseModel, ConfigDict, Field

PROMPT_VERSION = "v1"
SCHEMA_VERSION = 1


class SceneDescription(BaseModel):
    """Prompt A's answer."""

    model_config = ConfigDict(extra="forbid")
    description: str = Field(..., description="human-centric scene description, objects referred to by id")


class Routine(BaseModel):
    """One selected movement routine."""

    model_config = ConfigDict(extra="forbid")
    start_object: str = Field(..., description="object id where the pedestrian starts")
    goal_object: str = Field(..., description="object id the pedestrian walks to")
    activity: str = Field(..., description="short activity phrase")


class RoutineSelection(BaseModel):
    """Prompt B's answer."""

    model_config = ConfigDict(extra="forbid")
    routines: list[Routine]


def load_prompt(name: str) -> str:
    """A prompt template from package data (``prompts/<version>/<name>.txt``)."""
    return resources.files("song.pipeline.intents").joinpath(f"prompts/{PROMPT_VERSION}/{name}.txt").read_text()
