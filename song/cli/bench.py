"""``song export-bench`` and ``song bench list|verify|diff|export-habitat``."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from song.cli import app
from song.cli.common import console, escape, handle_errors, status_table

bench_app = typer.Typer(help="Benchmark releases: list, verify, diff, export to Habitat.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")


@app.command("export-bench")
@handle_errors
def export_bench_command(
    run: Path = typer.Option(..., "--run", help="graded run folder"),
    bench: Path = typer.Option(..., "--bench", help="benchmark folder (one sub-folder per version)"),
    version: str = typer.Option(..., "--version", help="new version X.Y.Z (never overwritten)"),
    parent: str | None = typer.Option(None, "--parent", help="the version this one derives from"),
    notes: str = typer.Option("", "--notes", help="changelog text"),
    amass: bool = typer.Option(False, "--amass", help="also ship each pedestrian's AMASS motion file"),
) -> None:
    """Write an immutable, versioned Parquet release of a graded run."""
    from song.datasets.bench.export import export_bench  # imported here: `--help` stays fast

    result = export_bench(run, bench, version, parent, notes, amass)
    console.print(
        f"released {result.path}: {result.n_episodes} episodes, {result.n_bytes / 1e6:.1f} MB, "
        f"fingerprint {result.fingerprint[:16]}"
    )


@bench_app.command("list")
@handle_errors
def list_command(bench: Path = typer.Argument(..., help="benchmark folder")) -> None:
    """Versions with fingerprints and counts."""
    from song.datasets.bench.release import list_versions, summarize

    rows = [summarize(bench / version) for version in list_versions(bench)]
    columns = ["version", "schema", "parent", "episodes", "scenes", "fingerprint", "created"]
    console.print(status_table(f"releases in {bench}", rows, columns))


@bench_app.command("verify")
@handle_errors
def verify_command(
    bench: Path = typer.Argument(..., help="benchmark folder"),
    version: str | None = typer.Argument(None, help="version (default: latest)"),
) -> None:
    """Recompute every hash; report missing, extra and altered files (exit 1 if any)."""
    from song.datasets.bench.release import resolve_version, verify_release

    report = verify_release(resolve_version(bench, version))
    for kind in ("missing", "extra", "altered"):
        for rel in getattr(report, kind):
            console.print(f"[red]{kind}[/red] {escape(str(rel))}")
    if not report.fingerprint_ok:
        console.print("[red]fingerprint[/red] manifest does not match info.json's fingerprint")
    console.print(f"{report.version}: {'ok' if report.ok else 'FAILED'}")
    if not report.ok:
        raise typer.Exit(1)


@bench_app.command("diff")
@handle_errors
def diff_command(
    bench: Path = typer.Argument(..., help="benchmark folder"),
    old: str = typer.Argument(..., help="older version"),
    new: str = typer.Argument(..., help="newer version"),
    as_json: bool = typer.Option(False, "--json", help="print the full diff as JSON"),
) -> None:
    """Added, removed and changed episodes, and schema changes, between two versions."""
    from song.datasets.bench.release import diff_releases, resolve_version

    diff = diff_releases(resolve_version(bench, old), resolve_version(bench, new))
    if as_json:
        console.print_json(json.dumps(diff))
        return
    console.print(
        f"{diff['old']} → {diff['new']}: +{len(diff['added'])} added, -{len(diff['removed'])} removed, "
        f"~{len(diff['changed'])} changed, {diff['unchanged']} unchanged"
    )
    for name, change in diff["schema_changes"].items():
        console.print(f"schema {name}: added {change['added']} removed {change['removed']}")
    for name, change in diff["content_changes"].items():
        console.print(f"columns {name}: now filled {change['filled']}, now empty {change['emptied']}")


@bench_app.command("export-habitat")
@handle_errors
def export_habitat_command(
    bench: Path = typer.Argument(..., help="benchmark folder or DIR@X.Y.Z"),
    out: Path = typer.Argument(
        ..., help="output folder (<split>/<split>.json.gz, scenes/), or one .json.gz (scenes/ beside it)"
    ),
    version: str | None = typer.Option(None, "--version", help="version (default: latest)"),
) -> None:
    """Habitat PointNav episodes (json.gz, Y-up), a GLB and a pedestrian file per scene."""
    from song.datasets.bench import open_benchmark
    from song.datasets.bench.habitat import export_habitat

    path = export_habitat(open_benchmark(bench, version), out)
    console.print(f"wrote {path}")
