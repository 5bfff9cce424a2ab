"""The results viewer: every episode a row, the first ones linked to their first-person videos, input escaped."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from typer.testing import CliRunner

from song.cli import app

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"


def test_the_page_lists_every_episode_and_links_the_videos(tmp_path: Path) -> None:
    runner = CliRunner()
    assert (
        runner.invoke(app, ["eval", "--bench", str(GOLDEN), "--policy", "straight", "--out", str(tmp_path)]).exit_code
        == 0
    )
    results = tmp_path / "straight.parquet"
    table = pq.read_table(results)
    errors = ["<script>alert(1)</script>"] + [""] * (table.num_rows - 1)  # a hostile string in a results file
    table = table.set_column(table.column_names.index("error"), "error", pa.array(errors))
    pq.write_table(table, results)
    out = tmp_path / "page"
    args = ["viz", "results", "--bench", str(GOLDEN), "--results", str(results), "--out", str(out)]
    result = runner.invoke(app, [*args, "--videos", "1", "--resolution", "64x48", "--render-backend", "numba"])
    assert result.exit_code == 0, result.output
    page = (out / "index.html").read_text()
    assert page.count("<tr>") == table.num_rows + 1  # the header and one row per episode
    assert page.count("first-person video</a>") == 1
    first = table.column("episode_id")[0].as_py()
    assert (out / f"{first}_straight_pov.mp4").is_file() and f'href="{first}_straight_pov.mp4"' in page
    assert "<script>" not in page and "&lt;script&gt;" in page
