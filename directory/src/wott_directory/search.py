"""JSONPath search (RFC 9535) over the array of all TDs, with python-jsonpath in strict mode.

``JSONPathEnvironment(strict=True)`` is python-jsonpath's RFC 9535 mode (it
passes the JSONPath Compliance Test Suite): no extensions, a leading ``$``, no
surrounding whitespace. Queries are compiled once and kept in an LRU cache.

At 10,000 TDs the library's filter costs ~5 µs per TD, ~55 ms a query on the
reference machine. The common directory query is ``$[?@.a.b == literal]...``
(find by title, by type, by id), so a compiled query of that shape gets a
*pre-filter*: a plain Python test that is false only where the library's
filter is certainly false (the member is missing, or is not equal to the
literal). The library then runs the original query on the surviving TDs. The
answer is the same as on the full array because the filter of the first
segment sees one TD at a time; queries that could see the whole array (any
other ``$`` in the query) get no pre-filter. ``tests/test_search.py`` checks
the equivalence on generated TDs and queries.

Bounded cost (issue 16): any reader may search, so one query must not be able
to freeze the hub or exhaust it.

- ``search()``/``match()`` run on RE2 (``google-re2``), whose matching time is
  linear in the subject; I-Regexp (RFC 9485) is a subset RE2 reads once ``.``
  is spelled ``[^\\n\\r]``. Python's ``re`` backtracks exponentially on
  ``(.|.){24}Q`` and holds the GIL while it does, so no thread would help.
- At compile time a query is refused (400) if it is longer than
  ``max_length``, has more than ``max_segments`` segments in one path (a
  registered TD is at most ``validation.MAX_TD_DEPTH`` deep, so a longer path
  selects nothing, yet ``$`` + 1,300 ``[0]`` overflows the evaluator's stack), or
  nests filters more than ``max_filter_nesting`` deep.
- At run time (on the search thread, never on the IOLoop) every node the
  evaluator creates is counted: past ``max_nodes`` the query is refused (400),
  past its deadline (``time_budget_s`` from when it was asked, waiting
  included) it is abandoned (503 with ``Retry-After``). The evaluating thread
  gives up the GIL every few milliseconds, so other clients are served
  meanwhile; ``tests/adversarial/test_directory_search_budget.py`` measures it.
"""

from __future__ import annotations

import functools
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import re2
from jsonpath import JSONPathEnvironment, JSONPathError, JSONPathMatch
from jsonpath.filter import (
    BooleanLiteral,
    FilterExpression,
    FilterQuery,
    FloatLiteral,
    InfixExpression,
    IntegerLiteral,
    Nil,
    RelativeFilterQuery,
    StringLiteral,
)
from jsonpath.function_extensions import ExpressionType, FilterFunction
from jsonpath.path import JSONPath
from jsonpath.segments import JSONPathChildSegment
from jsonpath.selectors import Filter, IndexSelector, NameSelector

from .errors import BadRequest, DirectoryError
from .threads import WorkThread
from .validation import MAX_TD_DEPTH

__all__ = ["MAX_PENDING_SEARCHES", "CompiledQuery", "QueryTooExpensive", "SearchEngine", "SearchThread",
           "SearchTimedOut"]

_R = TypeVar("_R")

MAX_PENDING_SEARCHES = 16
"""Searches queued for the search thread; past that a search gets 503 at once."""

MAX_FILTER_NESTING = 8
"""Filters inside filters (``$[?@[?@[?...]]]``); real queries use one or two."""
MAX_NODES = 5_000_000
"""Nodes one query may visit: ``$..*`` over 10,000 typical TDs visits about a million."""
TIME_BUDGET_S = 2.0
"""From the request to the last node evaluated, time spent waiting for the search thread included."""


class QueryTooExpensive(BadRequest):
    """A query whose cost is over a budget this directory states (400: change the query)."""


class SearchTimedOut(DirectoryError):
    def __init__(self, budget_s: float) -> None:
        super().__init__(503, f"The query did not finish within the search time budget of {budget_s:g} s "
                              "(time_budget_s); simplify it or try again later", [],
                         {"Retry-After": str(max(1, round(budget_s)))})


class _Budget:
    """What one evaluation may still spend; lives in a thread-local while the query runs."""

    __slots__ = ("budget_s", "deadline", "max_nodes", "nodes")

    def __init__(self, deadline: float, budget_s: float, max_nodes: int) -> None:
        self.deadline = deadline
        self.budget_s = budget_s
        self.max_nodes = max_nodes
        self.nodes = 0

    def check(self) -> None:
        if self.nodes > self.max_nodes:
            raise QueryTooExpensive(f"The query visits more than {self.max_nodes} nodes (max_nodes); "
                                    "narrow it, e.g. with a filter on the array of TDs first")
        if time.monotonic() > self.deadline:
            raise SearchTimedOut(self.budget_s)


_current = threading.local()


class _CountedMatch(JSONPathMatch):
    """python-jsonpath makes one match per node it visits (``new_child``, filter sub-queries):
    counting them here meters every segment, descendant walk and filter without forking the library
    (children are made by ``self.__class__``; roots by ``_MeteredPath``)."""

    __slots__ = ()

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        budget: _Budget | None = getattr(_current, "budget", None)
        if budget is not None:
            budget.nodes += 1
            if not budget.nodes & 1023:
                budget.check()


@functools.lru_cache(maxsize=512)
def _re2(pattern: str) -> Any:
    """The RE2 program of an I-Regexp, or None if RE2 cannot read it (RFC 9535: no match)."""
    options = re2.Options()
    options.log_errors = False
    options.max_mem = 8 << 20
    try:
        return re2.compile(_iregexp_to_re2(pattern), options)
    except (re2.error, UnicodeEncodeError, TypeError, ValueError):
        return None


def _iregexp_to_re2(pattern: str) -> str:
    """I-Regexp's ``.`` excludes ``\\n`` and ``\\r``; RE2's only ``\\n``. Everything else I-Regexp
    has (classes, ``\\p{..}``, quantifiers) RE2 reads the same way."""
    out: list[str] = []
    escaped = in_class = False
    for ch in pattern:
        if escaped:
            out.append(ch)
            escaped = False
        elif ch == "\\":
            out.append(ch)
            escaped = True
        elif ch == "[":
            in_class = True
            out.append(ch)
        elif ch == "]":
            in_class = False
            out.append(ch)
        elif ch == "." and not in_class:
            out.append(r"[^\n\r]")
        else:
            out.append(ch)
    return "".join(out)


class _MeteredPath(JSONPath):
    """A compiled path whose root match is a ``_CountedMatch``: the library's synchronous
    ``finditer`` builds a plain ``JSONPathMatch`` whatever ``env.match_class`` says. The compiled
    tree's paths are given this class in place (``SearchEngine._check_and_meter``)."""

    __slots__ = ()

    def finditer(self, data: Any, *, filter_context: Any = None) -> Any:
        matches: Any = [_CountedMatch(filter_context=filter_context or {}, obj=data, parent=None,
                                      path=self.env.root_token, parts=(), root=data)]
        for segment in self.segments:
            matches = segment.resolve(matches)
        return matches


class _RE2Function(FilterFunction):
    arg_types = [ExpressionType.VALUE, ExpressionType.VALUE]
    return_type = ExpressionType.LOGICAL
    anchored = False

    def __call__(self, value: object, pattern: object) -> bool:
        if not isinstance(value, str) or not isinstance(pattern, str):
            return False
        program = _re2(pattern)
        if program is None:
            return False
        try:
            found = program.fullmatch(value) if self.anchored else program.search(value)
        except (UnicodeEncodeError, re2.error):  # a lone surrogate in the TD's string
            return False
        return found is not None


class _Search(_RE2Function):
    """RFC 9535 ``search()``: the pattern matches a substring."""


class _Match(_RE2Function):
    """RFC 9535 ``match()``: the pattern matches the whole string."""

    anchored = True


class _Environment(JSONPathEnvironment):
    match_class = _CountedMatch

    def setup_function_extensions(self) -> None:
        super().setup_function_extensions()
        self.function_extensions["search"] = _Search()
        self.function_extensions["match"] = _Match()

Guard = Callable[[Any], bool]
_MISSING = object()


@dataclass(frozen=True)
class CompiledQuery:
    text: str
    path: Any
    guard: Guard | None

    def run(self, tds: Sequence[Any]) -> list[Any]:
        if self.guard is not None:
            guard = self.guard
            tds = [td for td in tds if guard(td)]
            if not tds:
                return []
        results: list[Any] = self.path.findall(tds)
        return results

    def run_within(self, tds: Sequence[Any], deadline: float, budget_s: float, max_nodes: int) -> list[Any]:
        """``run`` metered (see the module docstring); call it on the search thread."""
        budget = _Budget(deadline, budget_s, max_nodes)
        budget.check()  # waited past the deadline already
        _current.budget = budget
        try:
            return self.run(tds)
        except RecursionError:  # a TD stored before the depth limit: refused, never a 500
            raise QueryTooExpensive(f"The query nests deeper than this directory evaluates (TDs are at most "
                                    f"{MAX_TD_DEPTH} levels deep, max_depth)") from None
        finally:
            _current.budget = None


class SearchEngine:
    def __init__(self, cache_size: int = 256, max_length: int = 4096, *,
                 max_segments: int = MAX_TD_DEPTH + 1, max_filter_nesting: int = MAX_FILTER_NESTING,
                 max_nodes: int = MAX_NODES, time_budget_s: float = TIME_BUDGET_S) -> None:
        self.env = _Environment(strict=True)
        self.cache: OrderedDict[str, CompiledQuery] = OrderedDict()
        self.cache_size = cache_size
        self.max_length = max_length
        self.max_segments = max_segments
        self.max_filter_nesting = max_filter_nesting
        self.max_nodes = max_nodes
        self.time_budget_s = time_budget_s

    def compile(self, query: str) -> CompiledQuery:
        hit = self.cache.get(query)
        if hit is not None:
            self.cache.move_to_end(query)
            return hit
        if len(query) > self.max_length:
            raise QueryTooExpensive(f"The JSONPath query is longer than {self.max_length} characters "
                                    "(max_query_length)")
        try:
            path = self.env.compile(query)
        except (JSONPathError, RecursionError) as e:
            raise BadRequest(f"Invalid JSONPath (RFC 9535) query: {_first_line(e)}") from None
        if self.pseudo_root_in(path):
            raise BadRequest("Invalid JSONPath (RFC 9535) query: it must start with $")
        self._check_and_meter(path)
        compiled = CompiledQuery(query, path, prefilter(path, query))
        self.cache[query] = compiled
        if len(self.cache) > self.cache_size:
            self.cache.popitem(last=False)
        return compiled

    @staticmethod
    def pseudo_root_in(path: Any) -> bool:
        return bool(getattr(path, "pseudo_root", False))

    def _check_and_meter(self, path: Any) -> None:
        """Segments per path and filter nesting within budget (iterative: the tree may be deep);
        every path in the tree becomes a ``_MeteredPath``."""
        stack: list[tuple[Any, int]] = [(path, 0)]
        while stack:
            node, nesting = stack.pop()
            if isinstance(node, JSONPath):
                if type(node) is JSONPath:
                    node.__class__ = _MeteredPath
                if len(node.segments) > self.max_segments:
                    raise QueryTooExpensive(
                        f"The query has {len(node.segments)} segments in one path; the limit is "
                        f"{self.max_segments} (max_segments: TDs are at most {MAX_TD_DEPTH} levels deep)")
                for segment in node.segments:
                    for selector in segment.selectors:
                        if isinstance(selector, Filter):
                            if nesting + 1 > self.max_filter_nesting:
                                raise QueryTooExpensive(
                                    f"The query nests filters more than {self.max_filter_nesting} deep "
                                    "(max_filter_nesting)")
                            stack.append((selector.expression, nesting + 1))
            elif isinstance(node, FilterQuery):
                stack.append((node.path, nesting))
            elif hasattr(node, "children"):
                stack.extend((child, nesting) for child in node.children())
            else:  # a compound path (union/intersection), not in strict mode, but cheap to cover
                stack.extend((p, nesting) for p in getattr(node, "paths", ()) if p is not None)
                if getattr(node, "path", None) is not None:
                    stack.append((node.path, nesting))

    def search(self, query: str, tds: Sequence[Any]) -> list[Any]:
        """Unmetered, on the caller's thread (tests, in-process use on trusted queries)."""
        return self.compile(query).run(tds)


def _first_line(e: BaseException) -> str:
    return str(e).splitlines()[0] if str(e) else type(e).__name__


def prefilter(path: Any, query: str) -> Guard | None:
    """A test that rejects only TDs the query's first filter certainly rejects, or None."""
    if query.count("$") != 1 or not isinstance(path, JSONPath) or not path.segments:
        return None
    first = path.segments[0]
    if not isinstance(first, JSONPathChildSegment) or len(first.selectors) != 1:
        return None
    selector = first.selectors[0]
    if not isinstance(selector, Filter) or not isinstance(selector.expression, FilterExpression):
        return None
    return _guard(selector.expression.expression)


def _guard(expr: Any) -> Guard | None:
    if not isinstance(expr, InfixExpression):
        return None
    if expr.operator == "&&":
        left, right = _guard(expr.left), _guard(expr.right)
        if left and right:
            both = (left, right)
            return lambda td: both[0](td) and both[1](td)
        return left or right
    if expr.operator == "||":
        left, right = _guard(expr.left), _guard(expr.right)
        if left and right:
            return lambda td: left(td) or right(td)
        return None
    if expr.operator == "==":
        return _equality(expr.left, expr.right) or _equality(expr.right, expr.left)
    return None


def _equality(query: Any, literal: Any) -> Guard | None:
    """``@.a.b[0] == literal``: false when the member is missing or differs (Python's == is looser
    than RFC 9535's, e.g. ``1 == True``, which only lets more TDs through)."""
    if not isinstance(query, RelativeFilterQuery):
        return None
    if isinstance(literal, Nil):
        value = None
    elif isinstance(literal, StringLiteral | IntegerLiteral | FloatLiteral | BooleanLiteral):
        value = literal.value
    else:
        return None
    keys: list[str | int] = []
    for segment in query.path.segments:
        if not isinstance(segment, JSONPathChildSegment) or len(segment.selectors) != 1:
            return None
        sel = segment.selectors[0]
        if isinstance(sel, NameSelector):
            keys.append(sel.name)
        elif isinstance(sel, IndexSelector):
            keys.append(sel.index)
        else:
            return None
    if not keys:
        return None
    return _member_equals(tuple(keys), value)


def _member_equals(keys: tuple[str | int, ...], value: Any) -> Guard:
    def guard(td: Any) -> bool:
        node = td
        for key in keys:
            if isinstance(key, str):
                if not isinstance(node, dict):
                    return False
                node = node.get(key, _MISSING)
                if node is _MISSING:
                    return False
            else:
                if not isinstance(node, list) or not -len(node) <= key < len(node):
                    return False
                node = node[key]
        return bool(node == value)

    return guard


class SearchThread:
    """Searches run on one thread of their own (a long query is compiled there too), each within
    ``engine.time_budget_s`` counted from the request; at most ``MAX_PENDING_SEARCHES`` wait."""

    def __init__(self, engine: SearchEngine) -> None:
        self.engine = engine
        self.thread = WorkThread("wott-directory-search", MAX_PENDING_SEARCHES, "searches",
                                 "MAX_PENDING_SEARCHES")

    async def run(self, query: str, data: Callable[[], Sequence[Any]],
                  finish: Callable[[list[Any]], _R]) -> _R:
        """``finish`` of what ``query`` selects from ``data()`` (400 on a bad query, 400/503 naming
        the budget when it costs too much)."""
        engine = self.engine
        deadline = time.monotonic() + engine.time_budget_s
        tds = data()

        def run() -> _R:  # compiling a long query takes a while too: not on the IOLoop either
            compiled = engine.compile(query)
            return finish(compiled.run_within(tds, deadline, engine.time_budget_s, engine.max_nodes))

        try:
            return await self.thread.run(run, timeout_s=engine.time_budget_s + 1.0)
        except TimeoutError:  # the thread checks its deadline itself; this only bounds the answer
            raise SearchTimedOut(engine.time_budget_s) from None

    def shutdown(self) -> None:
        self.thread.shutdown()
