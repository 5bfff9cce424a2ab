"""``song scenes check|import|generate``."""

from __future__ import annotations

from pathlib import Path

import typer
from rich import box

from song.cli import app
from song.cli.common import console, escape, handle_errors, status_table
from song.errors import SongError

# the default is song.config.SURFEL_SPACING_M, resolved when a command runs (the CLI starts without the config)
SpacingOption = typer.Option(
    None, "--spacing", min=0.005, max=0.5, help="Gaussian surfel spacing, m (default 0.035)", show_default=False
)

scenes_app = typer.Typer(help="Scene packages: validate, import, generate.", no_args_is_help=True)
app.add_typer(scenes_app, name="scenes")


def _spacing(value: float | None) -> float:
    from song.config import SURFEL_SPACING_M

    return SURFEL_SPACING_M if value is None else value


@scenes_app.command("check")
@handle_errors
def check(folder: Path = typer.Argument(..., help="a scene package, or a folder of them")) -> None:
    """Validate scene packages: a status table, then one line per problem; exit 1 if any package fails.

    A package passes when it is well formed and synthesis can use it: enough walkable area for a
    pedestrian of the default radius, two connected standing spots, objects one can stand next to.
    Unreachable objects alone are a warning (those objects are skipped).
    """
    from song.config import SongConfig
    from song.datasets.scenes import find_scene_packages, load_scene_package
    from song.datasets.scenes.ply import check_gaussian_ply
    from song.pipeline.intents.navigation import usability_problems

    crowd = SongConfig().crowd
    rows, problems, warnings = [], [], []
    for root in find_scene_packages(folder):
        try:
            package = load_scene_package(root)
        except SongError as exc:
            rows.append({"scene": root.name, "status": "failed"})
            problems.append((root.name, str(exc)))
            continue
        smap = package.semantic_map
        ply, usd = package.gaussians_path, package.usd_path
        found = usability_problems(package, crowd.agent_radius_m, crowd.contour_error_m)
        fatal = [p for p in found if "cannot be reached on foot:" not in p]
        problems += [(root.name, p) for p in fatal]
        warnings += [(root.name, p) for p in found if p not in fatal]
        rows.append(
            {
                "scene": smap.scene_id,
                "venue": smap.venue_type,
                "source": smap.source,
                "size m": f"{smap.bounds[2] - smap.bounds[0]:.0f}x{smap.bounds[3] - smap.bounds[1]:.0f}",
                "obj": len(smap.objects),
                "splats": f"{check_gaussian_ply(ply):,}" if ply else "-",
                "usd": "yes" if usd else "-",
                "status": "unusable" if fatal else "ok",
            }
        )
    columns = ["scene", "venue", "source", "size m", "obj", "splats", "usd", "status"]
    table = status_table(f"scene packages in {folder}", rows, columns)
    table.box, table.padding, table.show_edge = box.SIMPLE_HEAD, (0, 1, 0, 0), False  # fits 80 columns (CI logs)
    table.columns[0].no_wrap = True
    console.print(table)
    for name, message in problems:  # whole, unwrapped lines: easy to grep and copy
        console.print(f"[red]FAILED[/red] {escape(name)}: {escape(message)}", soft_wrap=True)
    for name, message in warnings:
        console.print(f"[yellow]warning[/yellow] {escape(name)}: {escape(message)}", soft_wrap=True)
    failed = len({name for name, _ in problems})
    console.print(f"{len(rows) - failed} ok, {failed} failed" if rows else f"no scene packages found in {folder}")
    if failed or not rows:
        raise typer.Exit(1)


@scenes_app.command("import")
@handle_errors
def import_scenes(
    kind: str = typer.Argument(..., help="procthor | interiorgs"),
    src: Path = typer.Argument(..., help="house JSON, a folder of them, or a .jsonl/.jsonl.gz"),
    out: Path = typer.Option(..., "--out", help="folder for the scene packages"),
    cell_size: float = typer.Option(0.05, "--cell-size", min=0.01, max=0.5, help="occupancy cell size, m"),
    assets: Path | None = typer.Option(
        None, "--assets", help="ProcTHOR asset database JSON (default: the procthor package's)"
    ),
    splat: bool = typer.Option(True, "--splat/--no-splat", help="also write the Gaussian scene (PLY)"),
    spacing: float | None = SpacingOption,
) -> None:
    """Convert real layouts into scene packages; one bad house fails alone."""
    if kind == "procthor":
        from song.datasets.scenes.procthor import import_procthor

        results = import_procthor(src, out, resolution=cell_size, assets=assets, splat=splat, spacing=_spacing(spacing))
        for result in results:
            if result.warning:
                console.print(f"[yellow]warning[/yellow] {result.warning}", soft_wrap=True)
    elif kind == "interiorgs":
        from song.datasets.scenes.interiorgs import import_interiorgs

        results = import_interiorgs(src, out)
    else:
        raise typer.BadParameter(f"unknown importer '{kind}'; available: procthor, interiorgs")
    rows = [{"scene": r.scene_id, "status": "ok" if r.path else "failed", "problem": r.error} for r in results]
    console.print(status_table(f"imported into {out}", rows, ["scene", "status", "problem"]))
    if any(r.path is None for r in results):
        raise typer.Exit(1)


@scenes_app.command("generate")
@handle_errors
def generate(
    count: int = typer.Option(..., "--count", min=1, help="number of scene packages"),
    out: Path = typer.Option(..., "--out", help="folder for the packages"),
    seed: int = typer.Option(0, "--seed", help="generator seed (same seed → identical bytes)"),
    splat: bool = typer.Option(True, "--splat/--no-splat", help="also write the Gaussian scene (PLY)"),
    spacing: float | None = SpacingOption,
    workers: int = typer.Option(1, "--workers", "-j", min=1, help="processes (same bytes whatever the count)"),
) -> None:
    """Procedural venues (office, clinic, lobby, shop, restaurant, home, library) with all five files."""
    from song.datasets.scenes.generate import generate_scenes

    paths = generate_scenes(count, seed, out, splat=splat, spacing=_spacing(spacing), workers=workers)
    console.print(f"wrote {len(paths)} scene packages to {out}")


@scenes_app.command("splat")
@handle_errors
def splat_command(
    folder: Path = typer.Argument(..., help="a scene package, or a folder of them"),
    out: Path | None = typer.Option(None, "--out", help="write complete copies here (default: in place)"),
    spacing: float | None = SpacingOption,
    force: bool = typer.Option(False, "--force", help="also replace Gaussian scenes that exist"),
    light: bool = typer.Option(True, "--light/--no-light", help="bake the scene's lights (lights.json) in"),
) -> None:
    """Synthesise the Gaussian scene (and USD proxy) of packages that lack one, from their geometry.

    The scene's lights (``lights.json``, placed by rule when the package has none) are baked into the
    Gaussians with shadows and bounced light; ``--no-light`` gives the flat look of earlier releases.
    """
    _dress_all(folder, out, spacing, force, light, "scene Gaussians")


@scenes_app.command("light")
@handle_errors
def light_command(
    folder: Path = typer.Argument(..., help="a scene package, or a folder of them"),
    out: Path | None = typer.Option(None, "--out", help="write complete copies here (default: in place)"),
    spacing: float | None = SpacingOption,
) -> None:
    """Re-bake the Gaussian scene of packages from their ``lights.json`` (edit it, then run this)."""
    _dress_all(folder, out, spacing, True, True, "lit scene Gaussians")


def _dress_all(folder: Path, out: Path | None, spacing, force: bool, light: bool, title: str) -> None:
    import shutil

    from song.datasets.scenes import find_scene_packages
    from song.datasets.scenes.package import GAUSSIANS
    from song.datasets.scenes.splat import dress_package

    rows = []
    for root in find_scene_packages(folder):
        target = root
        if out is not None:
            target = out / root.name
            links = [p.name for p in root.rglob("*") if p.is_symlink()]
            if links:  # a link could carry any file of the machine into --out
                rows.append({"scene": root.name, "status": "failed", "gaussians": f"symbolic link(s) in the package: "
                             f"{', '.join(sorted(links)[:3])}; copy real files"})  # fmt: skip
                continue
            if target.resolve() != root.resolve():
                shutil.copytree(root, target, dirs_exist_ok=True)
        if (target / GAUSSIANS).is_file() and not force:
            rows.append({"scene": root.name, "status": "skipped", "gaussians": "exists"})
            continue
        try:
            result = dress_package(target, spacing=_spacing(spacing), light=light)
        except SongError as exc:
            rows.append({"scene": root.name, "status": "failed", "gaussians": str(exc)})
            continue
        rows.append({"scene": root.name, "status": "ok", "gaussians": f"{result.gaussians:,} ({result.ply_mb:.1f} MB)"})
    console.print(status_table(f"{title} in {out or folder}", rows, ["scene", "status", "gaussians"]))
    if any(r["status"] == "failed" for r in rows):
        raise typer.Exit(1)
