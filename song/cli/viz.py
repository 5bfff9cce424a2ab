"""``song viz scene|view|crowd|episode|pov|bench|avatar``: pictures and videos."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import (
    BenchArgument,
    BenchOption,
    bench_location,
    console,
    eval_results,
    handle_errors,
    one_location,
)

RESULTS_HELP = "a policy's output from song eval: NAME.json, NAME.parquet or NAME in its --out folder"

viz_app = typer.Typer(help="Top-down pictures and videos.", no_args_is_help=True)
app.add_typer(viz_app, name="viz")


def _report(paths: list[Path]) -> None:
    for path in paths:
        console.print(f"wrote {path}")


@viz_app.command("scene")
@handle_errors
def scene(
    scene: Path = typer.Argument(..., help="scene package folder"),
    out: Path = typer.Option(None, "--out", help="PNG path (default: <scene>.png here)"),
) -> None:
    """Occupancy, regions, objects and the navigable area of a scene package."""
    from song.viz.scene import render_scene

    _report([render_scene(scene, out or Path(f"{scene.name}.png"))])


@viz_app.command("view")
@handle_errors
def view(
    scene: Path = typer.Argument(..., help="scene package folder with a Gaussian scene"),
    out: Path = typer.Option(None, "--out", help="PNG path (default: <scene>-view.png here)"),
    pose: str | None = typer.Option(None, "--pose", help="X,Y,YAW (m, m, rad); default: a pose that sees much"),
    resolution: str = typer.Option("960x540", "--resolution", metavar="WxH", help="image size, px"),
) -> None:
    """What a camera 1.2 m above the floor sees of the scene's Gaussians."""
    from song.cli.common import parse_size
    from song.viz.view import render_view

    xyz = None
    if pose is not None:
        try:
            x, y, yaw = (float(v) for v in pose.split(","))
        except ValueError as exc:
            raise typer.BadParameter(f"--pose {pose!r}: expected X,Y,YAW") from exc
        xyz = (x, y, yaw)
    width, height = parse_size(resolution, "--resolution")
    _report([render_view(scene, out or Path(f"{scene.name}-view.png"), xyz, width, height)])


@viz_app.command("crowd")
@handle_errors
def crowd(
    positional: Path | None = typer.Argument(None, hidden=True, metavar="RUN"),  # as before: the run, bare
    run: Path | None = typer.Option(None, "--run", help="run folder made by song synth"),
    scene: str = typer.Option(..., "--scene", help="scene id"),
    out: Path = typer.Option(Path("runs/viz"), "--out", help="output folder"),
    video: bool = typer.Option(True, "--video/--no-video", help="also write an MP4"),
) -> None:
    """All pedestrian trajectories over the map (PNG) and an animation (MP4)."""
    from song.viz.crowd import render_crowd

    _report(
        render_crowd(
            one_location(positional, run, "--run", "runs", "a run folder made by song synth"), scene, out, video
        )
    )


@viz_app.command("episode")
@handle_errors
def episode(
    positional: str | None = BenchArgument,
    bench: str | None = BenchOption,
    episode_id: str = typer.Option(..., "--episode", help="episode id"),
    results: Path | None = typer.Option(None, "--results", help=RESULTS_HELP),
    out: Path = typer.Option(Path("runs/viz"), "--out", help="output folder"),
    video: bool = typer.Option(True, "--video/--no-video", help="also write an MP4"),
) -> None:
    """Map, pedestrians, the A* path and (with --results) the robot's path and events."""
    from song.viz.episode import render_episode

    log = eval_results(results, ".parquet") if results else None
    _report(render_episode(bench_location(positional, bench), episode_id, out, log, video))


@viz_app.command("pov")
@handle_errors
def pov(
    positional: str | None = BenchArgument,
    bench: str | None = BenchOption,
    episode_id: str = typer.Option(..., "--episode", help="episode id"),
    policy: str = typer.Option("depth", "--policy", help="straight | astar | social | depth | module:Class"),
    out: Path = typer.Option(Path("runs/viz"), "--out", help="output folder"),
    resolution: str = typer.Option("320x240", "--resolution", metavar="WxH", help="camera image size, px"),
    backend: str = typer.Option("auto", "--render-backend", help="auto | numba | gsplat | a render_backend plugin"),
) -> None:
    """First-person video of a policy on an episode: RGB | depth | top-down (H.264) and a PNG strip."""
    from song.cli.common import parse_size
    from song.viz.pov import render_pov

    _report(
        render_pov(
            bench_location(positional, bench), episode_id, policy, out, parse_size(resolution, "--resolution"), backend
        )
    )


@viz_app.command("bench")
@handle_errors
def bench(
    positional: str | None = BenchArgument,
    bench: str | None = BenchOption,
    out: Path = typer.Option(Path("runs/viz"), "--out", help="output folder"),
    results: list[Path] = typer.Option(None, "--results", help=RESULTS_HELP + " (repeatable: one per policy)"),
) -> None:
    """Fig. 3 left (encounters vs L*), factor histograms, mode × difficulty, results bars."""
    from song.viz.bench import render_bench

    summaries = [eval_results(path, ".json") for path in results or []]
    _report(render_bench(bench_location(positional, bench), out, summaries))


@viz_app.command("avatar")
@handle_errors
def avatar(
    avatars: Path = typer.Option(None, "--avatars", help="pool folder of *.avatar.npz (default: the default pool)"),
    out: Path = typer.Option(Path("avatars.png"), "--out", help="PNG path"),
    count: int = typer.Option(5, "--count", min=1, help="identities to show"),
    gallery: Path = typer.Option(None, "--gallery", help="also render them with a robot camera at 2 m and 5 m (PNG)"),
) -> None:
    """Splat preview of a few identities: front and side, rest pose and mid-stride."""
    from song.config import BindingConfig
    from song.datasets.avatars import list_avatars, load_avatar
    from song.pipeline.binding.pool import ensure_pool
    from song.viz.avatar import draw_avatars, mid_stride

    paths = list_avatars(avatars) if avatars else ensure_pool(BindingConfig())
    assets = [load_avatar(path) for path in paths[:count]]
    if not assets:
        raise typer.BadParameter(f"{avatars}: no *.avatar.npz here")
    written = [draw_avatars(assets, out, pose=mid_stride)]
    if gallery:
        from song.viz.avatar import render_gallery

        written.append(render_gallery(assets, gallery))
    _report(written)


@viz_app.command("results")
@handle_errors
def results_page(
    positional: str | None = BenchArgument,
    bench: str | None = BenchOption,
    results: Path = typer.Option(..., "--results", help=RESULTS_HELP),
    out: Path = typer.Option(Path("runs/viz/results"), "--out", help="output folder (index.html and the videos)"),
    videos: int = typer.Option(12, "--videos", min=0, help="first-person videos for the first N episodes"),
    resolution: str = typer.Option("320x240", "--resolution", metavar="WxH", help="video camera size, px"),
    backend: str = typer.Option("auto", "--render-backend", help="auto | numba | gsplat | a render_backend plugin"),
) -> None:
    """An HTML page of one policy's results, each episode linked to its first-person video."""
    from song.cli.common import parse_size
    from song.viz.results import render_results_page

    size = parse_size(resolution, "--resolution")
    location = bench_location(positional, bench)
    _report(render_results_page(location, eval_results(results, ".parquet"), out, videos, size, backend))
