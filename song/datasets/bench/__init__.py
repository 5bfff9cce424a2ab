"""Benchmark releases: Parquet tables, versions, verify, load API (DESIGN §7)."""

from song.datasets.bench.types import AvatarBinding, Episode, PedestrianTrack, StaticMap, pedestrian_states

__all__ = ["AvatarBinding", "Episode", "PedestrianTrack", "StaticMap", "pedestrian_states"]
