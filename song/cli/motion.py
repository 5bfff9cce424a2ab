"""``song motion``: re-run the motion stage of an existing run."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import handle_errors
from song.cli.synth import default_workers, run_chain_command
from song.pipeline.chain import read_run


@app.command("motion")
@handle_errors
def motion(
    run: Path = typer.Option(..., "--run", help="run folder made by song synth"),
    scene: str | None = typer.Option(None, "--scene", help="only this scene"),
    generator: str | None = typer.Option(None, "--generator", help="procedural | kimodo | auto"),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="worker processes (0 = all cores)"),
) -> None:
    """Full-body motion for each pedestrian (needs crowd); writes RUN/scenes/<id>/human_amass/."""
    scenes_dir, config = read_run(run)
    if generator is not None:
        if generator not in ("procedural", "kimodo", "auto"):
            raise typer.BadParameter("--generator must be procedural, kimodo or auto")
        config = config.model_copy(update={"motion": config.motion.model_copy(update={"generator": generator})})
    scene_ids = [scene] if scene else None
    results = run_chain_command(
        scenes_dir, run, config, ["motion"], workers or default_workers(), "process", None, False, scene_ids
    )
    if any(r.status == "failed" for r in results):
        raise typer.Exit(1)
