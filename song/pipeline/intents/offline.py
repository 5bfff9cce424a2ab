"""``OfflineIntentModel``: deterministic, venue-aware intents over a scene's real objects.

It proposes start→goal object pairs the way prompt B asks an LLM to: routines that make sense for the
venue, preferring long, cross-region and functionally related pairs, each with an activity phrase
built from the venue's vocabulary and the objects' actual names. Same scene + seed → same proposals.
"""

from __future__ import annotations

import numpy as np

from song.datasets.scenes import SceneObject, SemanticMap

# goal keyword → activity templates per venue ("{start}" / "{goal}" are object names)
VENUE_TEMPLATES: dict[str, dict[str, list[str]]] = {
    "home": {
        "fridge": ["walks from the {start} to the fridge to get a drink", "goes to the fridge for a snack"],
        "counter": ["walks to the kitchen counter to make coffee", "carries dishes from the {start} to the counter"],
        "sofa": ["walks from the {start} to the sofa to watch TV", "heads to the sofa to rest"],
        "bed": ["walks from the {start} to the bed to lie down", "goes to the bedroom to fetch a blanket"],
        "dining": ["brings a plate from the {start} to the dining table", "walks to the dining table for dinner"],
        "desk": ["walks from the {start} to the desk to check email", "goes to the desk to pick up a charger"],
        "toilet": ["walks from the {start} to the bathroom", "heads to the bathroom to wash up"],
        "sink": ["walks to the sink to wash hands", "carries a cup from the {start} to the sink"],
        "dresser": ["walks to the dresser to get clothes", "puts laundry away in the dresser"],
        "": ["walks from the {start} to the {goal}", "tidies up, moving from the {start} to the {goal}"],
    },
    "office": {
        "reception": [
            "walks from the {start} to the reception desk to collect a parcel",
            "asks reception about a visitor",
        ],
        "workstation": [
            "walks from the {start} to {goal} to drop off a document",
            "returns from the {start} to {goal}",
        ],
        "desk": ["walks from the {start} to {goal} to drop off a parcel", "goes back to {goal} after a break"],
        "printer": [
            "walks from {start} to the printer to collect a print-out",
            "heads to the printer with a USB stick",
        ],
        "meeting": ["walks from {start} to the meeting table for a meeting", "joins colleagues at the meeting table"],
        "coffee": ["walks to the coffee machine for a refill", "takes a coffee break away from {start}"],
        "": ["walks from the {start} to the {goal}", "carries files from the {start} to the {goal}"],
    },
    "clinic": {
        "reception": [
            "walks from the {start} to the reception to check in",
            "asks at reception for the next appointment",
        ],
        "consult": ["walks from the waiting area to {goal}", "is called into {goal}"],
        "waiting": ["walks from {start} back to the waiting area", "sits down again in the waiting area"],
        "": ["walks from the {start} to the {goal}", "a nurse walks from the {start} to the {goal}"],
    },
    "shop": {
        "counter": ["walks from the {start} to the counter to pay", "queues at the checkout counter"],
        "shel": ["browses from the {start} to {goal}", "looks for a product on {goal}"],
        "": ["walks from the {start} to the {goal}", "a clerk restocks, walking from the {start} to the {goal}"],
    },
    "restaurant": {
        "counter": ["walks from {start} to the counter to order", "a waiter picks up food at the counter"],
        "table": ["walks from the {start} to {goal} to sit down", "a waiter serves {goal}"],
        "": ["walks from the {start} to the {goal}", "leaves {start} for the {goal}"],
    },
    "library": {
        "shel": ["walks from {start} to {goal} to find a book", "returns a book to {goal}"],
        "desk": ["walks to the help desk to borrow a book", "checks out books at the desk"],
        "table": ["walks from {start} to a reading table", "settles at {goal} to study"],
        "": ["walks from the {start} to the {goal}", "browses from the {start} to the {goal}"],
    },
    "lobby": {
        "reception": ["walks from the entrance to the reception desk to check in", "asks reception for directions"],
        "elevator": ["walks from {start} to the elevators", "heads to the lifts with luggage"],
        "sofa": ["waits on the sofa after walking from {start}", "walks to the lounge sofas"],
        "": ["walks from the {start} to the {goal}", "crosses the lobby from the {start} to the {goal}"],
    },
}
VENUE_ALIASES = {"hotel": "lobby", "station": "lobby", "museum": "lobby", "school": "library", "other": "home"}
# functional relations: pairs of keywords that belong to one routine (bonus when proposing pairs)
RELATED = [
    ("fridge", "counter"),
    ("counter", "dining"),
    ("sofa", "television"),
    ("bed", "dresser"),
    ("toilet", "sink"),
    ("desk", "printer"),
    ("reception", "waiting"),
    ("waiting", "consult"),
    ("shel", "counter"),
    ("entrance", "reception"),
    ("table", "counter"),
]


def venue_vocabulary(venue: str) -> dict[str, list[str]]:
    """The activity templates of a venue (aliases resolved)."""
    return VENUE_TEMPLATES.get(venue, VENUE_TEMPLATES[VENUE_ALIASES.get(venue, "home")])


def _name(obj: SceneObject) -> str:
    number = obj.id.rsplit("_", 1)[-1]
    return f"{obj.label} {number}" if number.isdigit() and int(number) > 1 else obj.label


def _keyword(obj: SceneObject, vocabulary: dict[str, list[str]]) -> str:
    text = f"{obj.id} {obj.label} {obj.category}".lower()
    return next((key for key in vocabulary if key and key in text), "")


def activity_phrase(venue: str, start: SceneObject, goal: SceneObject, rng: np.random.Generator) -> str:
    """An activity sentence for walking from ``start`` to ``goal`` in a venue."""
    vocabulary = venue_vocabulary(venue)
    templates = vocabulary[_keyword(goal, vocabulary)]
    template = templates[int(rng.integers(len(templates)))]
    return template.format(start=_name(start), goal=_name(goal))


def relatedness(a: SceneObject, b: SceneObject) -> float:
    """1 when the two objects form a known routine pair, else 0."""
    ta, tb = f"{a.id} {a.label}".lower(), f"{b.id} {b.label}".lower()
    return float(any((x in ta and y in tb) or (y in ta and x in tb) for x, y in RELATED))


MAX_STARTS_PER_OBJECT = 6  # most routines proposed from one object (after two each, while more are needed)
ROUTE_REPEATS = 3  # most people proposed for the same start and goal objects (distinct spots around them)


class OfflineIntentModel:
    """Proposes ``n`` (start object, goal object, activity) routines for a scene, deterministically."""

    provider = "offline"
    model = "song-offline-v1"

    def propose(
        self,
        smap: SemanticMap,
        geodesic: dict[tuple[str, str], float],
        n: int,
        rng: np.random.Generator,
    ) -> list[tuple[str, str, str]]:
        """Pick pairs by score = length + cross-region + relatedness bonuses, with seeded tie-breaking noise.

        Args:
            smap: the scene's semantic map.
            geodesic: estimated walking distance (m) between reachable object pairs (ids).
            n: how many proposals to return.
            rng: seeded generator (tie-breaking noise).
        """
        objects = smap.object_by_id()
        scored = []
        for (a, b), length in sorted(geodesic.items()):
            oa, ob = objects[a], objects[b]
            cross = 1.0 if oa.region != ob.region else 0.0
            score = min(length, 15.0) / 15.0 + 0.6 * cross + 0.8 * relatedness(oa, ob) + 0.5 * rng.random()
            scored.append((score, a, b))
        scored.sort(key=lambda item: -item[0])
        chosen, used_starts, pairs = [], {}, set()
        # first two routines per start object over distinct pairs (variety); in a scene with few objects
        # and many people, further passes let more people start at an object and walk a pair again
        for cap, repeat in ((2, False), (MAX_STARTS_PER_OBJECT, False), (MAX_STARTS_PER_OBJECT, True)):
            for _, a, b in scored:
                if len(chosen) >= n:
                    return chosen
                if used_starts.get(a, 0) >= cap or (not repeat and ((a, b) in pairs or (b, a) in pairs)):
                    continue
                if repeat and sum(x == a and y == b for x, y, _ in chosen) >= ROUTE_REPEATS:
                    continue
                used_starts[a] = used_starts.get(a, 0) + 1
                pairs.add((a, b))
                chosen.append((a, b, activity_phrase(smap.venue_type, objects[a], objects[b], rng)))
        return chosen
