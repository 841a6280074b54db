"""The event plane: sequence numbers, fan-out to subscribers, resume buffer."""

from .plane import EventPlane, HistorySink, HistorySource, Stream
from .record import KIND_EVENT, KIND_PROPERTY, Record, encode
from .subscriber import Interest, Subscriber

__all__ = [
    "KIND_EVENT", "KIND_PROPERTY", "EventPlane", "HistorySink", "HistorySource", "Interest", "Record",
    "Stream", "Subscriber", "encode",
]
