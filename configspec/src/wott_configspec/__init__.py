"""Configuration declared once: typed fields with bounds, read by msgspec, errors naming file, table and key.

Every table a wott program reads (the hub's ``[hub]``, ``[directory]``, ``[discovery]``,
a device family's settings, a scene file, the standalone directory's settings) is a
msgspec ``Struct`` whose field types carry their bounds (``Meta(ge=..., le=...)``) and
the words a person is told when a value is wrong (``says``). That one declaration gives
the check, the default, the error message and the JSON Schema the docs show, so the
three can no longer drift apart as hand-written checks did.

Why a distribution of its own: the hub and the Thing Description Directory read their
settings the same way and must word their errors the same way, but the directory is a
distribution the hub depends on, so the code both use cannot live in either. It imports
msgspec only: reading a config stays cheap, and it knows nothing of either program.

Why every number has an upper bound too: NaN fails every comparison and infinity fails
every finite ``le``, so both are refused by the same bound that keeps ``workers = 100000``
from forking the machine to death (``bounded`` insists on one).

A wrong value is a ``ConfigError`` (a ``ValueError``) of one line:
``hub.toml: [hub].workers: a whole number of processes, got 100000; must be from 0 to 64``.
A program with an error tree of its own translates it once, where it reads
(``wott_hub.configspec``).
"""

from ._declare import Flag, Model, bounded, doc, says, table_of
from ._explain import explain, range_text
from ._read import ConfigError, check, json_schema, read

__all__ = ["ConfigError", "Flag", "Model", "bounded", "check", "doc", "explain", "json_schema", "range_text",
           "read", "says", "table_of"]
