"""The ``song`` command line (Typer + rich). Thin: parse, call one library function, print.

Each area adds its commands from its own module (``song/cli/<area>.py``) so that areas stay
independent; :data:`COMMAND_MODULES` lists them.
"""

from __future__ import annotations

import importlib
import os
import sys

import typer


def _hide_flag_types() -> None:
    """Help shows no type for on/off flags (Typer 0.29 prints ``<bool>`` after ``--help``, ``--video`` ...)."""
    option = getattr(getattr(typer, "core", None), "TyperOption", None)
    original = getattr(option, "display_type_rich", None)
    if original is None or getattr(original, "_song_flags_hidden", False):
        return

    def display_type_rich(self, ctx):
        return None if getattr(self, "is_flag", False) and not getattr(self, "count", False) else original(self, ctx)

    display_type_rich._song_flags_hidden = True
    option.display_type_rich = display_type_rich


_hide_flag_types()

app = typer.Typer(
    name="song",
    help="SONG: build social-navigation benchmarks from indoor scenes.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _check_environment() -> None:
    """Refuse, in one line, environment values that would crash a library import with a traceback."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch is not None and not epoch.strip().isdigit():
        sys.stderr.write(
            f"error: SOURCE_DATE_EPOCH={epoch!r} is not a whole number of seconds since 1970-01-01 (fix or unset it)\n"
        )
        raise SystemExit(2)


def _version(value: bool) -> None:
    if value:
        from song import __version__

        typer.echo(f"song {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="print the version and exit"
    ),
) -> None:
    """SONG: build social-navigation benchmarks from indoor scenes."""


_check_environment()  # before the command modules import numpy and friends

COMMAND_MODULES = (
    "song.cli.scenes",
    "song.cli.synth",
    "song.cli.stages",
    "song.cli.avatars",
    "song.cli.grade",
    "song.cli.bench",
    "song.cli.eval",
    "song.cli.viz",
    "song.cli.config",
)

for _module in COMMAND_MODULES:
    importlib.import_module(_module)


def main() -> None:  # pragma: no cover - console entry
    """Run the command line."""
    app()
