"""Shared CLI helpers: the rich console, config loading, error reporting, summaries."""

from __future__ import annotations

from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Any, TypeVar

import typer
from rich.console import Console
from rich.table import Table

from song.config import SongConfig, load_config
from song.errors import SongError

console = Console(stderr=False, highlight=False)
err_console = Console(stderr=True, highlight=False)

F = TypeVar("F", bound=Callable[..., Any])

ConfigOption = typer.Option(None, "--config", "-c", help="TOML/YAML config file (defaults: the paper's values)")
SeedOption = typer.Option(None, "--seed", help="run seed (overrides the config)")


def handle_errors(func: F) -> F:
    """Turn a :class:`SongError` into a one-line message on stderr and exit code 2."""

    @wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except SongError as exc:
            err_console.print(f"[red]error:[/red] {exc}", soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper  # type: ignore[return-value]


def make_config(path: Path | None, seed: int | None = None, **sections: dict[str, Any]) -> SongConfig:
    """Load the config file (or defaults) and apply CLI overrides (only non-None values)."""
    overrides: dict[str, Any] = {}
    if seed is not None:
        overrides["seed"] = seed
    for name, values in sections.items():
        values = {k: v for k, v in values.items() if v is not None}
        if values:
            overrides[name] = values
    return load_config(path, **overrides)


def status_table(title: str, rows: list[dict[str, Any]], columns: list[str]) -> Table:
    """A rich table with a coloured ``status`` column."""
    table = Table(title=title, show_lines=False)
    for column in columns:
        table.add_column(column, overflow="fold")
    colours = {"ok": "green", "failed": "red", "skipped": "yellow", "partial": "yellow"}
    for row in rows:
        cells = []
        for column in columns:
            value = str(row.get(column, ""))
            if column == "status":
                value = f"[{colours.get(value, 'white')}]{value}[/]"
            cells.append(value)
        table.add_row(*cells)
    return table
