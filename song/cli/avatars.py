"""``song avatars build|import``: the avatar pool."""

from __future__ import annotations

from pathlib import Path

import typer

from song.cli import app
from song.cli.common import console, handle_errors, status_table

avatars_app = typer.Typer(help="Gaussian avatars: build a pool, import a 3DGS PLY.", no_args_is_help=True)
app.add_typer(avatars_app, name="avatars")


def _row(asset) -> dict:
    gen = asset.meta.get("generator", {})
    clothing = "dress" if gen.get("dress") else f"{gen.get('top', '')} / {gen.get('bottom', '')}".strip(" /")
    return {
        "id": asset.avatar_id,
        "height m": f"{asset.height_m:.2f}",
        "clothing": f"{clothing} {gen.get('pattern', '')}".strip(),
        "body": gen.get("body", ""),
        "hair": gen.get("hair", ""),
        "gaussians": f"{len(asset):,}",
    }


@avatars_app.command("build")
@handle_errors
def build(
    out: Path = typer.Option(..., "--out", help="pool folder to write *.avatar.npz into"),
    count: int = typer.Option(128, "--count", min=1, help="identities"),
    seed: int = typer.Option(0, "--seed", help="pool seed (avatar i depends only on seed and i)"),
    gaussians: int = typer.Option(40_000, "--gaussians", min=5_000, max=100_000, help="Gaussians per avatar"),
    body: str = typer.Option(
        None, "--body", help="anny (the parametric body model) or procedural (default: anny where installed)"
    ),
) -> None:
    """Generate identities (a body shaped from anthropometry, clothing, hair, skin tone)."""
    from song.datasets.avatars import load_avatar
    from song.datasets.avatars.generate import BODIES, build_pool

    if body is not None and body not in BODIES:
        raise typer.BadParameter(f"--body {body!r}: expected one of {', '.join(BODIES)}")
    paths = build_pool(out, count, seed, gaussians, body=body)
    rows = [_row(load_avatar(path)) for path in paths]
    console.print(status_table(f"{len(paths)} avatars in {out}", rows, list(rows[0])))


@avatars_app.command("import")
@handle_errors
def import_command(
    ply: Path = typer.Argument(..., help="standard or compressed 3DGS PLY of a person in a canonical pose"),
    out: Path = typer.Option(..., "--out", help="pool folder"),
    avatar_id: str = typer.Option(None, "--id", help="identity id (default: the file stem)"),
    height: float = typer.Option(1.75, "--height", min=0.5, max=2.5, help="body height to scale to, m"),
    up: str = typer.Option(None, "--up", help="source up axis, e.g. +y (detected when omitted)"),
    forward: str = typer.Option(None, "--forward", help="source forward axis, e.g. +z (detected when omitted)"),
    force: bool = typer.Option(
        False, "--force", help="import a splat that does not look like a person (needs --up/--forward)"
    ),
) -> None:
    """Import a real Gaussian avatar (e.g. an LHM export): orient, ground, scale, skin, validate."""
    from song.datasets.avatars import save_avatar
    from song.datasets.avatars.importer import import_ply_avatar
    from song.util import check_id

    avatar_id = check_id(avatar_id or ply.name.split(".")[0], "--id")  # before any work: it names a file
    asset = import_ply_avatar(ply, avatar_id, height, up, forward, force=force)
    path = save_avatar(asset, out)
    console.print(f"wrote {path}: {len(asset):,} Gaussians, {asset.height_m:.2f} m")
