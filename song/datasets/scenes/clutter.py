"""Small things on surfaces and walls: what makes a synthesised room look lived in.

Clutter is part of the dressing (:mod:`song.datasets.scenes.dressing`): it becomes Gaussians and USD
proxy meshes (each labelled with its kind, ``item:mug``, ``item:art``, ...) but never enters the
occupancy map or the semantic map -- items stand on furniture or hang on walls, out of the walkers'
way. Deterministic in the scene's seed. By rule:

- **on tops** (desks, tables, counters; what a top has already -- a desk's monitor and keyboard --
  is kept clear): desks get papers, a mug, a phone, books, a folder, a pen cup, a small plant; tables
  in restaurants, dining rooms and cafeterias a place setting per side (plate, glass) and a vase;
  other tables papers, a laptop, bottles, mugs; shop counters and checkouts boxes of goods; other
  counters papers, a kettle, bowls. Items are placed without overlapping each other or the top's
  edge (rejection sampling, at most ``MAX_PER_TOP`` per top).
- **on shelves**: each board's goods become a row of individual books or boxes of varied widths
  and heights.
- **on walls**: framed pictures (homes, hotels, offices, clinics, restaurants, lobbies, museums) and
  signs (stations, shops, clinics, schools) on wall faces at least 1.4 m long that have floor in
  front and nothing standing before them, away from doorways and windows.
- **from the source**: ProcTHOR's objects placed on other objects (``children[]``), sized from its
  asset database (:class:`song.datasets.scenes.dressing.DressingHints` ``items``).
"""

from __future__ import annotations

import math

import numpy as np

from song.datasets.scenes.furniture import Part
from song.datasets.scenes.lights import segment_distance, wall_edges
from song.util import derive_rng

MAX_PER_TOP = 8
WALL_DECOR_EVERY_M = 2.0  # a long wall gets a picture or sign per this many metres
EDGE_M = 0.03  # items keep this far from a top's edge
GAP_M = 0.02  # and from each other
ART_VENUES = ("home", "hotel", "office", "clinic", "restaurant", "lobby", "museum", "library", "school")
SIGN_VENUES = ("station", "shop", "clinic", "school", "museum")
DINING_WORDS = ("dining", "restaurant", "cafe", "cafeteria", "bistro")

# kind: (shape, half x, half y, height, material); cylinders give radii
ITEMS = {
    "papers": ("box", 0.105, 0.15, 0.006, "paper"),
    "mug": ("cylinder", 0.04, 0.04, 0.10, "ceramic_white"),
    "phone": ("box", 0.036, 0.075, 0.012, "plastic_black"),
    "book": ("box", 0.085, 0.12, 0.035, "books"),
    "folder": ("box", 0.12, 0.16, 0.04, "fabric_blue"),
    "pen_cup": ("cylinder", 0.035, 0.035, 0.10, "metal_dark"),
    "laptop": ("box", 0.17, 0.12, 0.02, "metal_steel"),
    "bottle": ("cylinder", 0.035, 0.035, 0.24, "metal_white"),
    "plate": ("cylinder", 0.12, 0.12, 0.02, "ceramic_white"),
    "glass": ("cylinder", 0.035, 0.035, 0.12, "metal_white"),
    "vase": ("cylinder", 0.06, 0.06, 0.22, "pot_clay"),
    "box": ("box", 0.12, 0.09, 0.14, "cardboard"),
    "kettle": ("cylinder", 0.08, 0.08, 0.2, "metal_steel"),
    "bowl": ("cylinder", 0.09, 0.09, 0.07, "ceramic_white"),
    "plant": ("pot", 0.06, 0.06, 0.11, "pot_clay"),
    "bin": ("cylinder", 0.13, 0.13, 0.3, "metal_dark"),
}
DESK = ("papers", "papers", "mug", "phone", "book", "folder", "pen_cup", "plant")
MEETING = ("papers", "laptop", "bottle", "mug", "papers", "folder", "bottle")
SHOP = ("box", "box", "box", "bottle", "box")
COUNTER = ("papers", "kettle", "bowl", "mug", "plant", "bottle")
ARTS = ("canvas_ochre", "canvas_teal", "canvas_rose", "canvas_sky")
ROUND_WORDS = ("cup", "mug", "bowl", "plate", "bottle", "vase", "pot", "candle", "can", "glass", "jar")
SOURCE_MATERIALS = (
    (("book",), "books"),
    (("laptop", "phone", "remote", "tv", "television", "monitor", "computer"), "screen"),
    (("pillow", "towel", "cloth", "blanket"), "linen_white"),
    (("plant", "flower"), "foliage"),
    (("cup", "mug", "bowl", "plate", "vase", "candle"), "ceramic_white"),
    (("bottle", "glass", "jar", "can", "kettle", "pot", "pan", "toaster", "lamp", "clock"), "metal_steel"),
    (("painting", "picture", "poster"), "canvas_ochre"),
    (("box", "paper", "newspaper", "tissue"), "cardboard"),
    (("apple", "tomato", "potato", "bread", "egg", "lettuce"), "fabric_red"),
    (("bat", "ball", "statue", "key", "pen", "pencil", "watch", "spoon", "fork", "knife", "spatula"), "metal_dark"),
)
SIGNS = ("sign_green", "sign_blue")


def _item_parts(name: str, kind: str, centre, yaw: float, z0: float) -> list[Part]:
    shape, hx, hy, h, material = ITEMS[kind]
    group = f"item:{kind}"
    if shape == "pot":
        return [
            Part(f"{name}/pot", group, "cylinder", centre, 0.0, (hx, hy), z0, z0 + h, material, ("bottom",)),
            Part(f"{name}/leaves", group, "ellipsoid", centre, 0.0, (hx * 1.4, hy * 1.4), z0 + h * 0.8,
                 z0 + h * 2.4, "foliage"),
        ]  # fmt: skip
    return [
        Part(name, group, shape, centre, yaw if shape == "box" else 0.0, (hx, hy), z0, z0 + h, material, ("bottom",))
    ]


def _footprint_half(kind: str) -> tuple[float, float]:
    shape, hx, hy, _, _ = ITEMS[kind]
    return (hx * 1.4, hy * 1.4) if shape == "pot" else (hx, hy)


def _local(top: Part, point) -> tuple[float, float]:
    c, s = math.cos(top.yaw), math.sin(top.yaw)
    dx, dy = point[0] - top.centre[0], point[1] - top.centre[1]
    return c * dx + s * dy, -s * dx + c * dy


def _world(top: Part, x: float, y: float) -> tuple[float, float]:
    c, s = math.cos(top.yaw), math.sin(top.yaw)
    return top.centre[0] + c * x - s * y, top.centre[1] + s * x + c * y


def _place(top: Part, kinds, taken: list, rng, oid: str, start: int) -> list[Part]:
    """Items of ``kinds`` on ``top`` where they fit, none overlapping ``taken`` (local rectangles)."""
    out = []
    hx, hy = top.half
    for k, kind in enumerate(kinds):
        ix, iy = _footprint_half(kind)
        if ix > hx - EDGE_M or iy > hy - EDGE_M:
            continue
        for _ in range(12):
            x = rng.uniform(-hx + EDGE_M + ix, hx - EDGE_M - ix)
            y = rng.uniform(-hy + EDGE_M + iy, hy - EDGE_M - iy)
            if all(abs(x - tx) >= ix + thx + GAP_M or abs(y - ty) >= iy + thy + GAP_M for tx, ty, thx, thy in taken):
                taken.append((x, y, ix, iy))
                yaw = top.yaw + (rng.uniform(-0.3, 0.3) if ITEMS[kind][0] == "box" else 0.0)
                out += _item_parts(f"{oid}/item{start + k}", kind, _world(top, x, y), yaw, top.z1)
                break
    return out


def _cushions(oid: str, seat: Part, back: Part, rng) -> list[Part]:
    """Cushions leaning on a sofa's back, one per ~0.5 m of seat."""
    count = max(2, int(2 * seat.half[0] // 0.5))
    material = ("fabric_beige", "fabric_red", "fabric_blue", "linen_white", "fabric_green")[int(rng.integers(5))]
    out = []
    bx, by = _local(seat, back.centre)
    for k in range(count):
        x = -seat.half[0] + (k + 0.5) * 2 * seat.half[0] / count
        centre = _world(seat, x, by + back.half[1] + 0.06)
        out.append(Part(f"{oid}/cushion{k}", "item:cushion", "box", centre, seat.yaw + rng.uniform(-0.15, 0.15),
                        (0.2, 0.06), seat.z1, seat.z1 + 0.38, material))  # fmt: skip
    return out


def _setting(top: Part, oid: str) -> list[Part]:
    """A plate and a glass at the middle of each long side and a vase in the centre of a dining table."""
    hx, hy = top.half
    out = []
    if hy >= 0.3:
        for k, side in enumerate((-1, 1)):
            seats = max(1, int(2 * hx // 0.6))
            for j in range(seats):
                x = -hx + (j + 0.5) * 2 * hx / seats
                out += _item_parts(f"{oid}/plate{k}_{j}", "plate", _world(top, x, side * (hy - 0.17)), 0.0, top.z1)
                gx = x + 0.16 if x + 0.2 < hx else x - 0.16
                out += _item_parts(f"{oid}/glass{k}_{j}", "glass", _world(top, gx, side * (hy - 0.3)), 0.0, top.z1)
    if hx >= 0.3 and hy >= 0.3:
        out += _item_parts(f"{oid}/vase", "vase", _world(top, 0.0, 0.0), 0.0, top.z1)
    return out


def surface_items(oid: str, label: str, category: str, region_type: str, parts: list[Part], venue: str,
                  seed: int) -> list[Part]:  # fmt: skip
    """An object's parts with items on its top and its shelves' goods as single books or boxes (module docstring)."""
    rng = derive_rng(seed, "clutter", oid)
    label = label.lower()
    blocks = [p for p in parts if "/items" in p.name and p.kind == "box"]
    out = [p for p in parts if p not in blocks] + _shelf_rows(blocks, rng)
    seat = next((p for p in parts if p.name == f"{oid}/seat" and p.kind == "box"), None)
    back = next((p for p in parts if p.name == f"{oid}/back" and p.kind == "box"), None)
    if seat is not None and back is not None and seat.half[0] > 0.4:
        out += _cushions(oid, seat, back, rng)
    top = next((p for p in parts if p.name == f"{oid}/top" and p.kind == "box"), None)
    if top is None:  # a low cabinet, dresser or stand: its body's top
        top = next((p for p in parts if p.name == f"{oid}/body" and p.kind == "box" and 0.4 < p.z1 < 1.3), None)
    if top is None:
        return out
    # what already stands on the top (a desk's monitor and keyboard) stays clear
    taken = []
    for p in parts:
        if p is top or p.z0 < top.z1 - 1e-3 or p.kind != "box":
            continue
        x, y = _local(top, p.centre)
        taken.append((x, y, p.half[0] + 0.02, p.half[1] + 0.02))
    words = f"{label} {category} {region_type}"
    if any(k in label for k in ("desk", "workstation")) and "reception" not in label:
        kinds = [DESK[i] for i in rng.permutation(len(DESK))[: int(rng.integers(4, 8))]]
        # a waste bin under the desk, inside its footprint (no change to the map)
        hx, hy = top.half
        if hx > 0.35 and hy > 0.25:
            out += _item_parts(f"{oid}/bin", "bin", _world(top, hx - 0.2, 0.0), 0.0, 0.0)
    elif category == "table" or "table" in label:
        if venue == "restaurant" or any(w in words for w in DINING_WORDS):
            return out + _setting(top, oid)
        kinds = [MEETING[i] for i in rng.permutation(len(MEETING))[: int(rng.integers(3, 7))]]
    elif venue == "shop" or any(k in label for k in ("checkout", "shop")):
        kinds = list(SHOP) * 2
    else:
        kinds = [COUNTER[i] for i in rng.permutation(len(COUNTER))[: int(rng.integers(3, 6))]]
    return out + _place(top, kinds[:MAX_PER_TOP], taken, rng, oid, 0)


def _shelf_rows(blocks: list[Part], rng) -> list[Part]:
    """Each shelf board's goods block (``…/items<k>``) as a row of books or boxes."""
    out = []
    for p in blocks:
        books = p.material == "books"
        depth, height = 2 * p.half[1], p.z1 - p.z0
        x = -p.half[0]
        k = 0
        c, s = math.cos(p.yaw), math.sin(p.yaw)
        while x < p.half[0] - 0.02:
            w = rng.uniform(0.02, 0.05) if books else rng.uniform(0.08, 0.2)
            w = min(w, p.half[0] - x)
            h = height * rng.uniform(0.75, 1.0)
            d = depth * (rng.uniform(0.8, 1.0) if books else rng.uniform(0.6, 0.95))
            cx = x + w / 2
            centre = (p.centre[0] + c * cx, p.centre[1] + s * cx)
            material = p.material if books else ("cardboard" if rng.random() < 0.5 else p.material)
            out.append(Part(f"{p.name}_{k}", f"item:{'book' if books else 'goods'}", "box", centre, p.yaw,
                            (max(w / 2 - 0.002, 0.004), d / 2), p.z0, p.z0 + h, material, ("bottom",)))  # fmt: skip
            x += w
            k += 1
    return out


def source_items(items) -> list[Part]:
    """Parts for a source's small objects (:class:`song.datasets.scenes.dressing.Item`), material by their kind."""
    out = []
    for k, item in enumerate(items):
        kind = item.kind.lower()
        material = next((m for words, m in SOURCE_MATERIALS if any(w in kind for w in words)), "fabric_grey")
        shape = "cylinder" if any(w in kind for w in ROUND_WORDS) else "box"
        if any(w in kind for w in ("plant", "flower")):
            shape = "ellipsoid"
        out.append(Part(f"item_{k}", f"item:{kind.replace(' ', '_')}", shape, tuple(item.centre), item.yaw,
                        tuple(item.half), item.z0, item.z1, material))  # fmt: skip
    return out


def wall_decor(dressing, openings, windows, seed: int) -> list[Part]:
    """Pictures and signs on wall faces (see the module docstring); ``windows``: (a, b) wall segments."""
    venue = dressing.venue
    art, sign = venue in ART_VENUES, venue in SIGN_VENUES
    if not (art or sign):
        return []
    rng = derive_rng(seed, "clutter", "walls")
    grid = dressing.grid
    from song.geometry.freespace import clearance_field

    free = clearance_field(grid.free, grid.resolution)
    blocked_segments = [(np.asarray(o.a), np.asarray(o.b), 0.3 + o.thickness) for o in openings]
    blocked_segments += [(np.asarray(a), np.asarray(b), 0.3) for a, b in windows]
    out: list[Part] = []
    for a, length, along, inward in wall_edges(dressing, 1.4):
        count = max(1, int(length // WALL_DECOR_EVERY_M))
        for k in range(count):
            if rng.random() < 0.15:
                continue
            c = a + along * (k + 0.5) * length / count
            probe = grid.to_cell((c + inward * 0.4)[None])[0]
            if not (0 <= probe[0] < grid.shape[0] and 0 <= probe[1] < grid.shape[1]):
                continue
            if free[probe[0], probe[1]] < 0.2:  # something stands before it
                continue
            if any(segment_distance(c, s0, s1) < 0.8 + m for s0, s1, m in blocked_segments):
                continue
            out += _wall_piece(f"decor_{len(out)}", c, along, inward, dressing, art, sign, rng)
    return out


def _wall_piece(name: str, c: np.ndarray, along, inward, dressing, art: bool, sign: bool, rng) -> list[Part]:
    """A framed picture (canvas before a wider frame board) or a sign, centred on the wall at ``c``."""
    is_sign = sign and (not art or rng.random() < 0.5)
    w = rng.uniform(0.5, 1.0) if not is_sign else rng.uniform(0.6, 1.0)
    h = rng.uniform(0.4, 0.8) if not is_sign else 0.25
    zc = 1.55 if not is_sign else min(2.1, dressing.ceiling_height - 0.35)
    yaw = math.atan2(along[1], along[0])
    kind = "sign" if is_sign else "art"
    material = ARTS[int(rng.integers(len(ARTS)))] if not is_sign else SIGNS[int(rng.integers(len(SIGNS)))]
    front = c + inward * 0.012
    out = [Part(name, f"item:{kind}", "box", (float(front[0]), float(front[1])), yaw, (w / 2, 0.012), zc - h / 2,
                zc + h / 2, material, ("+y",))]  # fmt: skip
    if not is_sign:  # a frame board behind the canvas, 3 cm wider all round
        back = c + inward * 0.008
        out.append(Part(f"{name}/frame", f"item:{kind}", "box", (float(back[0]), float(back[1])), yaw,
                        (w / 2 + 0.03, 0.008), zc - h / 2 - 0.03, zc + h / 2 + 0.03, "wood_dark", ("+y",)))  # fmt: skip
    return out


def item_count(parts: list[Part]) -> int:
    """How many items (not parts: a potted plant's pot and leaves, a picture's canvas and frame count once)."""
    return len({p.name.split("/")[0] + "/" + p.name.split("/")[1] if p.name.count("/") >= 2 else p.name.split("/frame")[0]
                for p in parts if p.group.startswith("item:")})  # fmt: skip
