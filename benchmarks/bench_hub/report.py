"""The hub section of docs/benchmarks.md: headings, tables and the numbers beside them, nothing else.

What the columns mean, how each point is measured and the targets are hand-written in
docs/benchmarks.md ("Hub: what the tables measure"), outside the generated section, so a
re-run replaces only numbers. The headings here are the anchors that text refers to: keep
them when a table changes.
"""

from __future__ import annotations

import re
import statistics

from report import DOC, markdown_table, write_section  # benchmarks/report.py, shared by every benchmark

__all__ = ["SECTION", "TITLE", "body", "cell", "expose", "history", "keep_others", "latency", "ms", "startup",
           "throughput", "write"]

SECTION = "hub"
TITLE = "Hub: servient, event plane, history"


def ms(ns: float) -> str:
    return "-" if ns != ns else f"{ns / 1e6:.2f}"


def cell(t) -> str:
    """(sent, received, p50, p99) -> "p50 / p99 (received/sent)" in ms."""
    sent, got, p50, p99 = t
    return f"{ms(p50)} / {ms(p99)} ({got}/{sent})"


def latency(res: dict) -> str:
    repeats = "".join(
        f"\n\n{n} devices, {len(sse)} runs (the median run by SSE p99 is shown): SSE p99 "
        + ", ".join(ms(x) for x in sse) + " ms; hub WS p99 " + ", ".join(ms(x) for x in ws)
        + " ms; frames/s processed " + ", ".join(f"{x:.0f}" for x in fps)
        + f" (median {statistics.median(fps):.0f}); hub CPU per frame " + ", ".join(f"{x:.0f}" for x in cpu)
        + f" µs (median {statistics.median(cpu):.0f}), less the simulated devices' own "
        + ", ".join(f"{x:.0f}" for x in own) + f" µs (median {statistics.median(own):.0f})."
        for n, sse, ws, fps, cpu, own in res["repeats"])
    out = (
        f"### Latency: a frame enters the pipeline -> its event at a client (ms, p50 / p99; "
        f"{res['duration']:g} s per point)\n\n"
        + markdown_table(["devices", "frames/s processed / offered", "hub SSE", "hub WS",
                          "hub WS, wotpy client", "plain wotpy WS, wotpy client",
                          "CPU % of a core, hub / client",
                          "hub CPU µs per frame · less the devices' own"], res["rows"])
        + repeats
        + "\n\nStages (ms, p50 / p99):\n\n"
        + markdown_table(["devices", "processing", "encoding", "SSE fan-out", "SSE transport",
                          "SSE decode", "WS fan-out", "WS transport", "wotpy after write",
                          "wotpy decode"], res["stage_rows"]))
    if res["variant_rows"]:
        out += ("\n\nVariants: `workers = N`, `processing precomputed` (ms, p50 / p99):\n\n"
                + markdown_table(["devices", "variant", "frames/s", "hub SSE", "hub WS", "processing",
                                  "SSE fan-out", "SSE transport", "CPU % of a core, hub / client",
                                  "hub CPU µs per frame · less the devices' own"],
                                 res["variant_rows"]))
    if res.get("ab_rows"):
        out += ("\n\nOne `skinDisplacement` subscriber per device (issue 29; SSE, its JSON text), three runs "
                "without and with alternated, medians:\n\n"
                + markdown_table(["devices", "frames/s, none", "frames/s, one per device",
                                  "frames/s processed (median)", "hub CPU µs per frame (median)",
                                  "hub SSE p99"], res["ab_rows"])
                + "\n\nHub CPU per frame: the hub process's and its history process's CPU time in the SSE "
                  "client's window over the frames processed then (what the cost is on a machine that "
                  "has the cores; frames processed is what it becomes on one that has not).")
    return out


def throughput(res: dict) -> str:
    return (f"### Sustained events/s to one subscriber ({res['duration']:g} s per rate)\n\n"
            + markdown_table(["server", "offered/s", "published/s", "published", "SSE received",
                              "WS received", "in history"], res["rows"]))


def expose(res: dict) -> str:
    return ("### Things on one servient: time to expose N Tactile Things, TD GET latency\n\n"
            + markdown_table(["server", "N", "exposed", "expose (s)", "TD GET p50 (ms)", "TD GET p99 (ms)"],
                             res["rows"]))


def startup(res: dict) -> str:
    rest = res["rest"]
    rows = [[name, i + 1, f"{a:.2f}", f"{b:.2f}", c]
            for name, trials in res["trials"].items() for i, (a, b, c) in enumerate(trials)]
    return ("### Start-up of the demo scene\n\n"
            "`uv run wott-hub run` as typed (target: TDs served <= 1.5 s) and the venv's `wott-hub` "
            "script, trials alternated.\n\n"
            + markdown_table(["launcher", "trial", "TDs served (s)", "ready (s)", "devices"], rows)
            + "\n\nThe demo at rest (ready, no client, its simulated devices playing their looping scenes), "
            f"over {rest['seconds']:g} s, the hub and its {rest.get('processes', 1) - 1} child process(es) "
            f"(the history writer's): CPU {rest['cpu_pct']:.0f} % of one core, resident memory "
            f"{rest['rss_mib']:.0f} MiB (peak {rest['peak_mib']:.0f} MiB).")


def history(res: dict) -> str:
    r, span = res["result"], res["span"]
    return (
        "### History\n\n"
        f"{span} of one 120 Hz device: {r['records']:,} records, {r['size_mb']:.0f} MB SQLite (WAL).\n\n"
        + markdown_table(["what", "result", "target"], [
            ["written (batched writer, events/s)", f"{r['write_rate']:,.0f}", ">= 50,000"],
            ["anchor: INSERT + COMMIT per event (events/s)", f"{r['naive_rate']:,.0f}", "-"],
            [f"replay {span} at speed 0 through the event plane (s)", f"{r['replay_s']:.2f}",
             "<= 5 (one hour)"],
            ["replayed / stored", f"{r['replayed']:,} / {r['stored']:,}", "equal"],
        ]))


def body(sections: list[str], load: float, quick: bool) -> str:
    head = f"Load average at the end: {load:.1f}.{' Quick mode.' if quick else ''}"
    return "\n\n".join([head, *sections])


def _heading(sub: str) -> str:
    """A subsection's anchor: its heading up to the first parenthesis or colon."""
    return re.split(r"[(:]", sub.splitlines()[0], maxsplit=1)[0].strip()


def keep_others(text: str) -> str:
    """``text`` (a run of some groups) followed by the subsections of the groups it did not run,
    as docs/benchmarks.md has them, each marked with the run it comes from: re-measuring one
    group does not delete the others' tables."""
    old = re.search(rf"<!-- bench:{SECTION} -->.*?<!-- /bench:{SECTION} -->", DOC.read_text(), re.S)
    if old is None:
        return text
    run = re.search(r"^Run: (.*)$", old.group(0), re.M)
    new = {_heading(s) for s in text.split("\n### ")[1:]}
    kept = [s for s in old.group(0).removesuffix(f"<!-- /bench:{SECTION} -->").split("\n### ")[1:]
            if _heading(s) not in new]
    mark = "(Not re-run: kept from"
    note = f"\n\n{mark} {run.group(1)}.)" if run else ""
    return text + "".join(f"\n\n### {s.rstrip()}{'' if mark in s else note}" for s in kept)


def write(text: str, command: str):
    return write_section(SECTION, TITLE, text, command)
