"""Errors the client raises: each carries what the server said (its HTTP status, its error
``code`` and ``message``), so a script can tell a take the format cannot hold (409) from a
range past the take's end (416) without parsing text."""

from __future__ import annotations


class MocapstoreError(Exception):
    """An error answer of the server, or a failure to reach it."""

    def __init__(self, message: str, *, status: int = 0, code: str = "") -> None:
        super().__init__(message)
        self.status = status
        self.code = code
        self.message = message

    def __str__(self) -> str:
        if self.status:
            return f"{self.status} {self.code}: {self.message}"
        return self.message


class BadRequest(MocapstoreError):
    """400: the request's own fields make no sense (an unknown unit, a point named twice)."""


class Unauthorized(MocapstoreError):
    """401: the server needs a token (``MOCAP_TOKEN``) and got none, or a wrong one."""


class Forbidden(MocapstoreError):
    """403: the token is valid but does not reach this (its scope or libraries)."""


class NotFound(MocapstoreError):
    """404: no such take (or one of a library the token does not reach)."""


class Conflict(MocapstoreError):
    """409: valid, but this take cannot give it (BVH of a marker take, a live take)."""


class OutOfRange(MocapstoreError):
    """416: the range lies outside the take."""


class Unreadable(MocapstoreError):
    """422: the uploaded file is not a take the server can read."""


class Busy(MocapstoreError):
    """503 (or 429): the server is at a limit; the same request may succeed later. The client
    has already retried it as often as it was told to."""

    def __init__(self, message: str, *, status: int, code: str, retry_after: float) -> None:
        super().__init__(message, status=status, code=code)
        self.retry_after = retry_after


class ServerError(MocapstoreError):
    """5xx: the server failed (its log says more)."""


class IncompatibleServer(MocapstoreError):
    """The server speaks another version of the API than this client."""


class ConnectionFailed(MocapstoreError):
    """The server could not be reached, or the connection broke."""


_BY_STATUS: dict[int, type[MocapstoreError]] = {
    400: BadRequest,
    401: Unauthorized,
    403: Forbidden,
    404: NotFound,
    409: Conflict,
    416: OutOfRange,
    422: Unreadable,
}


def from_status(status: int, code: str, message: str) -> MocapstoreError:
    """The exception of an error answer."""
    if status >= 500:
        return ServerError(message, status=status, code=code)
    return _BY_STATUS.get(status, MocapstoreError)(message, status=status, code=code)
