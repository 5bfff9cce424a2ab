"""``song eval``: closed-loop evaluation of a policy on a benchmark release."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from song.cli import app
from song.cli.common import ConfigOption, console, handle_errors, make_config
from song.datasets.bench import open_benchmark
from song.runtime.evaluate import iter_eval, write_results
from song.runtime.metrics import markdown_table


@app.command("eval")
@handle_errors
def eval_command(
    bench: str = typer.Option(..., "--bench", help="benchmark folder, DIR@X.Y.Z, or a release folder"),
    policy: list[str] = typer.Option(["social"], "--policy", help="straight | astar | social | module:Class"),
    difficulty: str | None = typer.Option(None, "--difficulty", help="easy | medium | hard (default: all)"),
    out: Path = typer.Option(Path("runs/eval"), "--out", help="results folder"),
    workers: int = typer.Option(1, "--workers", "-j", min=1, help="worker processes"),
    config: Path | None = ConfigOption,
) -> None:
    """Run policies on every episode; write per-episode Parquet and the paper's metric table."""
    cfg = make_config(config)
    release = open_benchmark(bench)
    episodes = list(release.episodes(difficulty=difficulty)) if difficulty else None
    total = len(episodes) if episodes is not None else len(release)
    table = {}
    for name in policy:
        results = []
        columns = (TextColumn(f"{name:>10}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
        with Progress(*columns, console=console) as progress:
            task = progress.add_task(name, total=total)
            for result in iter_eval(release, name, cfg.robot, episodes, workers):
                results.append(result)
                progress.advance(task)
        table[name] = write_results(out, name, results, release)["metrics"]
    text = markdown_table(table)
    (out / "results.md").write_text(text, encoding="utf-8")
    typer.echo(text)
