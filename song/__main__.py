"""``python -m song``: the command line."""

from song.cli import app

app()
