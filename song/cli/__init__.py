"""The ``song`` command line (Typer + rich). Thin: parse, call one library function, print.

Each area adds its commands from its own module (``song/cli/<area>.py``) so that areas stay
independent; :data:`COMMAND_MODULES` lists them and a module that does not exist yet is skipped.
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
    "song.cli.intents",
    "song.cli.crowd",
    "song.cli.motion",
    "song.cli.bind",
    "song.cli.avatars",
    "song.cli.avatars",
    "song.cli.grade",
    "song.cli.bench",
    "song.cli.eval",
    "song.cli.viz",
)

for _module in COMMAND_MODULES:
    try:
        importlib.import_module(_module)
    except ModuleNotFoundError as _exc:
        if _exc.name != _module:
            raise


def main() -> None:  # pragma: no cover - console entry
    app()
