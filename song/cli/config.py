"""``song config show``: every setting with its default, unit and meaning."""

from __future__ import annotations

import json

import typer

from song.cli import app
from song.cli.common import handle_errors
from song.errors import ConfigError

config_app = typer.Typer(help="Inspect the configuration.", no_args_is_help=True)
app.add_typer(config_app, name="config")


def config_lines(model, prefix: str = "") -> list[str]:
    """``key = value  # description`` for every field of ``model`` (sections recursively)."""
    from pydantic import BaseModel

    lines = []
    for name, info in type(model).model_fields.items():
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            lines += ["", f"[{prefix}{name}]", *config_lines(value, f"{prefix}{name}.")]
            continue
        note = f"  # {info.description}" if info.description else ""
        lines.append(f"{name} = {json.dumps(value, default=str)}{note}")
    return lines


@config_app.command("show")
@handle_errors
def show(
    stage: str | None = typer.Option(None, "--stage", help="only this section (intents, crowd, motion, ...)"),
) -> None:
    """Print the defaults (TOML sections; units in the descriptions); override with ``--set section.key=value``."""
    from pydantic import BaseModel

    from song.config import SongConfig

    config = SongConfig()
    if stage is None:
        typer.echo("\n".join(config_lines(config)).strip())
        return
    if stage not in SongConfig.model_fields or not isinstance(getattr(config, stage), BaseModel):
        sections = [n for n in SongConfig.model_fields if isinstance(getattr(config, n), BaseModel)]
        raise ConfigError("--stage", stage, f"no such section; use one of {', '.join(sections)}")
    typer.echo("\n".join([f"[{stage}]", *config_lines(getattr(config, stage), f"{stage}.")]))
