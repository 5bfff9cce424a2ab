"""Benchmark releases: Parquet tables, versions, verify, load API.

``song.datasets.bench.open(path, version=None)`` is the runtime's entry point.
"""

from song.datasets.bench.load import Benchmark, open_benchmark
from song.datasets.bench.types import AvatarBinding, Episode, PedestrianTrack, StaticMap, pedestrian_states

open = open_benchmark  # noqa: A001 - the documented spelling: song.datasets.bench.open(...)

__all__ = [
    "AvatarBinding",
    "Benchmark",
    "Episode",
    "PedestrianTrack",
    "StaticMap",
    "open",
    "open_benchmark",
    "pedestrian_states",
]
