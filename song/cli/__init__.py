"""The ``song`` command line (Typer + rich). Thin: parse, call one library function, print.

Each area adds its commands from its own module (``song/cli/<area>.py``) so that areas stay
independent; :data:`COMMAND_MODULES` lists them.
"""

from __future__ import annotations

import importlib

import typer

app = typer.Typer(
    name="song",
    help="SONG: build social-navigation benchmarks from indoor scenes.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

COMMAND_MODULES = (
    "song.cli.scenes",
    "song.cli.synth",
    "song.cli.stages",
    "song.cli.avatars",
    "song.cli.grade",
    "song.cli.bench",
    "song.cli.eval",
    "song.cli.viz",
)

for _module in COMMAND_MODULES:
    importlib.import_module(_module)


def main() -> None:  # pragma: no cover - console entry
    """Run the command line."""
    app()
