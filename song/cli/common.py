"""Shared CLI helpers: the rich console, config loading, error reporting, summaries."""

from __future__ import annotations

from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from song.errors import SongError

if TYPE_CHECKING:
    from song.config import SongConfig

console = Console(stderr=False, highlight=False)
err_console = Console(stderr=True, highlight=False)

F = TypeVar("F", bound=Callable[..., Any])

ConfigOption = typer.Option(None, "--config", "-c", help="TOML/YAML config file (defaults: the paper's values)")
SeedOption = typer.Option(None, "--seed", help="run seed (overrides the config)")
SetOption = typer.Option(
    None,
    "--set",
    metavar="SECTION.KEY=VALUE",
    help="override one config value (repeatable), e.g. crowd.agent_radius_m=0.3",
)
WorkersOption = typer.Option(0, "--workers", "-j", min=0, help="worker processes (0 = all cores)")


def resolve_workers(workers: int) -> int:
    """``--workers``: 0 means every core this process may use (outputs never depend on the count)."""
    from song.parallel import default_workers

    return workers or default_workers()


BenchOption = typer.Option(None, "--bench", help="benchmark folder, DIR@X.Y.Z, or a release folder")
# the benchmark as a bare first argument, as `song viz` took it before every command but `song bench …`
# took --bench: still accepted, not advertised
BenchArgument = typer.Argument(None, hidden=True, metavar="BENCH")


def handle_errors(func: F) -> F:
    """Turn a :class:`SongError` or a file-system error into a one-line message on stderr and exit code 2.

    File-system errors: a read-only or full disk, a file where a folder is expected, a missing path.
    """

    @wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except SongError as exc:  # escaped: messages hold brackets ('song[usd]', paths) rich would eat
            err_console.print(f"[red]error:[/red] {escape(str(exc))}", soft_wrap=True)
            raise typer.Exit(2) from None
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            err_console.print(f"[red]error:[/red] {escape(where + str(exc.strerror or exc))}", soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper  # type: ignore[return-value]


def make_config(path: Path | None, seed: int | None = None, sets: list[str] | None = None) -> SongConfig:
    """Load the config file (or defaults) and apply ``--seed`` and ``--set`` overrides, all validated."""
    from song.config import load_config, parse_assignments

    overrides: dict[str, Any] = parse_assignments(sets or [])
    if seed is not None:
        overrides["seed"] = seed
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
            value = escape(str(row.get(column, "")))  # ids and messages from input files may hold [brackets]
            if column == "status":
                value = f"[{colours.get(value, 'white')}]{value}[/]"
            cells.append(value)
        table.add_row(*cells)
    return table


def one_location(positional: Any, option: Any, flag: str, noun: str, what: str) -> Any:
    """The folder a command was given as ``flag DIR`` or, as ``song viz`` took it before, a bare first argument."""
    if positional and option and str(positional) != str(option):
        raise typer.BadParameter(f"two {noun} given ('{positional}' and {flag} '{option}'): give one")
    value = option or positional
    if not value:
        raise typer.BadParameter(f"missing {flag} DIR ({what})")
    return value


def bench_location(positional: str | None, option: str | None) -> str:
    """The benchmark a command was given, as ``--bench DIR`` (or, as before, a bare first argument)."""
    return one_location(
        positional, option, "--bench", "benchmarks", "a benchmark folder, DIR@X.Y.Z, or a release folder"
    )


def eval_results(path: Path, suffix: str) -> Path:
    """The file of one policy's ``song eval`` output with ``suffix`` (.json summary, .parquet per episode).

    ``path`` may name either file or their common stem (``runs/eval/social``); the other is found beside it.
    """
    candidate = path.with_suffix(suffix) if path.suffix in (".json", ".parquet", ".md", "") else path
    if not candidate.is_file():
        raise typer.BadParameter(
            f"{path}: no {candidate.name} beside it (--results takes a policy's output from song eval: "
            f"NAME.json, NAME.parquet or NAME in the --out folder)"
        )
    return candidate


MAX_IMAGE_SIDE = 8192  # px: a camera image larger than this is a typing error, not a camera


def parse_size(text: str, option: str) -> tuple[int, int]:
    """``"320x240"`` → ``(320, 240)``; a clear error naming ``option`` otherwise (ASCII digits only)."""
    width, sep, height = text.lower().partition("x")
    digits = set("0123456789")
    if not sep or not width or not height or not set(width) <= digits or not set(height) <= digits:
        raise SongError(f"{option} {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 320x240")
    w, h = int(width), int(height)
    if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE):
        raise SongError(f"{option} {text!r}: each side must be 1-{MAX_IMAGE_SIDE} pixels")
    return w, h
