"""Scene packages: model, formats, importers, procedural generator."""

from song.datasets.scenes.model import Region, SceneObject, SemanticMap
from song.datasets.scenes.occupancy import OccupancyGrid
from song.datasets.scenes.package import (
    ScenePackage,
    find_scene_packages,
    load_scene_package,
    write_scene_package,
)

__all__ = [
    "OccupancyGrid",
    "Region",
    "SceneObject",
    "ScenePackage",
    "SemanticMap",
    "find_scene_packages",
    "load_scene_package",
    "write_scene_package",
]
