from song.cli import app

app()
