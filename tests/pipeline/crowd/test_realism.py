"""Crowd statistics (song.pipeline.crowd.realism): one method on synthetic pairs with known answers and on
the real reference sequences."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from song.pipeline.crowd.realism import (
    Track,
    covered_area,
    crowd_statistics,
    density,
    heading_reversals,
    pass_distances,
    read_edinburgh_tracks,
    read_obsmat,
    resample,
    stop_facing,
    wall_clearances,
)

REAL = Path(__file__).resolve().parents[3].parent / "shared" / "reference" / "pedestrians"


def walk(start, velocity, t0: float, t1: float, rate: float = 10.0) -> Track:
    t = np.arange(t0, t1 + 1e-9, 1.0 / rate)
    return Track(t, np.asarray(start, float) + (t - t0)[:, None] * np.asarray(velocity, float))


def test_resample_puts_tracks_on_a_common_clock() -> None:
    (track,) = resample([walk((0.0, 0.0), (1.0, 0.0), 0.13, 2.13)])  # samples 0.13, 0.23, ..., 2.13 s
    np.testing.assert_allclose(track.t, np.arange(1, 6) / 2.5)  # multiples of 0.4 s inside the track
    np.testing.assert_allclose(track.xy[:, 0], track.t - 0.13, atol=1e-12)
    assert resample([walk((0.0, 0.0), (1.0, 0.0), 0.1, 0.3)]) == []  # shorter than two samples


def test_head_on_and_crossing_pairs_pass_at_their_geometric_closest_approach() -> None:
    """Closest approaches are refined between samples (the miss distance, not the nearest sample)."""
    a = walk((0.0, 0.0), (1.3, 0.0), 0.0, 10.0)
    b = walk((13.0, 0.7), (-1.3, 0.0), 0.0, 10.0)  # head-on, 0.7 m apart laterally
    c = walk((6.5, -6.0), (0.0, 1.2), 0.0, 10.0)  # crosses a's line at x = 6.5 when a is there (t = 5 s)
    passes = pass_distances(resample([a, b]))
    assert len(passes["head_on"]) == 1 and passes["head_on"][0] == pytest.approx(0.7, abs=1e-9)
    crossing = pass_distances(resample([a, c]))
    assert len(crossing["crossing"]) == 1 and crossing["crossing"][0] == pytest.approx(0.0, abs=1e-9)
    far = walk((0.0, 5.0), (1.3, 0.0), 0.0, 10.0)  # same direction, never within 2 m
    assert len(pass_distances(resample([a, far]))["all"]) == 0


def test_speed_and_standing_share() -> None:
    walker = walk((0.0, 0.0), (1.25, 0.0), 0.0, 20.0)
    stander = walk((0.0, 10.0), (0.0, 0.0), 0.0, 20.0)
    stats = crowd_statistics([walker, stander])
    assert stats["speed_median_mps"] == pytest.approx(1.25, abs=1e-9)
    assert stats["standing_share"] == pytest.approx(0.5, abs=0.03)


def test_steady_acceleration_leaves_setting_off_and_stopping_out() -> None:
    """A walker who stands, sets off at 2 m/s² to 1.2 m/s, walks straight and stops: the steady figure is 0,
    the overall one is not; a path's tortuosity p95 is reported beside its median; a short track is fine."""
    t = np.arange(0.0, 30.0, 0.1)
    speed = np.clip(np.minimum(2.0 * (t - 5.0), 2.0 * (25.0 - t)), 0.0, 1.2)
    x = np.concatenate([[0.0], np.cumsum(speed[:-1] * 0.1)])
    track = Track(t, np.column_stack([x, np.zeros_like(x)]))
    stats = crowd_statistics([track, walk((0.0, 9.0), (1.0, 0.0), 0.0, 0.6)])
    assert stats["acceleration_rms_mps2"] > 0.3 and stats["acceleration_rms_steady_mps2"] == pytest.approx(
        0.0, abs=1e-9
    )
    assert stats["tortuosity_p95"] == pytest.approx(1.0, abs=1e-9)


def test_steady_acceleration_splits_into_speed_changes_and_turning() -> None:
    """On a circle at a constant 1.2 m/s the acceleration is all across the velocity (v²/R), none along it;
    on a straight line with the speed swinging, all along it."""
    t = np.arange(0.0, 40.0, 0.1)
    radius, speed = 3.0, 1.2
    circle = Track(t, radius * np.column_stack([np.cos(speed / radius * t), np.sin(speed / radius * t)]))
    stats = crowd_statistics([circle])
    assert stats["acceleration_rms_steady_across_mps2"] == pytest.approx(speed**2 / radius, rel=0.05)  # 2.5 Hz chords
    assert stats["acceleration_rms_steady_along_mps2"] < 0.01  # (one-sided differences at the ends)
    x = 1.2 * t + 0.5 * np.sin(t)  # speed 1.2 + 0.5 cos t: always moving
    swing = crowd_statistics([Track(t, np.column_stack([x, np.zeros_like(x)]))])
    assert swing["acceleration_rms_steady_across_mps2"] == pytest.approx(0.0, abs=1e-9)
    assert swing["acceleration_rms_steady_along_mps2"] == pytest.approx(swing["acceleration_rms_steady_mps2"])


def test_wall_clearances_are_taken_over_moving_samples() -> None:
    """A walk 0.3 m from a wall (y = 0) gives its body's gap at every 2.5 Hz sample; someone standing gives none."""
    along = walk((0.0, 0.3), (1.0, 0.0), 0.0, 10.0)
    standing = Track(np.arange(0.0, 10.0, 0.1), np.tile([5.0, 0.26], (100, 1)))
    gaps = wall_clearances([along, standing], lambda xy: xy[:, 1] - 0.25)
    assert len(gaps) == 26  # 0, 0.4, ..., 10 s
    np.testing.assert_allclose(gaps, 0.05)


def test_heading_reversals_count_zigzags_not_turns() -> None:
    """A 30 FPS walk that swings 30° left and straight back every 0.2 s reverses; a smooth turn does not."""
    fps, speed = 30.0, 1.0
    t = np.arange(0.0, 10.0, 1.0 / fps)
    smooth = np.cumsum(speed / fps * np.column_stack([np.cos(0.3 * t), np.sin(0.3 * t)]), axis=0)
    zig = np.where((np.arange(len(t)) // 6) % 2 == 0, np.radians(15.0), -np.radians(15.0))
    zigzag = np.cumsum(speed / fps * np.column_stack([np.cos(zig), np.sin(zig)]), axis=0)
    assert heading_reversals([Track(t, smooth)]) == (0, pytest.approx((len(t) - 1) / fps / 60.0))
    count, minutes = heading_reversals([Track(t, zigzag)])
    assert count == len(t) // 6 - 2  # every swing after the first is one back
    assert minutes == pytest.approx((len(t) - 1) / fps / 60.0)
    standing = Track(t, np.zeros((len(t), 2)))
    assert heading_reversals([standing]) == (0, 0.0)


def test_density_on_the_covered_floor_and_on_a_given_area() -> None:
    """The mean number present per m², over the samples at which anyone is; the covered floor is 0.5 m cells."""
    walker = walk((0.25, 0.25), (1.0, 0.0), 0.0, 10.0)  # 0.25 → 10.25 m along y = 0.25: cells 0..20 of row 0
    stander = walk((0.25, 5.25), (0.0, 0.0), 0.0, 10.0)  # one more cell
    early = walk((0.25, 5.25), (0.0, 0.0), 0.0, 4.8)  # present for 13 of the walker's 26 samples
    assert covered_area([walker, stander]) == pytest.approx(22 * 0.25)
    assert density([walker, stander], 10.0) == pytest.approx(0.2)
    assert density([walker, early], 10.0) == pytest.approx(0.15)
    stats = crowd_statistics([walker, stander], walkable_m2=10.0)
    assert stats["density_per_m2"] == pytest.approx(0.2)
    assert stats["density_covered_per_m2"] == pytest.approx(2 / 5.5, abs=1e-4)


@pytest.mark.skipif(not REAL.is_dir(), reason=f"the real reference trajectories are not here ({REAL})")
def test_real_sequences_read_as_their_readme_says() -> None:
    """ETH from the EWAP obsmat: median walking speed 1.49 m/s (the shared README's figure); the indoor
    Edinburgh atrium: 146 tracks, walking speed near 1.07 m/s at the nominal 9 fps."""
    eth = crowd_statistics(read_obsmat(REAL / "ewap_seq_eth_obsmat.txt"))
    assert eth["speed_median_mps"] == pytest.approx(1.49, abs=0.01)
    forum = read_edinburgh_tracks(REAL / "edinburgh_forum_tracks.01Aug.txt")
    assert len(forum) == 146
    assert all(np.all(np.diff(track.t) > 0) for track in forum)
    assert 0.9 < crowd_statistics(forum)["speed_median_mps"] < 1.25


def test_edinburgh_reader_parses_pixels_and_frames(tmp_path: Path) -> None:
    path = tmp_path / "tracks.txt"
    path.write_text(
        "% Total number of trajectories in file are  2\n\n"
        "Properties.R1=[3 10 12 1.0 ];\n TRACK.R1=[[100 200 10];[110 200 11];[120 200 12]];\n"
        "Properties.R2=[2 5 6 1.0 ];\n TRACK.R2=[[0 0 6];[0 40 5]];\n"
    )
    first, second = read_edinburgh_tracks(path)
    np.testing.assert_allclose(first.t, np.array([10, 11, 12]) / 9.0)
    np.testing.assert_allclose(first.xy, np.array([[100, 200], [110, 200], [120, 200]]) * 0.0247)
    np.testing.assert_allclose(second.t, [5 / 9.0, 6 / 9.0])  # sorted by frame
    np.testing.assert_allclose(second.xy[0], [0.0, 40 * 0.0247])


def test_stop_facing_measures_each_unbroken_stay() -> None:
    # 6 s at its start facing the desk east of it (the first 2 s, a settling turn, facing away), 4 s walking,
    # then 5 s standing 0.4 m from the start, facing away from the desk: a stay at its goal when the goal is
    # there (each stay measured after its settling), none when it only stepped aside near its start
    from tests.pipeline.crowd.test_simulate import intent

    fps, frames = 30, 30 * 15
    xy, yaw = np.zeros((1, frames, 2)), np.zeros((1, frames))
    yaw[0, : 2 * fps] = np.pi  # the settling turn
    walking = slice(6 * fps, 10 * fps)
    xy[0, walking, 0] = np.linspace(0.0, 0.4, 4 * fps)
    xy[0, 10 * fps :, 0] = 0.4
    yaw[0, 10 * fps :] = np.pi  # facing away from the desk
    speed = np.zeros((1, frames))
    speed[0, walking] = 0.3
    crowd = SimpleNamespace(ids=np.array([0]), xy=xy, yaw=yaw, speed=speed, fps=fps)
    desk = SimpleNamespace(footprint=[(1.0, -0.5), (2.0, -0.5), (2.0, 0.5), (1.0, 0.5)])
    at_desk = intent(0, (0.0, 0.0), (0.4, 0.0)).model_copy(update={"start_object": "desk", "goal_object": "desk"})
    np.testing.assert_allclose(stop_facing(crowd, [at_desk], {"desk": desk}), [0.0, 180.0], atol=1e-9)
    aside = intent(0, (0.0, 0.0), (9.0, 9.0)).model_copy(update={"start_object": "desk"})
    np.testing.assert_allclose(stop_facing(crowd, [aside], {"desk": desk}), [0.0], atol=1e-9)
