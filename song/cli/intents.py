"""``song intents`` and ``song crowd``: re-run one stage of an existing run."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import handle_errors
from song.cli.synth import default_workers, run_chain_command
from song.pipeline.chain import read_run


def _rerun(run: Path, stage: str, scene: str | None, workers: int, **overrides) -> None:
    scenes_dir, config = read_run(run)
    for section, values in overrides.items():
        values = {k: v for k, v in values.items() if v is not None}
        if values:
            config = config.model_copy(update={section: getattr(config, section).model_copy(update=values)})
    scene_ids = [scene] if scene else None
    results = run_chain_command(scenes_dir, run, config, [stage], workers, "process", None, False, scene_ids)
    if any(r.status == "failed" for r in results):
        raise typer.Exit(1)


@app.command("intents")
@handle_errors
def intents(
    run: Path = typer.Option(..., "--run", help="run folder made by song synth"),
    scene: str | None = typer.Option(None, "--scene", help="only this scene"),
    llm: str | None = typer.Option(None, "--llm", help="offline | gemini | openai | auto"),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="worker processes (0 = all cores)"),
) -> None:
    """Semantic intents for each scene (LLM replies are cached under RUN/llm_cache)."""
    _rerun(run, "intents", scene, workers or default_workers(), intents={"llm": llm})


@app.command("crowd")
@handle_errors
def crowd(
    run: Path = typer.Option(..., "--run", help="run folder made by song synth"),
    scene: str | None = typer.Option(None, "--scene", help="only this scene"),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="worker processes (0 = all cores)"),
) -> None:
    """Joint 30 FPS crowd trajectories for each scene (needs intents)."""
    _rerun(run, "crowd", scene, workers or default_workers())
