"""``wott-hub bench NAME``: run a benchmark from the source tree's ``benchmarks/``.

Benchmarks measure this checkout, so they live beside the code, not in the
installed package; this command finds ``benchmarks/bench_NAME.py`` from the
working folder upwards and runs it with the remaining arguments.
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import typer

app = typer.Typer(help="Performance and accuracy reports (written to docs/benchmarks.md).")


def _benchmarks_dir() -> Path | None:
    for folder in (Path.cwd(), *Path.cwd().parents):
        if (folder / "benchmarks" / "report.py").exists():
            return folder / "benchmarks"
    return None


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def bench(ctx: typer.Context, name: str = typer.Argument(None, help="Benchmark name; omit to list.")):
    """Run benchmarks/bench_NAME.py (extra arguments are passed on)."""
    folder = _benchmarks_dir()
    if folder is None:
        typer.echo("no benchmarks/ folder here: run from a wott-hub checkout", err=True)
        raise typer.Exit(2)
    available = sorted(p.stem.removeprefix("bench_") for p in folder.glob("bench_*.py"))
    if not name:
        typer.echo("\n".join(available))
        return
    script = folder / f"bench_{name}.py"
    if not script.exists():
        typer.echo(f"unknown benchmark {name!r}; available: {', '.join(available)}", err=True)
        raise typer.Exit(2)
    sys.argv = [str(script), *ctx.args]
    sys.path.insert(0, str(folder))
    runpy.run_path(str(script), run_name="__main__")
