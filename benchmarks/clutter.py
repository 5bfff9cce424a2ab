"""Objects per scene: floor objects (the semantic map's) plus the dressing's items (on tops, shelves, walls).

    .venv/bin/python benchmarks/clutter.py [--generated 3]

Over the shipped sample scenes (``datasets/sample_scenes``) and ``--generated`` fresh scenes of each
procedural venue (seed 5). Items count once each (a potted plant's pot and leaves, a picture's canvas
and frame are one item; each book on a shelf is one). Target: a median of at least 150.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks._common import ROOT, emit  # noqa: E402


def count(root: Path) -> dict:
    """Floor objects and items of one package."""
    from song.datasets.scenes import load_scene_package
    from song.datasets.scenes.clutter import item_count
    from song.datasets.scenes.dressing import DressingHints, build_dressing
    from song.datasets.scenes.usd import read_usd_dressing

    package = load_scene_package(root, min_free_area_m2=0.0)
    hints = DressingHints.from_json(read_usd_dressing(root / "scene_flat.usda"))
    dressing = build_dressing(package.semantic_map, package.occupancy, hints)
    floor = len(package.semantic_map.objects)
    items = item_count(dressing.parts)
    kinds: dict[str, int] = {}
    for part in dressing.parts:
        if part.group.startswith("item:"):
            kinds[part.group[5:]] = kinds.get(part.group[5:], 0) + 1
    top = dict(sorted(kinds.items(), key=lambda kv: -kv[1])[:5])
    return {"venue": package.semantic_map.venue_type, "floor_objects": floor, "items": items,
            "total": floor + items, "most_common_item_parts": top}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--generated", type=int, default=3)
    args = parser.parse_args()
    from song.datasets.scenes.generate import VENUE_ORDER, generate_scene

    rows = {}
    samples = ROOT / "datasets" / "sample_scenes"
    for root in sorted(p for p in samples.iterdir() if (p / "semantic_map.json").is_file()):
        rows[f"sample/{root.name}"] = count(root)
    with tempfile.TemporaryDirectory() as tmp:
        for venue in VENUE_ORDER:
            for k in range(args.generated):
                root = generate_scene(f"{venue}_{k:04d}", venue, 5 + k, Path(tmp), splat=False)
                rows[f"generated/{root.name}"] = count(root)
    totals = [r["total"] for r in rows.values()]
    emit(
        {
            "scenes": rows,
            "median_total": float(np.median(totals)),
            "median_total_samples": float(np.median([r["total"] for k, r in rows.items() if k.startswith("sample")])),
            "min_total": int(min(totals)),
            "target_median": 150,
        }
    )


if __name__ == "__main__":
    main()
