"""Errors the directory answers with, as RFC 7807 Problem Details.

Operations raise these; the HTTP layer turns any of them into an
``application/problem+json`` body, so the store and the handlers never build
error responses by hand.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from http import HTTPStatus
from typing import Any

__all__ = [
    "PROBLEM_CONTENT_TYPE", "BadRequest", "DirectoryError", "Forbidden", "NotFound", "PayloadTooLarge",
    "Unauthorized", "UnsupportedMediaType", "ValidationFailed", "problem_body",
]

PROBLEM_CONTENT_TYPE = "application/problem+json"


@dataclass
class DirectoryError(Exception):
    status: int = 500
    detail: str = ""
    validation_errors: list[dict[str, str]] = field(default_factory=list)
    headers: dict[str, str] = field(default_factory=dict)

    def __str__(self) -> str:
        return f"{self.status} {self.detail}"

    @property
    def title(self) -> str:
        try:
            return HTTPStatus(self.status).phrase
        except ValueError:
            return "Error"

    def problem(self, instance: str | None = None) -> dict[str, Any]:
        body: dict[str, Any] = {"type": "about:blank", "title": self.title, "status": self.status}
        if self.detail:
            body["detail"] = self.detail
        if instance:
            body["instance"] = instance
        if self.validation_errors:
            body["validationErrors"] = self.validation_errors
        return body


def problem_body(problem: dict[str, Any]) -> bytes:
    """UTF-8 JSON, non-ASCII kept as is (the spec wants UTF-8 problem details, not escapes only)."""
    return json.dumps(problem, ensure_ascii=False).encode("utf-8")


class BadRequest(DirectoryError):
    def __init__(self, detail: str, validation_errors: list[dict[str, str]] | None = None) -> None:
        super().__init__(400, detail, validation_errors or [])


class ValidationFailed(BadRequest):
    def __init__(self, validation_errors: list[dict[str, str]],
                 detail: str = "The TD did not pass validation") -> None:
        super().__init__(detail, validation_errors)


class Unauthorized(DirectoryError):
    def __init__(self, detail: str, error: str | None = None) -> None:
        challenge = 'Bearer realm="wott-directory"' + (f', error="{error}"' if error else "")
        super().__init__(401, detail, [], {"WWW-Authenticate": challenge})


class Forbidden(DirectoryError):
    def __init__(self, detail: str) -> None:
        super().__init__(403, detail)


class NotFound(DirectoryError):
    def __init__(self, detail: str) -> None:
        super().__init__(404, detail)


class PayloadTooLarge(DirectoryError):
    def __init__(self, limit: int) -> None:
        super().__init__(413, f"The request body exceeds the limit of {limit} bytes")


class UnsupportedMediaType(DirectoryError):
    def __init__(self, detail: str) -> None:
        super().__init__(415, detail)
