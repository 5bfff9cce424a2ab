"""Runtime parameters: the release's recorded values, and explicit, recorded overrides.

The release (``meta/info.json``) is the single source of the robot, camera and pedestrian parameters
the runtime uses. A user may evaluate with other values (a faster robot, another camera) only by
saying so: :func:`apply_overrides` refuses changed values unless ``allow`` is set, and returns what
changed so that the results record it next to the release fingerprint (such results are marked
unofficial).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from pydantic import ValidationError

from song.config import CameraConfig, RobotConfig
from song.datasets.bench.types import RuntimeParams
from song.errors import ConfigError

OVERRIDABLE = {"robot": RobotConfig, "camera": CameraConfig}


def apply_overrides(
    params: RuntimeParams, overrides: dict[str, Any], allow: bool, source: str = "<overrides>"
) -> tuple[RuntimeParams, dict[str, list[Any]]]:
    """The effective parameters and the values that differ from the release's.

    Args:
        params: the release's recorded parameters.
        overrides: ``{"robot": {...}, "camera": {...}}`` from a config file or ``--set``; other
            sections (synthesis settings) are ignored here.
        allow: the user passed ``--override``.
        source: where the overrides came from, for the error message.

    Returns:
        ``(params, changed)`` with ``changed = {"robot.max_speed_mps": [release value, new value], ...}``.

    Raises:
        ConfigError: a value is invalid, or values differ and ``allow`` is False.
    """
    updated: dict[str, Any] = {}
    changed: dict[str, list[Any]] = {}
    for section, model in OVERRIDABLE.items():
        values = overrides.get(section) or {}
        if not values:
            continue
        current = getattr(params, section)
        try:
            new = model.model_validate({**current.model_dump(mode="json"), **values})
        except ValidationError as exc:
            first = exc.errors()[0]
            raise ConfigError(source, f"{section}.{'.'.join(map(str, first['loc']))}", first["msg"]) from exc
        for key, value in new.model_dump(mode="json").items():
            old = getattr(current, key)
            if value != old:
                changed[f"{section}.{key}"] = [old, value]
        updated[section] = new
    if changed and not allow:
        what = ", ".join(f"{key}: {old} → {new}" for key, (old, new) in changed.items())
        raise ConfigError(
            source,
            next(iter(changed)),
            f"overrides the release's recorded parameters ({what}); pass --override to evaluate with them "
            "(the results are then marked unofficial)",
        )
    return dataclasses.replace(params, **updated), changed
