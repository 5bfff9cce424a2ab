"""Does a run still match its inputs? Each stage records the sha256 of every scene-package file it read.

``stages.json`` keeps, per completed stage, ``"scene": {file name: sha256}`` of the package files at the
time it ran. Exporting a release re-reads the packages, so it first checks that none was edited,
replaced, removed or added since: otherwise old episodes would be paired with a new map.
"""

from __future__ import annotations

from pathlib import Path

from song.datasets.run.layout import SceneFolder
from song.datasets.scenes.package import PACKAGE_FILES
from song.errors import StageError
from song.util import read_json_object, sha256_file


def check_scene_unchanged(folder: SceneFolder, package_root: Path) -> None:
    """Refuse (one line naming the scene file) when a package file differs from what the stages read.

    Raises:
        StageError: a recorded file changed, vanished or appeared, or no completed stage recorded its
            inputs (a run from an older song: re-run ``song synth``, it resumes).
    """
    record = read_json_object(folder.stages)
    completed = {
        name: entry for name, entry in sorted(record.items()) if isinstance(entry, dict) and entry.get("status") == "ok"
    }
    if not completed:
        raise StageError(f"{folder.stages}: no completed stage for scene '{folder.scene_id}'; run `song synth` first")
    present = {name: package_root / name for name in PACKAGE_FILES if (package_root / name).is_file()}
    for stage, entry in completed.items():
        files = entry.get("scene")
        if not isinstance(files, dict):
            raise StageError(
                f"{folder.stages}: stage '{stage}' recorded no scene hashes (an older run); re-run `song synth`"
            )
        for name in sorted(set(files) | set(present)):
            now = sha256_file(present[name]) if name in present else None
            if now != files.get(name):
                change = "appeared" if name not in files else "was removed" if now is None else "changed"
                raise StageError(
                    f"{package_root / name}: {change} since the '{stage}' stage read the scene; "
                    "re-run `song synth` (it resumes) and `song grade` before exporting"
                )
