"""Secrets out of every log line and error text: tokens, ``access_token=`` values, bearer credentials.

A token reaches text in more ways than any one call site can guard: tornado's
"Uncaught exception POST /...?access_token=..." when a client drops mid-request, a
``repr`` of a request, an HTTP client's error quoting a URL, a header echoed in a
debug line. So the redaction sits where every log line is made: a ``LogRecord``
factory (``install_log_redaction``, once per process, kept for its life) rewrites
each record's message, and the text of its exception and stack, before any handler
or formatter sees it. Error texts the hub hands to clients or shows in health (a
wot-remote device's reason, a directory's answer) go through ``redact`` where they
are made.

What is redacted: a wott token's secret (``wott_<id>_<secret>`` becomes
``wott_<id>_[redacted]``: the id is public and says which token it was), the value of
an ``access_token`` parameter, and the credential after ``Bearer``. The gate also takes
``access_token`` out of each request before a handler runs (``gate.py``).
"""

from __future__ import annotations

import logging
import re
import threading
import traceback
from typing import Any

__all__ = ["REDACTED", "install_log_redaction", "redact"]

REDACTED = "[redacted]"

_TOKEN = re.compile(r"\b(wott_[0-9A-Fa-f]{8}_)[A-Za-z0-9_\-]+")
_QUERY = re.compile(r"((?:\baccess_token|%61ccess_token)(?:=|%3D))[^&\s\"'<>#]+", re.IGNORECASE)
_BEARER = re.compile(r"(\bBearer\s+)[A-Za-z0-9._~+/\-]{16,}=*", re.IGNORECASE)  # not "Bearer realm"
_HINT = re.compile(r"wott_|access_token|%61ccess|bearer", re.IGNORECASE)

_installed = False
_lock = threading.Lock()


def redact(text: str) -> str:
    """``text`` with every secret it holds replaced by ``[redacted]`` (module docstring)."""
    if not _HINT.search(text):
        return text
    text = _TOKEN.sub(r"\1" + REDACTED, text)
    text = _QUERY.sub(r"\1" + REDACTED, text)
    return _BEARER.sub(r"\1" + REDACTED, text)


def _redact_record(record: logging.LogRecord) -> None:
    try:
        message = record.getMessage()
    except Exception:  # a record whose arguments do not format: leave it to the handler's own error
        return
    clean = redact(message)
    if clean != message:
        record.msg, record.args = clean, None
    if record.exc_info and record.exc_info[0] is not None and not record.exc_text:
        text = "".join(traceback.format_exception(*record.exc_info)).rstrip("\n")
        record.exc_text = redact(text)  # formatters use exc_text when it is set
    if record.stack_info:
        record.stack_info = redact(record.stack_info)


def install_log_redaction() -> None:
    """Redact every ``LogRecord`` this process makes from now on (idempotent)."""
    global _installed
    with _lock:
        if _installed:
            return
        previous = logging.getLogRecordFactory()

        def factory(*args: Any, **kwargs: Any) -> logging.LogRecord:
            record = previous(*args, **kwargs)
            _redact_record(record)
            return record

        logging.setLogRecordFactory(factory)
        _installed = True
