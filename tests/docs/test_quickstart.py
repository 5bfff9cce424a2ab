"""Every command of docs/quickstart.md runs, in order, in a scratch folder."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _commands() -> list[str]:
    text = (DOCS / "quickstart.md").read_text()
    block = re.search(r"```bash\n(.*?)```", text, re.S).group(1)
    commands = [line for line in block.splitlines() if line.startswith("song ")]
    assert len(commands) >= 7
    return commands


def test_quickstart_commands_run_in_a_small_configuration(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same commands in this process, on one generated scene and four episodes."""
    from typer.testing import CliRunner

    from song.cli import app

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    for command in _commands():
        small = command.replace("--count 2", "--count 1").replace("--episodes 12", "--episodes 4")
        result = CliRunner().invoke(app, shlex.split(small)[1:])
        assert result.exit_code == 0, f"{small}\n{result.output[-2000:]}"
    assert (tmp_path / "qs/bench/1.0.0/meta/info.json").is_file()
    assert (tmp_path / "qs/figures/encounters_vs_length.png").is_file()


@pytest.mark.slow
def test_quickstart_commands_run(tmp_path: Path) -> None:
    """Every command as written, each in its own process, as a user types them."""
    commands = _commands()
    env = {**os.environ, "SOURCE_DATE_EPOCH": "1700000000", "COLUMNS": "200"}
    for command in commands:
        args = shlex.split(command)
        proc = subprocess.run(
            [sys.executable, "-m", "song", *args[1:]], cwd=tmp_path, env=env, capture_output=True, text=True
        )
        assert proc.returncode == 0, f"{command}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    assert (tmp_path / "qs/bench/1.0.0/meta/info.json").is_file()
    assert (tmp_path / "qs/figures/encounters_vs_length.png").is_file()


def test_docs_link_to_existing_files() -> None:
    for page in DOCS.glob("*.md"):
        for target in re.findall(r"\]\(([^)#]+\.md)\)", page.read_text()):
            assert (page.parent / target).is_file(), f"{page.name} links to missing {target}"
