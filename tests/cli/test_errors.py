"""One-line errors, never a traceback, for a newcomer's typical mistakes (issue 21), and the policy loader."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from song import __version__
from song.cli import app
from song.errors import SongError
from song.runtime.policies import load_policy
from tests.conftest import SAMPLES

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"


def _invoke(args: list[str]) -> tuple[int, str]:
    result = CliRunner().invoke(app, args)
    assert "Traceback" not in result.output, result.output
    return result.exit_code, result.output


def test_version() -> None:
    code, out = _invoke(["--version"])
    assert code == 0 and out.strip() == f"song {__version__}"


def test_bad_source_date_epoch_is_one_line() -> None:
    env = {"SOURCE_DATE_EPOCH": "abc", "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-m", "song", "--help"], env=env, capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        "error: SOURCE_DATE_EPOCH='abc' is not a whole number of seconds since 1970-01-01 (fix or unset it)"
    ]


def test_out_is_a_file_and_unknown_stage(tmp_path: Path) -> None:
    target = tmp_path / "afile"
    target.write_text("keep me")
    code, out = _invoke(["synth", "--scenes", str(SAMPLES), "--out", str(target)])
    assert code == 2 and "is a file" in out and target.read_text() == "keep me"
    code, out = _invoke(["synth", "--scenes", str(SAMPLES), "--out", str(tmp_path / "run"), "--stages", "bogus"])
    assert code == 2 and "unknown stage 'bogus'" in out
    assert not (tmp_path / "run").exists()  # refused before anything was written


def test_unknown_difficulty() -> None:
    code, out = _invoke(["eval", "--bench", str(GOLDEN), "--policy", "straight", "--difficulty", "hrad"])
    assert code == 2 and "unknown difficulty 'hrad'" in out


def test_full_or_read_only_disk_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import errno

    import song.cli.synth

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "run" / "run.json"))

    monkeypatch.setattr(song.cli.synth, "run_chain_command", full)
    code, out = _invoke(["synth", "--scenes", str(SAMPLES), "--out", str(tmp_path / "run")])
    assert code == 2 and out.strip() == f"error: {tmp_path / 'run' / 'run.json'}: No space left on device"


POLICY = """
class Forward:
    def reset(self, episode):
        pass

    def act(self, observation):
        return (0.5, 0.0)
"""


def test_policy_from_a_file_and_clear_errors(tmp_path: Path) -> None:
    path = tmp_path / "my_policy.py"
    path.write_text(POLICY)
    assert load_policy(f"{path}:Forward").act(None) == (0.5, 0.0)
    with pytest.raises(SongError, match="PYTHONPATH"):
        load_policy("no_such_module_xyz:Forward")
    with pytest.raises(SongError, match="no such policy file"):
        load_policy(f"{tmp_path / 'absent.py'}:Forward")
    with pytest.raises(SongError, match="has no attribute 'Backward'"):
        load_policy(f"{path}:Backward")


def test_config_show_lists_every_setting_with_its_description() -> None:
    from song.config import SongConfig

    code, out = _invoke(["config", "show", "--stage", "crowd"])
    assert code == 0 and out.splitlines()[0] == "[crowd]"
    fields = SongConfig.model_fields["crowd"].annotation.model_fields
    for name, info in fields.items():
        assert any(line.startswith(f"{name} = ") and (info.description or "") in line for line in out.splitlines())
    code, out = _invoke(["config", "show", "--stage", "bogus"])
    assert code == 2 and "no such section" in out


def test_generate_refuses_to_overwrite_a_different_package(tmp_path: Path) -> None:
    out = tmp_path / "scenes"
    args = ["scenes", "generate", "--count", "1", "--out", str(out), "--no-splat"]
    assert _invoke([*args, "--seed", "0"])[0] == 0
    before = (out / "office_0000" / "semantic_map.json").read_bytes()
    code, text = _invoke([*args, "--seed", "1"])
    assert code == 2 and "a different package is already there" in text
    assert (out / "office_0000" / "semantic_map.json").read_bytes() == before  # nothing overwritten
    assert _invoke([*args, "--seed", "0"])[0] == 0  # the same scene again is fine (resume)


def test_help_starts_without_the_heavy_libraries() -> None:
    """`song --help` stays fast (≤ 0.5 s CPU, issue 21): the CLI imports the pipeline only when a command runs."""
    code = "import sys, song.cli; print(sorted({m.split('.')[0] for m in sys.modules} & HEAVY))"
    heavy = "{'numpy', 'scipy', 'numba', 'torch', 'pyarrow', 'pydantic', 'cv2', 'shapely'}"
    out = subprocess.run([sys.executable, "-c", code.replace("HEAVY", heavy)], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr


@pytest.mark.parametrize("command", [["synth"], ["viz", "episode"], ["bench", "diff"], ["export-bench"], ["eval"]])
def test_help_shows_no_type_after_on_off_flags(command: list[str]) -> None:
    code, out = _invoke([*command, "--help"])
    assert code == 0 and "--help" in out and "<bool>" not in out


def test_spacing_help_names_the_real_default() -> None:
    from song.config import SURFEL_SPACING_M

    code, out = _invoke(["scenes", "generate", "--help"])
    words = [w for w in out.replace("│", " ").split() if w]  # rich wraps help text inside a box
    assert code == 0 and f"(default {SURFEL_SPACING_M:g})" in " ".join(words)


def test_an_llm_fallback_is_printed_per_scene_and_in_the_summary(tmp_path) -> None:
    """``--llm openai`` with no server: the offline model stands in, and the run says so (never silent)."""
    import shutil

    scenes = tmp_path / "scenes"
    shutil.copytree(SAMPLES / "shop_0003", scenes / "shop_0003")
    args = ["synth", "--scenes", str(scenes), "--out", str(tmp_path / "run"), "--stages", "intents"]
    args += ["--set", "intents.llm=openai", "--set", "intents.openai_base_url=http://127.0.0.1:9/v1"]
    args += ["--set", "intents.max_retries=1", "--set", "intents.backoff_base_s=0.01", "--set", "intents.timeout_s=1"]
    code, out = _invoke(args)
    assert code == 0, out
    assert "shop_0003: the LLM failed, the offline model stood in" in out
    assert "LLM fallbacks: 1 scenes used the offline model" in out


def test_a_missing_extra_names_it_in_brackets() -> None:
    """Rich markup must not swallow '[usd]' from the install hint (it printed `pip install 'song'`)."""
    from song.cli.common import handle_errors
    from song.errors import MissingDependencyError

    @handle_errors
    def fails() -> None:
        raise MissingDependencyError("pxr", "usd")

    import typer

    probe = typer.Typer()
    probe.command()(fails)
    result = CliRunner().invoke(probe, [])
    assert result.exit_code == 2 and "pip install 'song[usd]'" in result.output, result.output
