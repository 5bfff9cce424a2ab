"""Narrow passages of a navmesh (doors and gaps two people cannot pass each other in), and queues at them.

A passage is where the navmesh (the set of legal centres) is narrower than one body diameter, so two
pedestrians cannot be side by side across it: a disc of radius r does not fit inside the mesh there. On a
raster of the mesh, that is the mesh minus its morphological opening by a disc of radius r
(``scipy.ndimage.binary_opening``), grown by ``ZONE_M`` within the mesh (the throat of a door in a thin
wall is only a line). A part counts when taking it out of the mesh leaves two or more pieces beside it
(its sides: the rooms a door joins); the slivers the opening shaves off the mesh's sharp corners, and
narrow dead ends, leave one. In the two-room test scene doors of 0.9 and 1.0 m are passages, 1.1 m and
wider are not (two people pass there).

The flow rule (:class:`Queues`, ``crowd.queue_at_passages``): a walker looks ``APPROACH_M`` along its
way; coming to a passage used the other way it waits clear of the opening on its own side, ``HOLD_M``
back and ``SIDE_M`` to the right of its way (so those coming out walk past), later arrivals behind it.
A clear passage goes to the side whose walker asked first, all of that side at once; a walker heading the
same way as those in it follows them unless someone waits on the other side. Waiting (and going through)
is not being stuck for ``PATIENCE_S``. Helbing et al. (2005, Transportation Science 39(1)) describe this
one-side-at-a-time flow at narrow bottlenecks with counterflow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from song.geometry.navmesh import Navmesh

CELL_M = 0.05  # raster of the mesh
ZONE_M = 0.3  # a passage reaches this far beyond where the mesh is narrow (the throat of a door is a line)
WINDOW_M = 0.6  # how far around a narrow zone it is checked to join two stretches of the mesh
MIN_PIECE_M2 = 0.05  # smaller pieces left beside a narrow zone do not count as a side of it
APPROACH_M = 2.5  # a walker this far (along its path) from a passage asks for it: room to stop at 1 m/s²
HOLD_M = 1.0  # a waiter stands this far before the passage's edge ...
SIDE_M = 0.6  # ... and this far to the right of its way, so those coming out pass it
QUEUE_GAP_M = 0.6  # later waiters on the same side line up behind, this far apart
PATIENCE_S = 20.0  # waiting at a passage, or following others through it, counts as progress this long
LOOK_STEP_M = 0.1  # the path is looked along in steps of this (a passage is at least 2 ZONE_M across)


@dataclass
class Passages:
    """Labelled raster of the narrow passages: ``labels`` (rows, cols) int32, −1 outside every passage."""

    labels: np.ndarray
    origin: np.ndarray  # (2,) m: the corner of cell (0, 0)
    count: int
    sides: list[tuple[int, int, np.ndarray]]  # per passage: (row, col) of a window around it, its sides there

    def _lookup(self, raster: np.ndarray, row: int, col: int, points: np.ndarray) -> np.ndarray:
        """(M,) the values of ``raster`` (whose first cell is cell (row, col)) at points (M, 2); −1 off it."""
        ij = np.floor((np.asarray(points, dtype=np.float64) - self.origin) / CELL_M).astype(np.int64) - [col, row]
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < raster.shape[1]) & (ij[:, 1] >= 0) & (ij[:, 1] < raster.shape[0])
        out = np.full(len(ij), -1, dtype=np.int64)
        out[ok] = raster[ij[ok, 1], ij[ok, 0]]
        return out

    def side_at(self, passage: int, points: np.ndarray) -> np.ndarray:
        """(M,) which side of ``passage`` each point (M, 2) is on, −1 where none (inside it, or away from it)."""
        row, col, sides = self.sides[passage]
        return self._lookup(sides, row, col, points)

    def label_at(self, points: np.ndarray) -> np.ndarray:
        """(M,) passage of each point (M, 2), −1 where none."""
        return self._lookup(self.labels, 0, 0, points)


def _disc(radius: float) -> np.ndarray:
    """A disc of ``radius`` m as a structuring element on the raster."""
    k = int(np.floor(radius / CELL_M))
    yy, xx = np.mgrid[-k : k + 1, -k : k + 1]
    return xx * xx + yy * yy <= (radius / CELL_M) ** 2


def _sides(inside: np.ndarray, parts: np.ndarray, i: int, box: tuple[slice, slice]):
    """The sides of part ``i`` of the narrow zones, when it joins two stretches of the mesh (a door, a corridor).

    Taken out of the mesh, within ``WINDOW_M`` of it, it leaves at least two pieces of ``MIN_PIECE_M2`` or
    more that touch it: the sides of a door. Returns ``(row, col, sides)``: the window's first cell and its
    raster of side numbers (−1 elsewhere); None for the sliver the opening shaves off a sharp corner of
    the mesh, or a narrow dead end, which leave one.
    """
    g = int(round(WINDOW_M / CELL_M))
    rows, cols = inside.shape
    win = (slice(max(box[0].start - g, 0), min(box[0].stop + g, rows)),
           slice(max(box[1].start - g, 0), min(box[1].stop + g, cols)))  # fmt: skip
    part = parts[win] == i
    rest = inside[win] & (parts[win] == 0)
    pieces, n = ndimage.label(rest, structure=np.ones((3, 3), dtype=bool))
    if n < 2:
        return None
    touching = np.unique(pieces[ndimage.binary_dilation(part, structure=np.ones((3, 3), dtype=bool)) & rest])
    touching = touching[touching > 0]
    sides = touching[ndimage.sum_labels(rest, pieces, index=touching) * CELL_M**2 >= MIN_PIECE_M2]
    if len(sides) < 2:
        return None
    number = np.full(n + 1, -1, dtype=np.int32)
    number[sides] = np.arange(len(sides), dtype=np.int32)
    return win[0].start, win[1].start, number[pieces]


def find_passages(mesh: Navmesh, radius: float) -> Passages:
    """The narrow passages of ``mesh`` (legal centres of bodies of ``radius`` m), see the module doc."""
    if not len(mesh.triangles):
        return Passages(np.full((1, 1), -1, dtype=np.int32), np.zeros(2), 0, [])
    lo = mesh.vertices.min(axis=0) - CELL_M
    hi = mesh.vertices.max(axis=0) + CELL_M
    cols, rows = (np.ceil((hi - lo) / CELL_M).astype(int) + 1).tolist()
    xs, ys = lo[0] + (np.arange(cols) + 0.5) * CELL_M, lo[1] + (np.arange(rows) + 0.5) * CELL_M
    centres = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    inside = (mesh.locate(centres) >= 0).reshape(rows, cols)
    disc = _disc(radius)
    narrow = inside & ~ndimage.binary_opening(inside, structure=disc)
    zone = inside & ndimage.binary_dilation(narrow, structure=_disc(ZONE_M))
    parts, n = ndimage.label(zone, structure=np.ones((3, 3), dtype=bool))
    relabel = np.full(n + 1, -1, dtype=np.int32)
    sides = []
    for i, box in enumerate(ndimage.find_objects(parts), start=1):
        found = _sides(inside, parts, i, box)
        if found is not None:
            relabel[i] = len(sides)
            sides.append(found)
    return Passages(relabel[parts], lo, len(sides), sides)


def path_ahead(pos: np.ndarray, corners: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``LOOK_STEP_M`` along the polyline pos → corners, up to ``reach`` m: (points (M, 2), s (M,)).

    The plain twin of :func:`_ahead_kernel` (which also labels the points, compiled: a walker near a
    passage is looked along three times a second).
    """
    poly = np.vstack([pos[None], corners])
    seg = np.diff(poly, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(length)])
    end = min(reach, cum[-1])
    s = np.arange(0.0, end + 1e-9, LOOK_STEP_M)
    if s[-1] < end:
        s = np.append(s, end)
    if not len(seg):
        return np.repeat(pos[None], len(s), axis=0), s
    j = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    frac = (s - cum[j]) / np.maximum(length[j], 1e-12)
    return poly[j] + np.clip(frac, 0.0, 1.0)[:, None] * seg[j], s


@dataclass
class Crossing:
    """The next passage on a walker's way: which, where it enters it, how far that is, which way it goes."""

    passage: int
    entry: np.ndarray  # (2,) m: the last point of the way before the passage
    distance: float  # along the path to the entry, m (0 when inside)
    sides: tuple[int, int]  # the sides it comes from and goes to (−1: not known, e.g. a start inside it)


@numba.njit(cache=True, nogil=True)
def _ahead_kernel(pos, corners, step, reach, labels, origin, cell):  # pragma: no cover
    """:func:`path_ahead`'s points and s, and each point's passage (:meth:`Passages.label_at`), compiled."""
    n = len(corners)
    cum = np.zeros(n + 1)
    px, py = pos[0], pos[1]
    for i in range(n):
        cum[i + 1] = cum[i] + np.hypot(corners[i, 0] - px, corners[i, 1] - py)
        px, py = corners[i, 0], corners[i, 1]
    end = min(reach, cum[n])
    m = int(np.floor((end + 1e-9) / step)) + 1
    extra = (m - 1) * step < end
    total = m + 1 if extra else m
    points, s, lab = np.empty((total, 2)), np.empty(total), np.full(total, -1, dtype=np.int64)
    rows, cols = labels.shape
    j = 0
    for k in range(total):
        sk = k * step if k < m else end
        s[k] = sk
        if n == 0:
            points[k, 0], points[k, 1] = pos[0], pos[1]
        else:
            while j + 1 < n and cum[j + 1] <= sk:
                j += 1
            ax, ay = (pos[0], pos[1]) if j == 0 else (corners[j - 1, 0], corners[j - 1, 1])
            length = cum[j + 1] - cum[j]
            frac = min(max((sk - cum[j]) / max(length, 1e-12), 0.0), 1.0)
            points[k, 0] = ax + frac * (corners[j, 0] - ax)
            points[k, 1] = ay + frac * (corners[j, 1] - ay)
        ci = int(np.floor((points[k, 0] - origin[0]) / cell))
        ri = int(np.floor((points[k, 1] - origin[1]) / cell))
        if 0 <= ci < cols and 0 <= ri < rows:
            lab[k] = labels[ri, ci]
    return points, s, lab


def next_crossing(passages: Passages, pos: np.ndarray, corners: np.ndarray) -> Crossing | None:
    """The first passage within ``APPROACH_M`` along pos → corners (None when there is none)."""
    points, s, labels = _ahead_kernel(
        np.ascontiguousarray(pos, dtype=np.float64), np.ascontiguousarray(corners, dtype=np.float64).reshape(-1, 2),
        LOOK_STEP_M, APPROACH_M + 2.0, passages.labels, passages.origin, CELL_M,
    )  # fmt: skip
    hits = np.flatnonzero(labels >= 0)
    if not len(hits) or s[hits[0]] > APPROACH_M:
        return None
    first, p = hits[0], int(labels[hits[0]])
    out = np.flatnonzero(labels[first:] != p)
    last = first + (out[0] - 1 if len(out) else len(labels) - 1 - first)
    entry = points[first - 1] if first > 0 else points[0]  # the last point before it: where its edge is
    before = passages.side_at(p, points[:first][::-1])
    after = passages.side_at(p, points[last + 1 :])
    sides = (_first_known(before), _first_known(after))
    return Crossing(p, entry.copy(), float(s[first]), sides)


def _first_known(sides: np.ndarray) -> int:
    known = sides[sides >= 0]
    return int(known[0]) if len(known) else -1


class Queues:
    """Who may go through which passage, who waits where (the flow rule of the module doc).

    Per walker: the passage next on its way (−1: none within ``APPROACH_M``), whether it has it, since
    when it asked, where it enters and which way it goes through, and where it waits meanwhile.
    """

    def __init__(self, passages: Passages, mesh: Navmesh, n: int):
        self.passages, self.mesh = passages, mesh
        self.passage = np.full(n, -1, dtype=np.int64)
        self.granted = np.zeros(n, dtype=bool)
        self.since = np.zeros(n)
        self.entry = np.zeros((n, 2))
        self.sides = np.full((n, 2), -1, dtype=np.int64)  # the sides each comes from and goes to
        self.distance = np.zeros(n)  # along its way to the passage at the last look, m (0: in it)
        self.hold = np.zeros((n, 2))
        if passages.count:
            ys, xs = np.nonzero(passages.labels >= 0)
            centres = passages.origin + (np.column_stack([xs, ys]) + 0.5) * CELL_M
            lab = passages.labels[ys, xs]
            self._centre = np.array([centres[lab == p].mean(axis=0) for p in range(passages.count)])
            self._extent = np.array(
                [np.hypot(*(centres[lab == p] - self._centre[p]).T).max() for p in range(passages.count)]
            )

    @property
    def waiting(self) -> np.ndarray:
        """(N,) bool: asked for a passage and waiting for it."""
        return (self.passage >= 0) & ~self.granted

    def patient(self, t: float) -> np.ndarray:
        """(N,) bool: at a passage, waiting for it or going through, for less than ``PATIENCE_S``: not stuck.

        A walker queueing, or following others through, makes no progress for a while without being stuck;
        after ``PATIENCE_S`` it stalls as anyone does (replans, steps aside, gives the stop up).
        """
        return (self.passage >= 0) & (t - self.since < PATIENCE_S)

    def update(self, pos: np.ndarray, ahead: list[np.ndarray], moving: np.ndarray, t: float) -> np.ndarray:
        """Look along the walkers' ways, ask for passages, grant them; returns those granted now.

        ``ahead``: per walker the corners still ahead of it (its path from the current corner on).
        """
        n = len(pos)
        if not self.passages.count:
            return np.zeros(0, dtype=np.int64)
        near = np.zeros(n, dtype=bool)
        if moving.any():
            gap = np.hypot(*(pos[:, None] - self._centre[None]).transpose(2, 0, 1)) - self._extent[None]
            near = moving & (gap.min(axis=1) <= APPROACH_M)
        for k in range(n):
            crossing = next_crossing(self.passages, pos[k], ahead[k]) if near[k] else None
            if crossing is None:
                self.passage[k], self.granted[k] = -1, False
                continue
            if crossing.passage != self.passage[k]:
                self.passage[k], self.granted[k], self.since[k] = crossing.passage, False, t
            self.entry[k], self.sides[k], self.distance[k] = crossing.entry, crossing.sides, crossing.distance
            if crossing.distance <= 0.0:  # inside already: it goes on
                self.granted[k] = True
        granted: list[int] = []
        for p in np.unique(self.passage[self.waiting]):
            at = self.passage == p
            waiting = np.flatnonzero(at & ~self.granted)
            inside = np.flatnonzero(at & self.granted)
            if not len(inside):  # clear: it goes to the side that has waited longest, all of it
                first = min(waiting, key=lambda k: (self.since[k], k))
                go = waiting[~self._against(first)[waiting]]
            elif self._against(inside[0])[waiting].all():  # in use the other way: everyone waits
                go = waiting[:0]
            else:  # in use this way: followers go on while nobody waits on the other side
                same = ~self._against(inside[0])[waiting]
                go = waiting[same] if same.all() else waiting[:0]
            self.granted[go] = True
            granted.extend(go.tolist())
        self._place(pos)
        return np.array(granted, dtype=np.int64)

    def _against(self, k: int) -> np.ndarray:
        """(N,) bool: who goes through a passage the other way from k.

        From the other side, when the sides both come from are known; else to the other side, when the
        sides both go to are.
        """
        f, g = self.sides[:, 0], self.sides[:, 1]
        fk, gk = self.sides[k]
        from_known = (f >= 0) & (fk >= 0)
        return np.where(from_known, f != fk, (g >= 0) & (gk >= 0) & (g != gk))

    def _place(self, pos: np.ndarray) -> None:
        """Where each waiter stands: beside its way before the passage, behind those on its side who came first."""
        for k in np.flatnonzero(self.waiting):
            d = self._centre[self.passage[k]] - self.entry[k]
            d /= max(float(np.hypot(*d)), 1e-9)
            side = (self.passage == self.passage[k]) & self.waiting & ~self._against(k)
            rank = int(
                ((self.since < self.since[k]) | ((self.since == self.since[k]) & (np.arange(len(pos)) < k)))[side].sum()
            )
            back = HOLD_M + rank * QUEUE_GAP_M
            ahead_m = float(np.hypot(*(self.entry[k] - pos[k])))
            self.hold[k] = pos[k]
            if rank and back >= ahead_m - 0.05:  # the queue reaches past it: it stops where it is
                continue
            right = np.array([d[1], -d[0]])
            for offset in (SIDE_M, 0.0):
                spot = self.entry[k] - d * back + right * offset
                if (
                    self.mesh.contains(spot[None])[0]
                    and self.passages.label_at(spot[None])[0] < 0
                    and self.mesh.segment_clear(pos[k][None], spot[None])[0]
                ):
                    self.hold[k] = spot
                    break
