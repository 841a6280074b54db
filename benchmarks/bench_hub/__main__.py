"""``wott-hub bench hub``: parse the options, run the chosen groups in order, print and write the tables.

The groups always run in the order of ``GROUPS``, whatever the order of ``--groups``, so a
partial run's section reads like a full one. Writing replaces the whole "Hub" section of
docs/benchmarks.md with what this run measured (``--no-write`` prints only).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import tempfile
from pathlib import Path

from wott_hub.config import MAX_WORKERS

from . import expose, history, latency, report, startup, throughput

__all__ = ["GROUPS", "main", "parse_args", "run_groups"]

GROUPS = ("latency", "throughput", "expose", "startup", "history")


def _devices(text: str) -> tuple[int, ...]:
    try:
        counts = tuple(int(v) for v in text.split(","))
    except ValueError:
        counts = ()
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"expected device counts like 32 or 1,8, got {text!r}")
    return counts


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _workers(text: str) -> tuple[int, ...]:
    try:
        counts = tuple(int(v) for v in text.split(","))
    except ValueError:
        counts = ()
    if not counts or min(counts) < 1 or max(counts) > MAX_WORKERS:
        raise argparse.ArgumentTypeError(f"expected worker counts from 1 to {MAX_WORKERS} like 1 or 1,2, "
                                         f"got {text!r}")
    return counts


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="wott-hub bench hub",
                                 description="Hub benchmarks: latency, events/s, Things per servient, "
                                             "start-up, history; plain wotpy in the same run.")
    ap.add_argument("--quick", action="store_true", help="smoke run in about a minute")
    ap.add_argument("--groups", default=",".join(GROUPS), help=f"comma-separated, of: {', '.join(GROUPS)}")
    ap.add_argument("--devices", type=_devices, default=None, metavar="N[,N...]",
                    help="latency group: these device counts only (default 1,8,32,64; 1,8 with --quick)")
    ap.add_argument("--workers", type=_workers, default=None, metavar="W[,W...]",
                    help="latency group: worker counts of the variant rows, from 8 devices on (default 1; "
                         "workers = 0 is the main row)")
    ap.add_argument("--duration", type=_seconds, default=None, metavar="S",
                    help="latency group: seconds measured per point (default 6; 2 with --quick)")
    ap.add_argument("--displacement-ab", action="store_true",
                    help="latency group: also three runs without and with one skinDisplacement subscriber "
                         "per device, alternated, at each device count (issue 29's cost rule)")
    ap.add_argument("--no-write", action="store_true", help="print only; do not update docs/benchmarks.md")
    args = ap.parse_args(argv)
    groups = [g.strip() for g in args.groups.split(",") if g.strip()]
    unknown = sorted(set(groups) - set(GROUPS))
    if unknown or not groups:
        ap.error(f"unknown group {', '.join(unknown) or '(none)'}; groups: {', '.join(GROUPS)}")
    args.groups = set(groups)
    return args


async def run_groups(args: argparse.Namespace) -> list[str]:
    """The report sections of the chosen groups, in ``GROUPS`` order."""
    tmp = Path(tempfile.mkdtemp(prefix="bench-hub-"))
    sections = []
    if "latency" in args.groups:
        sections.append(report.latency(await latency.run(tmp, quick=args.quick, devices=args.devices,
                                                         duration=args.duration, workers=args.workers,
                                                         ab=args.displacement_ab)))
    if "throughput" in args.groups:
        sections.append(report.throughput(await throughput.run(tmp, quick=args.quick)))
    if "expose" in args.groups:
        sections.append(report.expose(await expose.run(quick=args.quick)))
    if "startup" in args.groups:
        sections.append(report.startup(await startup.run()))
    if "history" in args.groups:
        sections.append(report.history(await history.run(tmp, quick=args.quick)))
    return sections


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces this run, for the section's "Run:" line."""
    cmd = "uv run wott-hub bench hub" + (" --quick" if args.quick else "")
    if args.groups != set(GROUPS):
        cmd += " --groups " + ",".join(g for g in GROUPS if g in args.groups)
    if args.devices:
        cmd += " --devices " + ",".join(map(str, args.devices))
    if args.workers:
        cmd += " --workers " + ",".join(map(str, args.workers))
    if args.duration is not None:
        cmd += f" --duration {args.duration:g}"
    if args.displacement_ab:
        cmd += " --displacement-ab"
    return cmd


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    logging.getLogger("asyncio").setLevel(logging.CRITICAL)  # plain wotpy's unretrieved write errors
    logging.getLogger("tornado").setLevel(logging.CRITICAL)
    sections = asyncio.run(run_groups(args))
    body = report.body(sections, os.getloadavg()[0], args.quick)
    print(body)
    if not args.no_write:
        print(report.write(body if args.groups == set(GROUPS) else report.keep_others(body), _command(args)))


if __name__ == "__main__":
    main()
