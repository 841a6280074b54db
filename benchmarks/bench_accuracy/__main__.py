"""``wott-hub bench accuracy``: record every family's cases, process them under each setting, score, report.

    uv run wott-hub bench accuracy [--families "scene pad,taxel"] [--variants] [--cost-before DIR]
                                   [--realtime] [--stress N] [--no-write] [--json FILE]

The tables go to the "accuracy" section of docs/benchmarks.md (what they measure is
written beside it, by hand); ``--json`` also saves the per-family numbers (to compare
runs); ``--variants`` adds the error-against-run-time table of the settings in
``variants.VARIANTS`` (each re-processes the same recordings); ``--cost-before`` the cost
per frame against another checkout's ``tactile`` package (``cost.py``). ``--realtime`` plays
the camera skins' simulated sources as live cameras (paced, frames dropped when read late);
``--stress N`` records beside ``stress-ng --cpu N`` (``stress.py``) and implies ``--realtime``:
what is derived from frames that came late or not at all is scored (issue 48, item 9). Both
write to their own section (``accuracy-stress``), not over the quiet run's tables.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from report import markdown_table, write_section

from wott_hub.tactile import FrameProcessor

from .cases import CASES
from .families import FAMILIES, Recording, record
from .score import CaseScore, score
from .stress import stress
from .tables import (
    SUMMARY_HEADER,
    actions_table,
    cases_table,
    noise_table,
    summary,
    summary_row,
    targets_table,
)
from .truth import FrameTruth, frame_truths
from .variants import DEFAULT, VARIANTS, Variant, processor, run

__all__ = ["main"]


def _families(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in FAMILIES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"families are {', '.join(FAMILIES)}; got {text!r}")
    return names


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a number of CPU workers, got {text!r}") from None
    if not 0 <= n <= 64:
        raise argparse.ArgumentTypeError(f"between 0 and 64 CPU workers, got {n}")
    return n


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="wott-hub bench accuracy", description=__doc__.split("\n\n")[0])
    ap.add_argument("--families", type=_families, default=list(FAMILIES), help="comma-separated, default all")
    ap.add_argument("--variants", action="store_true", help="also the error against run time of each setting")
    ap.add_argument("--realtime", action="store_true",
                    help="play the camera skins' sources in real time, as live cameras")
    ap.add_argument("--stress", type=_workers, default=0, metavar="N",
                    help="record beside stress-ng --cpu N (implies --realtime)")
    ap.add_argument("--no-write", action="store_true", help="print the tables, leave docs/benchmarks.md")
    ap.add_argument("--json", type=Path, help="write the per-family numbers here too")
    ap.add_argument("--cost-before", type=Path, metavar="DIR",
                    help="another checkout's src/wott_hub/tactile: processing cost per frame, before and now")
    return ap.parse_args(argv)


def _score_all(recs: list[tuple[Recording, list[FrameTruth]]], variant: Variant
               ) -> tuple[list[CaseScore], int]:
    scores, refused = [], 0
    for rec, truths in recs:
        kept, results, times, bad = run(rec, variant)
        refused += bad
        scores.append(score(rec, [truths[k] for k in kept], results, times))
    return scores, refused


def _noise_row(name: str, recs: list[tuple[Recording, list[FrameTruth]]]) -> list[object]:
    """What a family's frames at rest show (the largest free-node norm of each), and its thresholds."""
    rest = []
    for rec, truths in recs:
        free = rec.description.mesh.free
        rest += [float(np.linalg.norm(f.displacement[free], axis=1).max())
                 for f, t in zip(rec.frames, truths, strict=True) if t.rest]
    rec = recs[0][0]
    proc = processor(rec, DEFAULT)
    p, noise = proc.params, proc.noise_mm
    return [name, f"{p.epsilon_mm:g}", len(rest), f"{statistics.median(rest):.4f} / {max(rest):.4f}",
            f"{noise:.4f}", f"{p.merge_noise * noise:.3f} and {p.merge_ratio:.0%} of it",
            f"{p.birth_noise * noise:.4f}", f"{p.side_lobe_ratio:g}"]


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    t0 = time.monotonic()
    recs: list[tuple[Recording, list[FrameTruth]]] = []
    realtime = args.realtime or args.stress > 0
    with stress(args.stress):
        for name in args.families:
            family = FAMILIES[name]
            for i, case in enumerate(CASES[family.skin]):
                rec = record(family, case, i, realtime=realtime)
                recs.append((rec, frame_truths(rec)))
                print(f"recorded {name} {case.name}: {len(rec.frames)} frames", file=sys.stderr)
    recorded_s = time.monotonic() - t0
    scores, refused = _score_all(recs, DEFAULT)
    per_family = {n: summary(c for c in scores if c.family == n) for n in args.families}
    targets = targets_table([summary_row(n, m) for n, m in per_family.items()])
    parts = [targets, "### Per case", cases_table(scores), "### Actions: in how many cases each was reported",
             actions_table(scores)]
    if hasattr(FrameProcessor, "noise_mm"):  # issue 31's thresholds (the bench also scores the code before)
        parts += ["### Noise floors and the thresholds derived from them",
                  noise_table([_noise_row(n, [r for r in recs if r[0].family == n]) for n in args.families])]
    if args.variants:
        rows = []
        for variant in VARIANTS:
            vs, _ = _score_all(recs, variant)
            for n in args.families:
                rows.append(summary_row(f"{variant.name}: {n}", summary(c for c in vs if c.family == n)))
        parts += ["### Error against run time: the settings compared",
                  markdown_table(["setting: family", *SUMMARY_HEADER[1:]], rows)]
    if args.cost_before:
        from .cost import cost_table, load_tactile

        parts += ["### Processing cost per frame, against the code before",
                  cost_table(load_tactile(args.cost_before))]
    frames = sum(len(r.frames) for r, _ in recs)
    load = (f" beside `stress-ng --cpu {args.stress}`" if args.stress
            else " (camera skins in real time)" if realtime else "")
    parts.append(f"{len(recs)} recordings, {frames} frames ({recorded_s:.0f} s to record{load}); "
                 f"frames refused by the processor: {refused}.")
    body = "\n\n".join(parts)
    print(body)
    if args.json:
        args.json.write_text(json.dumps(per_family, indent=1))
    if not args.no_write:
        options = " --variants" if args.variants else ""
        options += " --cost-before DIR" if args.cost_before else ""
        if realtime:
            options += f" --stress {args.stress}" if args.stress else " --realtime"
            write_section("accuracy-stress", "Contacts and actions on a busy machine (issue 48)", body,
                          "uv run wott-hub bench accuracy" + options)
            return
        write_section("accuracy", "Contacts and actions against scene truth (issue 31)", body,
                      "uv run wott-hub bench accuracy" + options)


if __name__ == "__main__":
    main()
