"""A parquet file's tables written in a thread of their own, one table behind the export at most.

pyarrow lets the GIL go while it encodes and compresses a table (~0.15 s a block of 1,024 rows of the
benchmark's three skins here, a quarter of the export's main thread): written in this thread, that
overlaps the next block's decoding on the other core. A failure is raised in the export's thread at
its next call (``write``, ``flush``, ``close``).
"""

from __future__ import annotations

import queue
import threading
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pyarrow as pa
    import pyarrow.parquet as pq

__all__ = ["WriterBehind"]


class WriterBehind:
    def __init__(self, writer: pq.ParquetWriter) -> None:
        self.writer = writer
        self._queue: queue.Queue[pa.Table | None] = queue.Queue(maxsize=1)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="parquet", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (table := self._queue.get()) is not None:
            try:
                if self._error is None:
                    self.writer.write_table(table)
            except BaseException as e:  # raised in the export's thread at its next call
                self._error = e
            finally:
                self._queue.task_done()
        self._queue.task_done()

    def _check(self) -> None:
        if self._error is not None:
            raise self._error

    def write(self, table: pa.Table) -> None:
        """Queue ``table`` (its arrays must not change until it is written)."""
        self._check()
        self._queue.put(table)

    def flush(self) -> None:
        """Wait until every table queued is in the file."""
        self._queue.join()
        self._check()

    def close(self, check: bool = True) -> None:
        """Write what is queued, stop the thread and close the file (``check``: raise a failure)."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self.writer.close()
        if check:
            self._check()
