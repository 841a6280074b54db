"""``wott-hub bench NAME``: run a benchmark from the source tree's ``benchmarks/``.

Benchmarks measure this checkout, so they live beside the code, not in the installed
package; this command finds ``benchmarks/`` from the working folder upwards and runs
``bench_NAME.py`` (a script) or ``bench_NAME/`` (a package with a ``__main__``) with the
remaining arguments, ``benchmarks/`` first on ``sys.path`` (where ``report.py`` is shared).
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import typer

__all__ = ["app", "bench"]

app = typer.Typer(help="Performance and accuracy reports (written to docs/benchmarks.md).",
                  rich_markup_mode=None)


def _benchmarks_dir() -> Path | None:
    for folder in (Path.cwd(), *Path.cwd().parents):
        if (folder / "benchmarks" / "report.py").exists():
            return folder / "benchmarks"
    return None


def _available(folder: Path) -> dict[str, Path]:
    """Benchmark name -> its script, or its package's ``__main__.py``."""
    found = {p.stem.removeprefix("bench_"): p for p in folder.glob("bench_*.py")}
    found.update({p.parent.name.removeprefix("bench_"): p for p in folder.glob("bench_*/__main__.py")})
    return dict(sorted(found.items()))


@app.command(short_help="Run a benchmark (no NAME: list them).",
             context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def bench(ctx: typer.Context,
          name: str | None = typer.Argument(None, help="Benchmark name; omit to list.")) -> None:
    """Run benchmarks/bench_NAME.py or the package benchmarks/bench_NAME/ (extra arguments are passed on)."""
    folder = _benchmarks_dir()
    if folder is None:
        typer.echo("no benchmarks/ folder here: run from a wott-hub checkout", err=True)
        raise typer.Exit(2)
    available = _available(folder)
    if not name:
        typer.echo("\n".join(available))
        return
    target = available.get(name)
    if target is None:
        typer.echo(f"unknown benchmark {name!r}; available: {', '.join(available)}", err=True)
        raise typer.Exit(2)
    sys.path.insert(0, str(folder))
    if target.name == "__main__.py":
        sys.argv = [f"wott-hub bench {name}", *ctx.args]
        runpy.run_module(target.parent.name, run_name="__main__", alter_sys=True)
    else:
        sys.argv = [str(target), *ctx.args]
        runpy.run_path(str(target), run_name="__main__")
