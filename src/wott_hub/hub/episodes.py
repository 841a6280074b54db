"""Episodes marked while recording: the hub Thing's ``startEpisode``/``endEpisode``, the Thing ``episodes``.

A learning dataset is cut into episodes, each with a task ("pick up the cup"). Marking them while
recording is one POST each (``startEpisode {"task"}``, ``endEpisode {}``: the CLI's ``wott-hub episode``,
``wott_client``'s ``history.start_episode``), and the marks are history records like any other: the hub
serves a Thing ``episodes``, recorded, whose events ``episodeStarted`` and ``episodeEnded`` (``{"task",
"timeStamp"}``) say when; ``history export --format lerobot|zarr`` reads them back
(``history/learning/episodes.py``), and a subscriber sees them live. The Thing is served (and registered
in history) at the first ``startEpisode``: a hub that marks nothing lists nothing more.

One episode is open at a time: ``startEpisode`` while one is open, or ``endEpisode`` with none, is a 409
naming the open one; a task that is not a line of 1 to 1,000 characters is a 400; a hub without
history has nothing to mark (404). A hub that stops with an episode open ends it first (a killed hub
cannot: the export ends such an episode where the next starts, or at the end of its range). Both
actions change what is recorded: they need the ``control`` scope.
"""

from __future__ import annotations

import asyncio
import json
import time
from typing import TYPE_CHECKING, Any

from wott_hub.errors import Conflict, NotFound
from wott_hub.events.record import KIND_EVENT
from wott_hub.history.learning.episodes import (
    EPISODE_ENDED,
    EPISODE_STARTED,
    EPISODES_THING,
    MAX_TASK,
    task_text,
)
from wott_hub.td.vocabulary import TD_CONTEXT

from .actions import install as install_actions

if TYPE_CHECKING:
    from wott_hub.events.plane import EventPlane
    from wott_hub.servient.server import HubServer

    from .recording import HubHistory
    from .things import Things

__all__ = ["ACTIONS", "Episodes"]

_MARK = {
    "type": "object",
    "properties": {
        "task": {"type": "string", "description": "What is being done in the episode."},
        "timeStamp": {"type": "integer", "minimum": 0, "unit": "ns"},
    },
    "required": ["task", "timeStamp"],
}
_SPAN = {
    "type": "object",
    "properties": {
        "task": {"type": "string"},
        "from": {"type": "integer", "description": "Start, ns since the epoch."},
        "to": {"type": "integer", "description": "End, ns since the epoch (endEpisode only)."},
    },
}

ACTIONS: dict[str, dict[str, Any]] = {
    "startEpisode": {
        "title": "startEpisode",
        "description": "Start an episode of the recording with its task (one at a time); recorded as the "
        "Thing 'episodes' event episodeStarted, read by `history export --format lerobot`.",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {
            "type": "object",
            "properties": {
                "task": {
                    "type": "string",
                    "minLength": 1,
                    "maxLength": MAX_TASK,
                    "description": "What is being done, one line (e.g. 'pick up the cup').",
                }
            },
            "required": ["task"],
        },
        "output": _SPAN,
    },
    "endEpisode": {
        "title": "endEpisode",
        "description": "End the open episode (recorded as the Thing 'episodes' event episodeEnded).",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {"type": "object", "properties": {}},
        "output": _SPAN,
    },
}

_TD: dict[str, Any] = {
    "@context": list(TD_CONTEXT),
    "title": EPISODES_THING,
    "description": "Episodes marked while recording (the hub Thing's startEpisode and endEpisode).",
    "security": ["nosec_sc"],
    "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}},
    "events": {
        EPISODE_STARTED: {"title": EPISODE_STARTED, "description": "An episode started.", "data": _MARK},
        EPISODE_ENDED: {"title": EPISODE_ENDED, "description": "The episode ended.", "data": _MARK},
    },
}


class Episodes:
    """The open episode, and its marks published on the recorded Thing ``episodes``."""

    def __init__(self, plane: EventPlane, things: Things, history: HubHistory) -> None:
        self.plane = plane
        self.things = things
        self.history = history
        self.open: tuple[str, int] | None = None  # (task, start ns)
        self.served = False
        self._lock = asyncio.Lock()  # two starts at once: one opens, the other is a 409

    def install(self, td: dict[str, Any], server: HubServer) -> None:
        """Declare the actions in the hub Thing's TD (before it is served) and mount their handlers."""
        install_actions(
            td,
            server,
            {
                "startEpisode": (ACTIONS["startEpisode"], self._start),
                "endEpisode": (ACTIONS["endEpisode"], self._end),
            },
        )

    async def _marks(self) -> None:
        """Serve the Thing ``episodes`` (recorded) at the first mark: a hub that marks nothing serves and
        records nothing more."""
        if self.history.writer is None:
            raise NotFound("this hub records no history (history = false): there is nothing to mark")
        if not self.served:
            td = json.loads(json.dumps(_TD))
            td["id"] = f"{self.things.identity.urn}:{EPISODES_THING}"
            await self.things.expose(EPISODES_THING, td, record=True, family="episodes")
            self.served = True

    def _publish(self, name: str, task: str, t_ns: int) -> None:
        data = json.dumps({"task": task, "timeStamp": t_ns}, separators=(",", ":"), ensure_ascii=False)
        self.plane.publish(EPISODES_THING, KIND_EVENT, name, t_ns, data)

    async def _start(self, x: dict[str, Any]) -> dict[str, Any]:
        task = task_text(x.get("task"), "'task'")
        async with self._lock:
            return await self._open(task)

    async def _open(self, task: str) -> dict[str, Any]:
        if self.open is not None:
            raise Conflict(f"an episode is open ({self.open[0]!r}): end it first (endEpisode)")
        await self._marks()
        t_ns = time.time_ns()
        self._publish(EPISODE_STARTED, task, t_ns)
        self.open = (task, t_ns)
        return {"task": task, "from": t_ns}

    async def _end(self, x: dict[str, Any]) -> dict[str, Any]:
        if self.open is None:
            raise Conflict("no episode is open (startEpisode first)")
        return self.end()

    def end(self) -> dict[str, Any]:
        """End the open episode (the hub stopping: before history closes); nothing if none is open."""
        if self.open is None:
            return {}
        task, start = self.open
        t_ns = max(time.time_ns(), start + 1)
        self._publish(EPISODE_ENDED, task, t_ns)
        self.open = None
        return {"task": task, "from": start, "to": t_ns}
