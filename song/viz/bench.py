"""``song viz bench``: the paper's Fig. 3 left, factor histograms, mode × difficulty counts, results bars."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from song.datasets.bench import open_benchmark
from song.render.draw import DIFFICULTY_COLOURS

FACTORS = (
    ("path_length", "optimal path length L* (m)"),
    ("n_turns", "significant turns"),
    ("n_encounters", "avatar encounters"),
    ("corridor_width", "corridor width (m)"),
)
ORDER = ("easy", "medium", "hard")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def render_bench(bench: str, out_dir: str | Path, results: list[str | Path] | None = None) -> list[Path]:
    """Write ``encounters_vs_length.png``, ``factors.png``, ``modes.png`` (+ ``results.png``)."""
    plt = _pyplot()
    release = open_benchmark(bench)
    table = release.episodes_table.to_pydict()
    difficulty = np.asarray(table["difficulty"])
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []

    fig, ax = plt.subplots(figsize=(5.5, 4.2), dpi=130)
    rng = np.random.default_rng(0)  # jitter only to show overlapping integer counts
    for name in ORDER:
        mask = difficulty == name
        enc = np.asarray(table["n_encounters"])[mask] + rng.uniform(-0.15, 0.15, mask.sum())
        ax.scatter(
            np.asarray(table["geodesic_distance"])[mask],
            enc,
            s=14,
            alpha=0.75,
            c=DIFFICULTY_COLOURS[name],
            label=f"{name} ({mask.sum()})",
        )
    ax.set_xlabel("optimal path length L* (m)")
    ax.set_ylabel("avatar encounters")
    ax.set_title(f"SONG {release.version}: episodes by difficulty")
    ax.legend(frameon=False)
    fig.tight_layout()
    written.append(out_dir / "encounters_vs_length.png")
    fig.savefig(written[-1])
    plt.close(fig)

    fig, axes = plt.subplots(1, 4, figsize=(14, 3.4), dpi=110)
    for ax, (column, title) in zip(axes, FACTORS, strict=True):
        values = np.asarray(table[column], dtype=np.float64)
        bins = np.histogram_bin_edges(values, bins=12)
        for name in ORDER:
            ax.hist(values[difficulty == name], bins=bins, alpha=0.55, color=DIFFICULTY_COLOURS[name], label=name)
        ax.set_title(title, fontsize=9)
    axes[0].legend(frameon=False, fontsize=8)
    fig.tight_layout()
    written.append(out_dir / "factors.png")
    fig.savefig(written[-1])
    plt.close(fig)

    modes = sorted(set(table["mode"]))
    counts = np.array([[np.sum((difficulty == d) & (np.asarray(table["mode"]) == m)) for m in modes] for d in ORDER])
    fig, ax = plt.subplots(figsize=(6, 3), dpi=120)
    ax.imshow(counts, cmap="Blues")
    ax.set_xticks(range(len(modes)), [m.replace("_", "\n") for m in modes], fontsize=8)
    ax.set_yticks(range(3), ORDER)
    for (i, j), value in np.ndenumerate(counts):
        ax.text(j, i, int(value), ha="center", va="center", fontsize=9)
    ax.set_title("episodes per sampling mode × difficulty", fontsize=10)
    fig.tight_layout()
    written.append(out_dir / "modes.png")
    fig.savefig(written[-1])
    plt.close(fig)

    if results:
        written.append(_results_figure(plt, [Path(p) for p in results], out_dir / "results.png"))
    return written


def _results_figure(plt, paths: list[Path], out: Path) -> Path:
    summaries = [json.loads(p.read_text()) for p in paths]
    metrics = ("SR", "SPL", "CR_hum", "PSC")
    fig, axes = plt.subplots(1, len(metrics), figsize=(13, 3.2), dpi=110)
    width = 0.8 / len(summaries)
    for ax, metric in zip(axes, metrics, strict=True):
        for k, summary in enumerate(summaries):
            values = [(summary["metrics"].get(d) or {}).get(metric) or 0.0 for d in ORDER]
            ax.bar(np.arange(3) + k * width, values, width, label=summary["policy"])
        ax.set_xticks(np.arange(3) + 0.4 - width / 2, ORDER)
        ax.set_title(f"{metric} (%)", fontsize=10)
    axes[0].legend(frameon=False, fontsize=8)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out
