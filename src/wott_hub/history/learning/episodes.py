"""Episodes: the spans of history a learning export cuts into, marked while recording or given by hand.

A hub with history serves a Thing ``episodes`` (``hub/episodes.py``) whose two events are recorded
like a device's: ``episodeStarted`` ``{"task", "timeStamp"}`` when the hub Thing's ``startEpisode``
action is invoked, ``episodeEnded`` ``{"task", "timeStamp"}`` at ``endEpisode`` (or when the hub
stops with an episode open). ``marked`` reads them back: each start paired with the next end; a start
with no end before the next start (a hub that was killed) ends where the next one starts, or at the
end of the range asked for. An episode that only overlaps the range is cut to it.

On the command line an episode is ``FROM..TO`` or ``FROM..TO=TASK`` (``--episodes``), ``FROM`` and
``TO`` in any form ``wott-hub history`` reads (ISO 8601, ``-10m``, seconds since the epoch).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import TYPE_CHECKING

from wott_hub.errors import InvalidInput

from ..times import parse_time

if TYPE_CHECKING:
    from ..storage import StorageReader

__all__ = [
    "DEFAULT_TASK",
    "EPISODES_THING",
    "EPISODE_ENDED",
    "EPISODE_STARTED",
    "MAX_TASK",
    "Episode",
    "marked",
    "parse_episode",
    "task_text",
]

EPISODES_THING = "episodes"
EPISODE_STARTED = "episodeStarted"
EPISODE_ENDED = "episodeEnded"
DEFAULT_TASK = "recorded session"
"""The task of a range exported without marks or a task of its own."""
MAX_TASK = 1000
"""The longest task text (characters): a sentence, not a document."""


@dataclass(frozen=True)
class Episode:
    """[start_ns, end_ns] of history, and what was being done then."""

    start_ns: int
    end_ns: int
    task: str


def task_text(task: object, where: str) -> str:
    """A task as a dataset keeps it: a non-empty line of at most ``MAX_TASK`` characters."""
    if not isinstance(task, str) or not task.strip():
        raise InvalidInput(f"{where} must be a non-empty text, got {task!r}")
    task = task.strip()
    if len(task) > MAX_TASK or "\n" in task or "\r" in task:
        raise InvalidInput(f"{where} must be one line of at most {MAX_TASK} characters")
    return task


def parse_episode(text: str, default_task: str = DEFAULT_TASK, now_ns: int | None = None) -> Episode:
    """``FROM..TO`` or ``FROM..TO=TASK``; InvalidInput naming what is wrong."""
    span, eq, task = text.partition("=")
    lo, dots, hi = span.partition("..")
    if not dots or not lo.strip() or not hi.strip():
        raise InvalidInput(f"--episodes {text!r}: expected FROM..TO or FROM..TO=TASK")
    start, end = parse_time(lo.strip(), now_ns), parse_time(hi.strip(), now_ns)
    if start >= end:
        raise InvalidInput(f"--episodes {text!r}: its start is not before its end")
    return Episode(start, end, task_text(task, f"--episodes {text!r}: the task") if eq else default_task)


def marked(reader: StorageReader, t_from_ns: int | None, t_to_ns: int | None) -> list[Episode]:
    """The episodes marked in history that overlap [t_from, t_to], cut to it, in time order."""
    if not reader.recorded(EPISODES_THING):
        return []
    marks: list[tuple[int, str, str]] = []
    # every mark is read (a few per episode): an episode started before the range still counts
    for page in reader.pages(EPISODES_THING, None, t_to_ns, [EPISODE_STARTED, EPISODE_ENDED]):
        for rec in page:
            try:
                task = json.loads(rec.data).get("task", DEFAULT_TASK)
            except (ValueError, AttributeError):
                continue  # not a mark this hub wrote
            marks.append((rec.t_ns, rec.name, task if isinstance(task, str) and task else DEFAULT_TASK))
    marks.sort(key=lambda m: m[0])
    episodes: list[Episode] = []
    open_at: tuple[int, str] | None = None
    for t, name, task in marks:
        if name == EPISODE_STARTED:
            if open_at is not None:
                episodes.append(Episode(open_at[0], t, open_at[1]))
            open_at = (t, task)
        elif open_at is not None:
            episodes.append(Episode(open_at[0], t, open_at[1]))
            open_at = None
    if open_at is not None and t_to_ns is not None:
        episodes.append(Episode(open_at[0], t_to_ns, open_at[1]))
    elif open_at is not None:
        last = max(
            (s.last_t_ns or 0 for s in reader.things(count=False) if s.id != EPISODES_THING), default=0
        )
        if last > open_at[0]:
            episodes.append(Episode(open_at[0], last, open_at[1]))
    lo = t_from_ns if t_from_ns is not None else -1
    hi = t_to_ns if t_to_ns is not None else 1 << 63
    return [
        Episode(max(e.start_ns, lo), min(e.end_ns, hi), e.task)
        for e in episodes
        if e.end_ns >= lo and e.start_ns <= hi and max(e.start_ns, lo) < min(e.end_ns, hi)
    ]
