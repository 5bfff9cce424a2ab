"""``song grade``: episodes, factors, difficulty split, manifest."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import console, handle_errors, status_table
from song.pipeline.grading import grade_run


@app.command("grade")
@handle_errors
def grade(
    run: Path = typer.Option(..., "--run", help="run folder made by song synth"),
    episodes: int | None = typer.Option(None, "--episodes", min=1, help="total episodes (default: config, 500)"),
    workers: int = typer.Option(1, "--workers", "-j", min=1, help="worker processes (scenes in parallel)"),
) -> None:
    """Sample robot episodes over all scenes, grade them easy/medium/hard, write RUN/manifest/."""
    result = grade_run(run, n_episodes=episodes, workers=workers)
    rows = [{"difficulty": d, **{m: str(c) for m, c in modes.items()}} for d, modes in result.summary["counts"].items()]
    modes = list(next(iter(result.summary["counts"].values())).keys())
    console.print(
        status_table(f"{result.summary['episodes']} episodes in {run}/manifest", rows, ["difficulty", *modes])
    )
    for factor, report in result.summary["bins"].items():
        occupancy = " / ".join(str(c) for c in report["occupancy"])
        console.print(f"{factor}: bins {occupancy} (easy→hard), {report['distinct']} distinct values")
    for scene, why in sorted(result.summary["infeasible"].items()):
        console.print(f"[yellow]infeasible[/yellow] {scene}: {why}")
