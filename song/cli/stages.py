"""``song rerun STAGE``: re-run one registered stage of an existing run (any stage, plugins too)."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import SetOption, WorkersOption, handle_errors
from song.cli.synth import run_chain_command
from song.errors import SongError


@app.command("rerun")
@handle_errors
def rerun(
    stage: str = typer.Argument(..., help="stage name: intents | crowd | motion | binding (or a plugin's)"),
    run: Path = typer.Option(..., "--run", help="run folder made by song synth"),
    scene: str | None = typer.Option(None, "--scene", help="only this scene"),
    sets: list[str] | None = SetOption,
    workers: int = WorkersOption,
) -> None:
    """Re-run one stage, and every stage made from its outputs, with the run's config.

    ``--set`` changes the config and the run records the new one; the stages downstream of STAGE re-run
    too (a stage made from outputs that changed would be stale), unless nothing they read changed.

    Examples: ``song rerun intents --run RUN --set intents.llm=openai``;
    ``song rerun motion --run RUN --set motion.generator=kimodo``;
    ``song rerun binding --run RUN --set binding.avatars_dir=/abs/avatars --set binding.materialize=true``.
    """
    from song.config import load_config, parse_assignments
    from song.parallel import default_workers
    from song.pipeline.chain import downstream, load_stages, read_run

    scenes_dir, config = read_run(run)
    overrides = parse_assignments(sets or [])
    base = config.model_dump(mode="json")
    for section, values in overrides.items():
        base[section] = {**base.get(section, {}), **values} if isinstance(values, dict) else values
    config = load_config(None, **base)  # validated before run.json is rewritten
    known = [s.name for s in load_stages()]
    if stage not in known:
        raise SongError(f"unknown stage '{stage}': use any of {', '.join(known)}")
    scene_ids = [scene] if scene else None
    results = run_chain_command(
        scenes_dir, run, config, downstream(stage), workers or default_workers(), "process", None, False, scene_ids
    )
    if any(r.status == "failed" for r in results):
        raise typer.Exit(1)
