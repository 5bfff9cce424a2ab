"""``song synth``: the per-scene chain intents → crowd → motion → binding."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from song.cli import app
from song.cli.common import (
    ConfigOption,
    SeedOption,
    SetOption,
    WorkersOption,
    console,
    handle_errors,
    make_config,
    status_table,
)
from song.errors import SongError

if TYPE_CHECKING:  # the pipeline is imported when a command runs, so that `--help` starts fast
    from song.config import SongConfig
    from song.pipeline.chain import RunSummary, SceneResult


def run_chain_command(
    scenes: Path,
    out: Path,
    cfg: SongConfig,
    stage_names: list[str] | None,
    workers: int,
    executor: str,
    scheduler: str | None,
    quiet: bool,
    scene_ids: list[str] | None = None,
) -> list[SceneResult]:
    """Run the chain with a progress display (or JSON lines when ``quiet``) and print the summary."""
    from song.datasets.scenes import find_scene_packages
    from song.pipeline.chain import iter_run, load_stages, summarize_run

    names = stage_names or [stage.name for stage in load_stages()]
    if "binding" in names:
        from song.pipeline.binding.pool import ensure_pool

        ensure_pool(cfg.binding)  # build the default avatar pool once, before the workers start
    results: list[SceneResult] = []
    started = time.perf_counter()
    total = len(find_scene_packages(scenes)) if scene_ids is None else len(scene_ids)
    iterator = iter_run(
        scenes, out, cfg, stage_names, workers=workers, executor=executor, scheduler=scheduler, scene_ids=scene_ids
    )
    if quiet:
        for result in iterator:
            results.append(result)
            sys.stdout.write(json.dumps({"event": "scene", **result.to_json()}, sort_keys=True) + "\n")
            sys.stdout.flush()
    else:
        columns = (
            TextColumn("{task.description:>10}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("[red]{task.fields[failed]} failed"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
        )
        with Progress(*columns, console=console, transient=False) as progress:
            tasks = {name: progress.add_task(name, total=total, failed=0) for name in names}
            for result in iterator:
                results.append(result)
                if result.totals.get("llm_fallbacks"):  # never silent: say which scene, where the reason is
                    progress.console.print(
                        f"[yellow]{result.scene_id}: the LLM failed, the offline model stood in "
                        f"(llm_error in scenes/{result.scene_id}/intents.json)[/yellow]"
                    )
                for name in names:
                    status = result.stages.get(name)
                    failed = progress.tasks[tasks[name]].fields["failed"] + (status == "failed")
                    progress.update(tasks[name], advance=1, failed=failed)
    _print_summary(summarize_run(results, names), time.perf_counter() - started, out, quiet, cfg.crowd.fps)
    return results


def _print_summary(summary: RunSummary, wall: float, out: Path, quiet: bool, fps: int) -> None:
    peds = summary.totals.get("pedestrians", 0)
    frames = summary.totals.get("pedestrian_frames", 0)
    if quiet:
        record = {
            "event": "summary",
            "scenes": summary.scenes,
            "stage_seconds": summary.stage_seconds,
            "wall_seconds": round(wall, 3),
            "pedestrians": peds,
            "pedestrian_frames": frames,
        }
        sys.stdout.write(json.dumps(record, sort_keys=True) + "\n")
        return
    if summary.failed:
        rows = [{"scene": scene, "status": "failed", "error": error} for scene, error in summary.failed]
        console.print(status_table("failed scenes", rows, ["scene", "status", "error"]))
    counts = summary.scenes
    if summary.totals.get("llm_fallbacks"):
        console.print(
            f"[yellow]LLM fallbacks: {summary.totals['llm_fallbacks']} scenes used the offline model[/yellow]"
        )
    console.print(
        f"scenes: {counts['ok']} ok, {counts['skipped']} unchanged, {counts['failed']} failed in {wall:.1f} s wall; "
        f"{peds} pedestrians, {frames} pedestrian-frames at {fps} FPS; "
        + ", ".join(f"{name} {seconds:.2f} cpu s" for name, seconds in summary.stage_seconds.items())
    )


def _refuse_changed_settings(out: Path, cfg: SongConfig) -> None:
    """Stop (one line) when the run folder records other settings than ``cfg``: a resume never reverts them."""
    from song.config import config_differences
    from song.datasets.run import read_run_info
    from song.datasets.run.layout import RUN_FILE

    if not (out / RUN_FILE).is_file():
        return
    recorded = read_run_info(out).config
    changes = config_differences(recorded, cfg)
    if changes:
        shown = ", ".join(
            f"{key}={json.dumps(old)} (this run would use {json.dumps(new)})" for key, old, new in changes
        )
        sets = " ".join(f"--set {key}={json.dumps(old)}" for key, old, _ in changes[:3])
        raise SongError(
            f"{out / RUN_FILE}: the run was made with {shown}; pass the same settings ({sets}) "
            "or --replace-settings to re-run with the new ones"
        )


@app.command("synth")
@handle_errors
def synth(
    scenes: Path = typer.Option(..., "--scenes", help="folder of scene packages"),
    out: Path = typer.Option(..., "--out", help="run folder (created; re-running resumes)"),
    config: Path | None = ConfigOption,
    seed: int | None = SeedOption,
    sets: list[str] | None = SetOption,
    workers: int = WorkersOption,
    executor: str = typer.Option("process", "--executor", help="serial | process | dask"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="dask scheduler, e.g. tcp://host:8786"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="JSON line per scene instead of progress bars"),
    stages: str | None = typer.Option(None, "--stages", help="comma-separated subset of stages (default: all)"),
    replace_settings: bool = typer.Option(
        False, "--replace-settings", help="re-run an existing run with settings other than the ones it records"
    ),
) -> None:
    """Run every registered per-scene stage on every scene package (resumable, parallel).

    Re-running into an existing run folder resumes it. When the settings differ from the ones the run
    records (e.g. after ``song rerun ... --set``), it names them and stops: give the same ``--set``
    again, or ``--replace-settings`` to re-run with the new ones.
    """
    from song.parallel import default_workers
    from song.pipeline.chain import load_stages

    cfg = make_config(config, seed, sets)
    if not replace_settings:
        _refuse_changed_settings(out, cfg)
    names = [name.strip() for name in stages.split(",")] if stages else None
    if out.exists() and not out.is_dir():
        raise SongError(f"--out {out} is a file: give a folder for the run")
    known = [stage.name for stage in load_stages()]
    for name in names or []:
        if name not in known:
            raise SongError(f"unknown stage '{name}' in --stages: use any of {', '.join(known)}")
    results = run_chain_command(scenes, out, cfg, names, workers or default_workers(), executor, scheduler, quiet)
    if any(r.status == "failed" for r in results):
        raise typer.Exit(1)
