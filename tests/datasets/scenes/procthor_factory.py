"""ProcTHOR house JSONs written by our own code from the schema (AI2-THOR's house format), for tests.

:func:`open_plan_house` is a three-room house that exercises what real ProcTHOR houses do and the
shipped samples happen not to: an open-plan connection (the kitchen–living-room boundary is a pair of
``"empty": true`` walls) and a door on a wall whose polygon runs from its larger corner (its
``holePolygon`` is measured from that corner, so reading it from the id's sorted corners mirrors it
onto a dresser). Unity frame: metres, x right, z forward, y up; walls run along their room's floor
polygon, so the two sides of an interior wall run in opposite directions, as ProcTHOR writes them.
"""

from __future__ import annotations

import json
from pathlib import Path

WALL_HEIGHT = 2.5

# asset id → (objectType, (x, y, z) bounding-box size in the asset's own axes, m)
ASSETS = {
    "Fridge_test": ("Fridge", (0.8, 1.8, 0.7)),
    "Counter_test": ("CounterTop", (2.0, 0.9, 0.6)),
    "Sofa_test": ("Sofa", (2.0, 0.8, 0.9)),
    "TVStand_test": ("TVStand", (1.4, 0.5, 0.45)),
    "Bed_test": ("Bed", (1.6, 0.6, 2.0)),
    "Dresser_test": ("Dresser", (1.5, 1.0, 0.55)),
    "Doorway_test": ("Doorway", (1.0, 2.1, 0.1)),
}


def _point(x: float, z: float, y: float = 0.0) -> dict:
    return {"x": x, "y": y, "z": z}


def _wall(room: int | str, a: tuple[float, float], b: tuple[float, float], empty: bool = False) -> dict:
    """A wall from a to b (Unity x, z); its id carries the sorted corners, its polygon the direction."""
    (x0, z0), (x1, z1) = sorted([a, b])
    wall = {
        "id": f"wall|{room}|{x0:.2f}|{z0:.2f}|{x1:.2f}|{z1:.2f}",
        "roomId": f"room|{room}",
        "polygon": [_point(*a), _point(*b), _point(*a, WALL_HEIGHT), _point(*b, WALL_HEIGHT)],
        "material": {"name": "PureWhite", "color": {"r": 0.8, "g": 0.8, "b": 0.78}},
    }
    if empty:
        wall["empty"] = True
    return wall


def _room_walls(room: int, polygon: list[tuple[float, float]], empty: set = frozenset()) -> list[dict]:
    """One wall per floor-polygon edge, in the polygon's order; edges in ``empty`` are open-plan."""
    edges = zip(polygon, polygon[1:] + polygon[:1], strict=True)
    return [_wall(room, a, b, frozenset((a, b)) in empty) for a, b in edges]


def _object(asset: str, kind: str, room: int, k: int, x: float, z: float, yaw: float = 0.0) -> dict:
    height = ASSETS[asset][1][1]
    return {
        "id": f"{kind}|{room}|{k}",
        "assetId": asset,
        "position": _point(x, z, height / 2),
        "rotation": _point(0.0, 0.0, yaw),
        "kinematic": False,
        "children": [],
    }


def open_plan_house(open_plan: bool = True) -> dict:
    """A kitchen and a living room side by side (open plan when ``open_plan``), a bedroom behind both.

    The bedroom's only door is in its wall to the living room, whose polygon runs from x = 8 to x = 4:
    the hole 0.3–1.3 m along it is at x 6.7–7.7. Mirrored (measured from x = 4) it would be at
    x 4.3–5.3, behind the bedroom's dresser, and the bedroom would be sealed.
    """
    kitchen = [(0.0, 0.0), (0.0, 4.0), (4.0, 4.0), (4.0, 0.0)]
    living = [(4.0, 0.0), (4.0, 4.0), (8.0, 4.0), (8.0, 0.0)]
    bedroom = [(0.0, 4.0), (0.0, 7.0), (8.0, 7.0), (8.0, 4.0), (4.0, 4.0)]
    boundary = {frozenset(((4.0, 4.0), (4.0, 0.0)))} if open_plan else set()
    walls = _room_walls(2, kitchen, boundary) + _room_walls(3, living, boundary) + _room_walls(4, bedroom)
    walls.append(_wall("exterior", (4.0, 0.0), (0.0, 0.0)))
    hole = [_point(0.3, 0.0), _point(1.3, 2.1)]
    doors = [
        {
            "id": "door|3|4",
            "assetId": "Doorway_test",
            "room0": "room|4",
            "room1": "room|3",
            "wall0": "wall|4|4.00|4.00|8.00|4.00",  # bedroom side: its polygon runs (8, 4) → (4, 4)
            "wall1": "wall|3|4.00|4.00|8.00|4.00",
            "holePolygon": hole,
            "assetPosition": _point(0.8, 0.0, 1.05),
            "openable": True,
            "openness": 1,
        },
        {
            "id": "door|1|2",
            "assetId": "Doorway_test",
            "room0": "room|2",
            "room1": "room|2",
            "wall0": "wall|2|0.00|0.00|4.00|0.00",  # the kitchen's south wall runs (4, 0) → (0, 0)
            "wall1": "wall|exterior|0.00|0.00|4.00|0.00",
            "holePolygon": [_point(1.0, 0.0), _point(2.0, 2.1)],
            "assetPosition": _point(1.5, 0.0, 1.05),
            "openable": False,
            "openness": 0,
        },
    ]
    objects = [
        _object("Fridge_test", "Fridge", 2, 0, 0.5, 3.5),
        _object("Counter_test", "CounterTop", 2, 1, 2.2, 3.6),
        _object("Sofa_test", "Sofa", 3, 0, 6.0, 0.6),
        _object("TVStand_test", "TVStand", 3, 1, 7.7, 2.0, 90.0),
        _object("Bed_test", "Bed", 4, 0, 1.5, 5.9),
        _object("Dresser_test", "Dresser", 4, 1, 4.8, 4.33),  # x 4.05–5.55 against the door wall
    ]
    rooms = [
        {"id": f"room|{rid}", "roomType": kind, "floorPolygon": [_point(x, z) for x, z in poly]}
        for rid, kind, poly in ((2, "Kitchen", kitchen), (3, "LivingRoom", living), (4, "Bedroom", bedroom))
    ]
    return {"rooms": rooms, "walls": walls, "doors": doors, "windows": [], "objects": objects, "metadata": {}}


def write_house(folder: Path, name: str = "house_open", open_plan: bool = True) -> tuple[Path, Path]:
    """Write the house and its asset table (the flat ``{assetId: {objectType, boundingBox}}`` form)."""
    folder.mkdir(parents=True, exist_ok=True)
    house = folder / f"{name}.json"
    house.write_text(json.dumps(open_plan_house(open_plan), indent=1))
    table = folder.parent / f"{folder.name}_assets.json"
    boxes = {k: {"objectType": t, "boundingBox": dict(zip("xyz", s, strict=True))} for k, (t, s) in ASSETS.items()}
    table.write_text(json.dumps(boxes, indent=1))
    return house, table
