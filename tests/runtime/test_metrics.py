"""Metrics on hand-built trajectories with hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from song.runtime.metrics import aggregate, episode_metrics, jerk, markdown_table, personal_space_compliance, spl


def test_spl_stl_hand_values() -> None:
    np.testing.assert_allclose(spl([1, 1, 0], [10.0, 4.0, 3.0], [5.0, 5.0, 5.0]), [0.5, 1.0, 0.0])


def test_episode_values_by_hand() -> None:
    xy = np.array([[0.0, 0.0], [0.05, 0.0], [0.1, 0.0], [0.15, 0.0], [0.2, 0.0]])
    nearest = np.array([2.0, 0.6, 0.4, 0.3, np.inf])
    m = episode_metrics(
        "success", xy, 0.1, optimal_length=0.1, optimal_time=0.2, nearest=nearest, psc_threshold=0.5, nominal_speed=0.5
    )
    assert m.length == pytest.approx(0.2) and m.time == pytest.approx(0.4)
    assert m.psc == pytest.approx(3 / 5) and m.min_distance == pytest.approx(0.3)
    assert m.jerk == 0.0  # a straight line has zero curvature everywhere
    row = aggregate([m])
    assert row["SPL"] == pytest.approx(50.0) and row["STL"] == pytest.approx(50.0) and row["AvgT"] == pytest.approx(0.4)


def test_jerk_of_a_circle_and_a_kink() -> None:
    dt, r = 0.1, 2.0
    t = np.arange(60) * dt
    circle = np.column_stack([r * np.cos(0.25 * t), r * np.sin(0.25 * t)])
    # constant curvature → Δκ/Δt = 0
    assert jerk(circle, dt, 0.5) < 1e-9
    kink = np.vstack([np.column_stack([np.arange(10) * 0.05, np.zeros(10)]), [[0.45, 0.05], [0.45, 0.1], [0.45, 0.15]]])
    assert jerk(kink, dt, 0.5) > 10.0


def test_outcome_rates_sum_to_100() -> None:
    rng = np.random.default_rng(1)
    episodes = []
    for outcome in rng.choice(["success", "obstacle", "human", "timeout"], size=37):
        xy = np.cumsum(rng.normal(0, 0.05, size=(20, 2)), axis=0)
        episodes.append(episode_metrics(str(outcome), xy, 0.1, 1.0, 2.0, rng.uniform(0.2, 3.0, size=20), 0.5, 0.5))
    row = aggregate(episodes)
    assert row["SR"] + row["CR_obs"] + row["CR_hum"] + row["TO"] == pytest.approx(100.0)
    table = markdown_table({"p": {"all": row}})
    assert table.count("\n") == 3 and "| p | all | 37 |" in table


def test_psc_counts_nobody_as_compliant() -> None:
    assert personal_space_compliance(np.array([np.inf, 0.49, 0.5])) == pytest.approx(2 / 3)
    with pytest.raises(ValueError, match="outcome"):
        episode_metrics("crashed", np.zeros((2, 2)), 0.1, 1, 1, np.ones(2), 0.5, 0.5)
