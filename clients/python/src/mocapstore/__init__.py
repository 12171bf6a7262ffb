"""mocapstore's Python client: takes as numpy arrays in one call.

>>> import mocapstore
>>> with mocapstore.Client() as c:                  # MOCAP_SERVER, MOCAP_TOKEN
...     take = c.ingest("walk.bvh", library="walks")
...     f = c.frames(take.id, t0=1.0, t1=3.0, fps=30, unit="m")
...     f.data.shape                                # (60, points, 3), NaN where missing
"""

from ._version import API, __version__
from .client import AsyncClient, AsyncStream, Client, Ingested, Stream
from .errors import (
    BadRequest,
    Busy,
    Conflict,
    ConnectionFailed,
    Forbidden,
    IncompatibleServer,
    MocapstoreError,
    NotFound,
    OutOfRange,
    ServerError,
    Unauthorized,
    Unreadable,
)
from .skeleton import Channels, Joint, Skeleton
from .types import Columns, Frames, Match, MotionStats, SearchResults, StatsGroup, Take

__all__ = [
    "API",
    "AsyncClient",
    "AsyncStream",
    "BadRequest",
    "Busy",
    "Channels",
    "Client",
    "Columns",
    "Conflict",
    "ConnectionFailed",
    "Forbidden",
    "Frames",
    "IncompatibleServer",
    "Ingested",
    "Joint",
    "Match",
    "MocapstoreError",
    "MotionStats",
    "NotFound",
    "OutOfRange",
    "SearchResults",
    "ServerError",
    "Skeleton",
    "StatsGroup",
    "Stream",
    "Take",
    "Unauthorized",
    "Unreadable",
    "__version__",
]
