"""A results viewer: one HTML page per ``song eval`` output, each episode linked to its first-person video.

``song viz results --bench DIR --results runs/eval/social --out DIR [--videos N]`` writes ``index.html``
(a table of every episode: scene, difficulty, outcome, steps, time, path length, PSC, closest distance,
jerk, error) and, for the first ``N`` episodes, the policy's first-person video (RGB | depth | map,
:func:`song.viz.pov.render_pov`), linked from its row. The videos re-run the policy on the episode
with the runtime of ``song eval``, so a deterministic policy draws the run the table scores. Every
string from the results or the release is escaped: a results file is untrusted input.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import Any

from song.util import check_id, write_text_atomic

COLUMNS = ("episode_id", "scene_id", "difficulty", "outcome", "steps", "time", "length", "psc", "min_distance", "jerk")
STYLE = """body{font:14px system-ui,sans-serif;margin:24px;color:#222}table{border-collapse:collapse}
td,th{padding:4px 10px;border-bottom:1px solid #ddd;text-align:left}th{background:#f3f3f3}
.success{color:#1a7f37}.human,.obstacle,.timeout,.stuck,.error{color:#b42318}"""


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return "–" if not math.isfinite(value) else f"{value:.2f}"
    return html.escape("" if value is None else str(value))


def render_results_page(
    bench: str,
    results_parquet: Path,
    out_dir: str | Path,
    videos: int = 12,
    size: tuple[int, int] = (320, 240),
    backend: str = "auto",
) -> list[Path]:
    """Write ``index.html`` and the first ``videos`` episodes' first-person videos into ``out_dir``."""
    import pyarrow.parquet as pq

    from song.viz.pov import render_pov

    table = pq.read_table(results_parquet)
    about = json.loads((table.schema.metadata or {}).get(b"song.eval", b"{}") or b"{}")
    policy = str(about.get("policy") or table.column("policy")[0].as_py())
    rows = table.select([c for c in COLUMNS if c in table.column_names] + ["error"]).to_pylist()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    links: dict[str, str] = {}
    for row in rows[: max(0, videos)]:
        episode_id = check_id(str(row["episode_id"]), "episode id")
        video = render_pov(bench, episode_id, policy, out_dir, size, backend)[0]
        links[episode_id] = video.name
        written.append(video)
    header = "".join(f"<th>{html.escape(c)}</th>" for c in (*COLUMNS, "video", "error"))
    lines = []
    for row in rows:
        outcome = html.escape(str(row["outcome"]))
        cells = [f'<td class="{outcome}">' if c == "outcome" else "<td>" for c in COLUMNS]
        cells = [f"{td}{_cell(row.get(c))}</td>" for td, c in zip(cells, COLUMNS, strict=True)]
        link = links.get(str(row["episode_id"]))
        cells.append(f'<td><a href="{html.escape(link)}">first-person video</a></td>' if link else "<td></td>")
        cells.append(f"<td>{_cell(row.get('error'))}</td>")
        lines.append("<tr>" + "".join(cells) + "</tr>")
    release = about.get("release", {})
    title = f"{policy}: {len(rows)} episodes of release {release.get('version', '?')} ({release.get('path', bench)})"
    note = (
        f"{len(links)} of {len(rows)} episodes have a video here; render another with "
        f"<code>song viz pov --bench {html.escape(str(bench))} --policy {html.escape(policy)} --episode ID</code>."
    )
    page = (
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{STYLE}</style></head><body><h1>{html.escape(title)}</h1><p>{note}</p>"
        f"<table><tr>{header}</tr>{''.join(lines)}</table></body></html>\n"
    )
    index = out_dir / "index.html"
    write_text_atomic(index, page)
    return [index, *written]
