"""What the trust checks cost: the release integrity check at open, and ``song eval --isolate`` per step.

.venv/bin/python benchmarks/trust.py [--bench runs/demo-bench] [--episodes 12] [--policy astar] [--rounds 2]

Prints JSON: the seconds to open the release and to check it, and per round the milliseconds per
step of the same episodes evaluated in-process and isolated (interleaved, one worker), with the
outcomes (they must be the same).
"""

from __future__ import annotations

import argparse
import json
import time


def main() -> None:
    from song.datasets.bench import open_benchmark
    from song.runtime.evaluate import iter_eval, make_setup

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", default="runs/demo-bench")
    parser.add_argument("--episodes", type=int, default=12)
    parser.add_argument("--policy", default="astar")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()

    started = time.perf_counter()
    bench = open_benchmark(args.bench)
    opened = time.perf_counter() - started
    started = time.perf_counter()
    problem = bench.integrity
    checked = time.perf_counter() - started
    episodes = list(bench.episodes())[: args.episodes]
    rounds = []
    for _ in range(args.rounds):
        row = {}
        for isolate in (False, True):
            setup = make_setup(bench, args.policy, isolate=isolate)
            started = time.perf_counter()
            results = list(iter_eval(bench, setup, episodes, 1))
            seconds = time.perf_counter() - started
            steps = sum(r.steps for r in results)
            row["isolated" if isolate else "in_process"] = {
                "steps": steps,
                "ms_per_step": round(1000 * seconds / max(steps, 1), 3),
                "outcomes": sorted(r.outcome for r in results),
            }
        rounds.append(row)
    report = {"release": str(bench.root), "open_s": round(opened, 4), "integrity_s": round(checked, 4),
              "integrity": problem or "ok", "rounds": rounds}  # fmt: skip
    print(json.dumps(report, indent=1))


if __name__ == "__main__":  # the isolated policy's process is spawned: it re-imports this module
    main()
