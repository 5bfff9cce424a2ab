"""``song eval``: closed-loop evaluation of a policy on a benchmark release."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from song.cli import app
from song.cli.common import (
    ConfigOption,
    SetOption,
    WorkersOption,
    console,
    err_console,
    handle_errors,
    parse_size,
    resolve_workers,
)


@app.command("eval")
@handle_errors
def eval_command(
    bench: str = typer.Option(..., "--bench", help="benchmark folder, DIR@X.Y.Z, or a release folder"),
    policy: list[str] = typer.Option(
        ["social"],
        "--policy",
        help="straight | astar | social | depth | a policy plugin | module:Class | file.py:Class",
    ),
    difficulty: str | None = typer.Option(None, "--difficulty", help="easy | medium | hard (default: all)"),
    split: str = typer.Option("test", "--split", help="which split's episodes (train | val | test)"),
    limit: int | None = typer.Option(
        None, "--limit", min=1, help="only the first N episodes (in release order, after --difficulty)"
    ),
    sensors: str | None = typer.Option(
        None, "--sensors", help="sensors shown besides the policy's own, comma-separated (state, scan, depth, rgb, ...)"
    ),
    resolution: str | None = typer.Option(
        None, "--resolution", metavar="WxH", help="camera sensors' image size (default: the release's, 960x540)"
    ),
    render_backend: str = typer.Option(
        "auto", "--render-backend", help="auto | numba | gsplat | reference | a render_backend plugin"
    ),
    camera_model: str | None = typer.Option(
        None,
        "--camera-model",
        help="what the camera does to the ideal image: ideal | d435i | a camera_model plugin (default: the "
        "release's; another one is recorded as an override)",
    ),
    out: Path = typer.Option(Path("runs/eval"), "--out", help="results folder"),
    workers: int = WorkersOption,
    step_timeout: float = typer.Option(
        5.0, "--step-timeout", min=0.01, help="a policy call taking longer fails its episode (outcome error), s"
    ),
    config: Path | None = ConfigOption,
    sets: list[str] | None = SetOption,
    override: bool = typer.Option(
        False, "--override", help="allow [robot]/[camera] values that differ from the release's (marked unofficial)"
    ),
    allow_modified: bool = typer.Option(
        False, "--allow-modified", help="run on a release edited since export (results marked unofficial)"
    ),
    isolate: bool = typer.Option(
        False, "--isolate", help="run the policy in a process of its own (for leaderboard-style results)"
    ),
    episode: list[str] | None = typer.Option(
        None, "--episode", help="only this episode id (repeatable); --difficulty/--split/--limit then do not apply"
    ),
    no_avatars: bool = typer.Option(
        False, "--no-avatars", help="the avatar-free ablation: the same episodes without pedestrians (unofficial)"
    ),
    reactive: bool = typer.Option(
        False,
        "--reactive-pedestrians",
        help="pedestrians near the robot avoid it (unofficial; also --set crowd.react_to_robot=true)",
    ),
) -> None:
    """Run policies on every episode; write per-episode Parquet and the paper's metric table.

    The robot, camera and pedestrian parameters come from the release; a config file or ``--set`` that
    changes them needs ``--override``, and the results then record the change. ``results.md`` in the
    output folder tables every result there, so an ablation run into the same folder appears beside
    the main rows.
    """
    from song.config import parse_assignments, read_config_mapping
    from song.datasets.bench import open_benchmark  # imported here: `--help` stays fast
    from song.errors import ConfigError
    from song.runtime.evaluate import iter_eval, make_setup, results_in, write_results
    from song.runtime.metrics import markdown_table
    from song.runtime.params import apply_overrides

    release = open_benchmark(bench)
    requested = read_config_mapping(config) if config else {}
    for section, values in parse_assignments(sets or []).items():
        requested[section] = {**requested.get(section, {}), **values} if isinstance(values, dict) else values
    crowd = requested.get("crowd")
    if isinstance(crowd, dict) and "react_to_robot" in crowd:  # a mode of the run, not a release parameter
        value = crowd.pop("react_to_robot")
        if not isinstance(value, bool):
            raise ConfigError(str(config or "--set"), "crowd.react_to_robot", f"expected true or false, got {value!r}")
        reactive = reactive or value
        if not crowd:
            requested.pop("crowd")
    params, changed = apply_overrides(release.params, requested, override, str(config or "--set"))
    for key, (old, new) in changed.items():
        err_console.print(f"[yellow]override[/yellow] {key}: {old} → {new} (results marked unofficial)")
    camera: dict = {"backend": render_backend, "model": camera_model or params.camera.model}
    if resolution:
        width, height = parse_size(resolution, "--resolution")
        camera.update(width=width, height=height)
    whole = not difficulty and not limit and not episode and release.splits() == {split}
    if episode:
        episodes = [release.episode(e) for e in dict.fromkeys(episode)]
    else:
        episodes = None if whole else list(release.episodes(difficulty=difficulty, split=split))
    if limit is not None and not episode:
        episodes = episodes[:limit]
    total = len(episodes) if episodes is not None else len(release)
    table = {}
    for name in policy:
        setup = make_setup(
            release, name, sensors, params, changed, camera, step_timeout, allow_modified, isolate, no_avatars,
            reactive,
        )  # fmt: skip
        results = []
        columns = (TextColumn(f"{name:>10}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
        with Progress(*columns, console=console) as progress:
            task = progress.add_task(name, total=total)
            for result in iter_eval(release, setup, episodes, resolve_workers(workers)):
                results.append(result)
                progress.advance(task)
        table[setup.label] = write_results(out, setup, results, release)["metrics"]
    text = markdown_table(results_in(out, table))
    (out / "results.md").write_text(text, encoding="utf-8")
    typer.echo(text)


@app.command("collect")
@handle_errors
def collect_command(
    bench: str = typer.Option(..., "--bench", help="benchmark folder, DIR@X.Y.Z, or a release folder"),
    out: Path = typer.Option(..., "--out", help="dataset folder to create (LeRobot layout)"),
    policy: str = typer.Option(
        "social", "--policy", help="the expert: straight | astar | social | depth | module:Class"
    ),
    split: str = typer.Option("train", "--split", help="which split's episodes (train | val | test)"),
    sensors: str = typer.Option(
        "state", "--sensors", help="what to record, comma-separated: state, scan, pedestrians, depth, rgb"
    ),
    resolution: str = typer.Option("160x120", "--resolution", metavar="WxH", help="camera image size"),
    limit: int | None = typer.Option(None, "--limit", min=1, help="only the first N episodes of the split"),
    keep: str = typer.Option("success", "--keep", help="success (only successful rollouts) | all"),
    workers: int = WorkersOption,
    allow_modified: bool = typer.Option(
        False, "--allow-modified", help="collect from a release edited since export (recorded in the dataset)"
    ),
    no_avatars: bool = typer.Option(
        False, "--no-avatars", help="the avatar-free ablation: episodes without pedestrians (recorded in the dataset)"
    ),
    dataset_format: str = typer.Option(
        "v3.0", "--format", help="LeRobot codebase version: v3.0 (LeRobot's current release) or v2.1 (older stacks)"
    ),
    reactive: bool = typer.Option(
        False, "--reactive-pedestrians", help="pedestrians near the robot avoid it (recorded in the dataset)"
    ),
) -> None:
    """Roll a policy out on training episodes; write what imitation learning needs (a LeRobot dataset)."""
    from song.runtime.collect import collect

    width, height = parse_size(resolution, "--resolution")
    camera = {"width": width, "height": height}
    summary = collect(
        bench,
        policy,
        out,
        split,
        tuple(sensors.split(",")),
        limit,
        camera,
        keep,
        resolve_workers(workers),
        allow_modified=allow_modified,
        no_avatars=no_avatars,
        dataset_format=dataset_format,
        reactive=reactive,
    )
    console.print(
        f"wrote {summary.out}: {summary.episodes} of {summary.rollouts} rollouts ({summary.successes} successful), "
        f"{summary.frames} steps"
    )


@app.command("teleop")
@handle_errors
def teleop_command(
    bench: str = typer.Option(..., "--bench", help="benchmark folder, DIR@X.Y.Z, or a release folder"),
    episode: list[str] | None = typer.Option(None, "--episode", help="drive this episode (repeatable)"),
    split: str = typer.Option("test", "--split", help="without --episode: every episode of this split"),
    out: Path = typer.Option(Path("runs/teleop"), "--out", help="results (human.*) and the LeRobot dataset/"),
    resolution: str | None = typer.Option(
        None,
        "--resolution",
        metavar="WxH",
        help="camera size (default: the largest of 320x240, 240x180, 160x120 that renders in time here)",
    ),  # fmt: skip
    port: int = typer.Option(0, "--port", min=0, max=65535, help="port on 127.0.0.1 (0: any free port)"),
    reactive: bool = typer.Option(
        False, "--reactive-pedestrians", help="pedestrians near the robot avoid it (unofficial; recorded)"
    ),
) -> None:
    """Drive the robot yourself from a browser page: the human upper bound, scored and recorded."""
    from song.runtime.teleop import run_teleop

    size = parse_size(resolution, "--resolution") if resolution else None

    def ready(url: str) -> None:
        console.print(f"open [bold]{url}[/bold] in a browser on this machine (W/A/S/D or the arrow keys drive)")

    summary = run_teleop(bench, out, episode or None, split, size, port, ready, reactive=reactive)
    from song.runtime.evaluate import results_stem
    from song.runtime.metrics import markdown_table

    name = results_stem("human", reactive=reactive)
    typer.echo(markdown_table({name: summary["metrics"]}))
    console.print(f"results in {out}/{name}.json, demonstrations in {out}/dataset")
