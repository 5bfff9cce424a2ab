"""``song synth``: the per-scene chain intents → crowd → motion → binding."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import ConfigOption, SeedOption, console, handle_errors, make_config, status_table
from song.pipeline.chain import iter_run, load_stages


@app.command("synth")
@handle_errors
def synth(
    scenes: Path = typer.Option(..., "--scenes", help="folder of scene packages"),
    out: Path = typer.Option(..., "--out", help="run folder (created; re-running resumes)"),
    config: Path | None = ConfigOption,
    seed: int | None = SeedOption,
    workers: int = typer.Option(1, "--workers", "-j", min=1, help="parallel worker processes"),
) -> None:
    """Run every registered per-scene stage on every scene package."""
    cfg = make_config(config, seed)
    names = [stage.name for stage in load_stages()]
    rows = []
    for result in iter_run(scenes, out, cfg, workers=workers):
        row = {"scene": result.scene_id, "status": result.status, "error": result.error}
        row.update({name: result.stages.get(name, "") for name in names})
        rows.append(row)
    rows.sort(key=lambda row: row["scene"])
    console.print(status_table(f"synth → {out}", rows, ["scene", *names, "status", "error"]))
    failed = sum(row["status"] == "failed" for row in rows)
    console.print(f"{len(rows) - failed} scenes ok, {failed} failed; stages: {', '.join(names) or 'none'}")
    if failed:
        raise typer.Exit(1)
