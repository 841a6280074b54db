"""The fleet's one WoT servient: wotpy adapters, the hub's HTTP/SSE routes, the hub Thing."""

from .adapters import FastThing, HubHTTPServer, HubServient, HubWebsocketServer, IndexedExposedThingSet
from .forms import PREFIX, FormLayout, clean_td, with_forms
from .hub_thing import HUB_THING_ID, hub_td
from .server import ALL_INTERFACES, HubServer
from .things import ServedThing, ThingRegistry

__all__ = [
    "ALL_INTERFACES", "HUB_THING_ID", "PREFIX", "FastThing", "FormLayout", "HubHTTPServer", "HubServer",
    "HubServient", "HubWebsocketServer", "IndexedExposedThingSet", "ServedThing", "ThingRegistry", "clean_td",
    "hub_td", "with_forms",
]
