"""``song bind``: (re-)run the binding stage of an existing run."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import handle_errors
from song.cli.synth import default_workers, run_chain_command
from song.pipeline.chain import read_run


@app.command("bind")
@handle_errors
def bind(
    run: Path = typer.Option(..., "--run", help="run folder made by song synth (with motion)"),
    avatars: Path | None = typer.Option(None, "--avatars", help="folder of *.avatar.npz (default: the cached pool)"),
    materialize: bool = typer.Option(False, "--materialize", help="also write the paper's FP16 Gaussian caches"),
    scene: str | None = typer.Option(None, "--scene", help="only this scene"),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="worker processes (0 = all cores)"),
) -> None:
    """Bind each pedestrian's motion to an avatar identity; writes RUN/scenes/<id>/binding/."""
    scenes_dir, config = read_run(run)
    update = {"materialize": materialize or config.binding.materialize}
    if avatars is not None:
        update["avatars_dir"] = str(avatars.resolve())
    config = config.model_copy(update={"binding": config.binding.model_copy(update=update)})
    scene_ids = [scene] if scene else None
    results = run_chain_command(
        scenes_dir, run, config, ["binding"], workers or default_workers(), "process", None, False, scene_ids
    )
    if any(r.status == "failed" for r in results):
        raise typer.Exit(1)
