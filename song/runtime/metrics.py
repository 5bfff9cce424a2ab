"""Social-navigation metrics as pure functions over arrays (paper "Evaluation metrics").

Choices (also in docs/metrics.md):
- Every episode has exactly one outcome: success, obstacle (C_obs ≥ δ_obs), human (any avatar
  collision), timeout, or error (the policy failed: raised, exited, ran past its time limit), so
  SR + CR_obs + CR_hum + TO + ERR = 100 % (ERR is shown only when a policy failed).
- SPL = S·L*/max(L, L*), STL = S·T*/max(T, T*), with L the robot's travelled length and T its time.
- Distances to people are horizontal, robot centre to avatar root. PSC is the fraction of an
  episode's steps whose nearest-avatar distance is ≥ 0.5 m (steps with nobody present count as
  compliant); MinD is the episode's minimum (inf when nobody is ever present; such episodes are left
  out of the MinD mean).
- JK: κ_t = |ẋÿ − ẏẍ| / |v|³ with |v| fixed to the robot's speed limit (0.5 m/s in the paper, read
  from the release), derivatives by central
  differences at the control period; JK = RMS of Δκ/Δt over the episode (0 for fewer than 4 poses).
All rates are percentages in the summary (0–100); per-episode values are fractions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from song import plugins

OUTCOMES = ("success", "obstacle", "human", "timeout", "error")


def spl(success: np.ndarray, length: np.ndarray, optimal_length: np.ndarray) -> np.ndarray:
    """Per-episode S · L* / max(L, L*)."""
    success, length, optimal = (np.asarray(a, dtype=np.float64) for a in (success, length, optimal_length))
    return success * optimal / np.maximum(np.maximum(length, optimal), 1e-12)


def stl(success: np.ndarray, time: np.ndarray, optimal_time: np.ndarray) -> np.ndarray:
    """Per-episode S · T* / max(T, T*)."""
    return spl(success, time, optimal_time)


def path_length(xy: np.ndarray) -> float:
    """Travelled length of a (K, 2) trajectory, m."""
    xy = np.asarray(xy, dtype=np.float64)
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) > 1 else 0.0


def personal_space_compliance(nearest: np.ndarray, threshold: float = 0.5) -> float:
    """Fraction of steps with nearest-avatar distance ≥ ``threshold`` (inf = nobody present)."""
    nearest = np.asarray(nearest, dtype=np.float64)
    return float(np.mean(nearest >= threshold)) if nearest.size else 1.0


def jerk(xy: np.ndarray, dt: float, speed: float) -> float:
    """RMS of Δκ/Δt along a (K, 2) trajectory sampled every ``dt`` seconds.

    κ = |ẋÿ − ẏẍ| / |v|³ with |v| = ``speed`` (paper: the robot's 0.5 m/s). Central differences: ÿ from three
    consecutive poses, ẏ the mean of the two adjacent first differences (exact on circles).
    """
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) < 4:
        return 0.0
    first = np.diff(xy, axis=0) / dt
    vel = 0.5 * (first[:-1] + first[1:])
    acc = np.diff(first, axis=0) / dt
    kappa = np.abs(vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]) / speed**3
    rate = np.diff(kappa) / dt
    return float(np.sqrt(np.mean(rate**2)))


@dataclass(frozen=True)
class EpisodeMetrics:
    """Per-episode values that the aggregate metrics are built from."""

    outcome: str
    length: float
    time: float
    optimal_length: float
    optimal_time: float
    psc: float
    min_distance: float
    jerk: float


def episode_metrics(
    outcome: str,
    xy: np.ndarray,
    dt: float,
    optimal_length: float,
    optimal_time: float,
    nearest: np.ndarray,
    psc_threshold: float,
    nominal_speed: float,
) -> EpisodeMetrics:
    """Per-episode metrics from the logged robot poses (K, 2) and nearest-avatar distances (K,).

    ``psc_threshold`` (m) and ``nominal_speed`` (m/s, the |v| of the jerk's curvature) come from the
    release's robot parameters.
    """
    if outcome not in OUTCOMES:
        raise ValueError(f"unknown outcome {outcome!r}; expected one of {OUTCOMES}")
    nearest = np.asarray(nearest, dtype=np.float64)
    return EpisodeMetrics(
        outcome=outcome,
        length=path_length(xy),
        time=(len(xy) - 1) * dt,
        optimal_length=optimal_length,
        optimal_time=optimal_time,
        psc=personal_space_compliance(nearest, psc_threshold),
        min_distance=float(nearest.min()) if nearest.size else float("inf"),
        jerk=jerk(xy, dt, nominal_speed),
    )


@dataclass(frozen=True)
class Metric:
    """An aggregate metric: a column of every results table (a ``metric`` plugin, :mod:`song.plugins`).

    ``value(episodes)`` gets a non-empty sequence of episodes -- ``song eval``'s
    :class:`~song.runtime.loop.EpisodeResult` (outcome, trajectory, nearest distances, ``metrics``) or
    bare :class:`EpisodeMetrics` -- and returns one number (NaN when undefined). A third-party metric is
    any object (or class with no arguments) with ``name`` and ``value``; ``only_when_nonzero`` hides its
    column from the Markdown table while it is 0 everywhere.
    """

    name: str
    compute: Callable[[Sequence[EpisodeMetrics]], float]
    only_when_nonzero: bool = False

    def value(self, episodes: Sequence[Any]) -> float:
        """The metric over ``episodes``."""
        return float(self.compute([getattr(e, "metrics", e) for e in episodes]))


def _outcome_rate(kind: str) -> Callable[[Sequence[EpisodeMetrics]], float]:
    return lambda es: 100.0 * float(np.mean([e.outcome == kind for e in es]))


def _success(es: Sequence[EpisodeMetrics]) -> np.ndarray:
    return np.array([e.outcome == "success" for e in es], dtype=np.float64)


def _avg_time(es: Sequence[EpisodeMetrics]) -> float:
    times = np.array([e.time for e in es])[_success(es) > 0]
    return float(times.mean()) if len(times) else float("nan")


def _min_distance(es: Sequence[EpisodeMetrics]) -> float:
    d = np.array([e.min_distance for e in es])
    return float(d[np.isfinite(d)].mean()) if np.isfinite(d).any() else float("nan")


BUILTIN_METRICS = (
    Metric("SR", _outcome_rate("success")),
    Metric("SPL", lambda es: 100.0 * float(spl(_success(es), [e.length for e in es], [e.optimal_length for e in es]).mean())),
    Metric("STL", lambda es: 100.0 * float(stl(_success(es), [e.time for e in es], [e.optimal_time for e in es]).mean())),
    Metric("TO", _outcome_rate("timeout")),
    Metric("AvgT", _avg_time),
    Metric("CR_obs", _outcome_rate("obstacle")),
    Metric("CR_hum", _outcome_rate("human")),
    Metric("PSC", lambda es: 100.0 * float(np.mean([e.psc for e in es]))),
    Metric("MinD", _min_distance),
    Metric("JK", lambda es: float(np.mean([e.jerk for e in es]))),
    Metric("ERR", _outcome_rate("error"), only_when_nonzero=True),
)  # fmt: skip
for _metric in BUILTIN_METRICS:
    plugins.add("metric", _metric.name, _metric)


def metrics() -> list[Any]:
    """Every registered metric, built-ins first (classes are instantiated)."""
    return [m() if isinstance(m, type) else m for m in plugins.registered("metric").values()]


def aggregate(episodes: Sequence[Any]) -> dict[str, float]:
    """Every registered metric over a set of episodes, and ``n`` (rates in %, AvgT in s, MinD in m)."""
    row = {"n": float(len(episodes))}
    for metric in metrics():
        row[metric.name] = float(metric.value(episodes)) if episodes else float("nan")
    return row


def markdown_table(rows: dict[str, dict[str, dict[str, float]]]) -> str:
    """The paper's Table 2 layout: one row per (policy, difficulty), one column per registered metric."""
    values = [v for by in rows.values() for v in by.values()]
    columns = [
        m.name
        for m in metrics()
        if not getattr(m, "only_when_nonzero", False) or any(v.get(m.name, 0.0) > 0 for v in values)
    ]
    header = "| policy | difficulty | n | " + " | ".join(columns) + " |"
    lines = [header, "|" + "---|" * (3 + len(columns))]
    for policy, by_difficulty in rows.items():
        for difficulty, row in by_difficulty.items():
            cells = [f"{row[c]:.2f}" if np.isfinite(row.get(c, np.nan)) else "–" for c in columns]
            lines.append(f"| {policy} | {difficulty} | {int(row['n'])} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
