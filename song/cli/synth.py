"""``song synth``: the per-scene chain intents → crowd → motion → binding."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from song.cli import app
from song.cli.common import ConfigOption, SeedOption, console, handle_errors, make_config, status_table
from song.pipeline.chain import SceneResult, iter_run, load_stages


def default_workers() -> int:
    import os

    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def run_chain_command(
    scenes: Path,
    out: Path,
    cfg,
    stage_names: list[str] | None,
    workers: int,
    executor: str,
    scheduler: str | None,
    quiet: bool,
    scene_ids: list[str] | None = None,
) -> list[SceneResult]:
    """Run the chain with a progress display (or JSON lines when ``quiet``) and print the summary."""
    names = stage_names or [stage.name for stage in load_stages()]
    if "binding" in names:
        from song.pipeline.binding.pool import ensure_pool

        ensure_pool(cfg.binding)  # build the default avatar pool once, before the workers start
    results: list[SceneResult] = []
    started = time.perf_counter()
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
            tasks = {name: progress.add_task(name, total=None, failed=0) for name in names}
            for result in iterator:
                results.append(result)
                for name in names:
                    status = result.stages.get(name)
                    failed = progress.tasks[tasks[name]].fields["failed"] + (status == "failed")
                    progress.update(tasks[name], advance=1, failed=failed)
    _print_summary(results, names, time.perf_counter() - started, out, quiet)
    return results


def _crowd_totals(out: Path, results: list[SceneResult]) -> tuple[int, int]:
    """Pedestrians and pedestrian-frames over the run's scenes (from the crowd files' metadata)."""
    import pyarrow.parquet as pq

    peds = frames = 0
    for result in results:
        path = out / "scenes" / result.scene_id / "crowd.parquet"
        if result.status != "failed" and path.is_file():
            meta = pq.read_metadata(path)
            frames += meta.num_rows
            status = json.loads((path.parent / "crowd_status.json").read_text())
            peds += sum(v["status"] != "removed" for v in status.values())
    return peds, frames


def _print_summary(results: list[SceneResult], names: list[str], wall: float, out: Path, quiet: bool) -> None:
    results = sorted(results, key=lambda r: r.scene_id)
    peds, frames = _crowd_totals(out, results)
    counts = {status: sum(r.status == status for r in results) for status in ("ok", "skipped", "failed")}
    per_stage = {name: sum(r.seconds.get(name, 0.0) for r in results) for name in names}
    if quiet:
        summary = {
            "event": "summary",
            "scenes": counts,
            "stage_seconds": per_stage,
            "wall_seconds": round(wall, 3),
            "pedestrians": peds,
            "pedestrian_frames": frames,
        }
        sys.stdout.write(json.dumps(summary, sort_keys=True) + "\n")
        return
    failed_rows = [{"scene": r.scene_id, "status": r.status, "error": r.error} for r in results if r.status == "failed"]
    if failed_rows:
        console.print(status_table("failed scenes", failed_rows, ["scene", "status", "error"]))
    rows = [
        {
            "stage": name,
            "ok": sum(r.stages.get(name) == "ok" for r in results),
            "skipped": sum(r.stages.get(name) == "skipped" for r in results),
            "failed": sum(r.stages.get(name) == "failed" for r in results),
            "cpu s": f"{per_stage[name]:.2f}",
        }
        for name in names
    ]
    console.print(status_table(f"run {out}", rows, ["stage", "ok", "skipped", "failed", "cpu s"]))
    console.print(
        f"scenes: {counts['ok']} ok, {counts['skipped']} unchanged, {counts['failed']} failed in {wall:.1f} s wall; "
        f"{peds} pedestrians, {frames} pedestrian-frames at 30 FPS"
    )


@app.command("synth")
@handle_errors
def synth(
    scenes: Path = typer.Option(..., "--scenes", help="folder of scene packages"),
    out: Path = typer.Option(..., "--out", help="run folder (created; re-running resumes)"),
    config: Path | None = ConfigOption,
    seed: int | None = SeedOption,
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="worker processes (0 = all cores)"),
    executor: str = typer.Option("process", "--executor", help="serial | process | dask"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="dask scheduler, e.g. tcp://host:8786"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="JSON line per scene instead of progress bars"),
    stages: str | None = typer.Option(None, "--stages", help="comma-separated subset of stages (default: all)"),
) -> None:
    """Run every registered per-scene stage on every scene package (resumable, parallel)."""
    cfg = make_config(config, seed)
    names = [name.strip() for name in stages.split(",")] if stages else None
    results = run_chain_command(scenes, out, cfg, names, workers or default_workers(), executor, scheduler, quiet)
    if any(r.status == "failed" for r in results):
        raise typer.Exit(1)
