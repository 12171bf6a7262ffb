"""The clients: [`Client`] (blocking) and [`AsyncClient`] (``await``). Both run the same
operations of [`mocapstore._protocol`]; this module only moves their bytes, retries what
may be retried and checks the server's API once.

Retries: an answer of 503 or 429 (the server refused at once, before acting, and says when
to come back with ``Retry-After``) is retried for any request, up to ``retries`` times; a
broken connection only for requests that are safe to repeat (reads and deletes), never for
an upload, whose first attempt may have been stored.
"""

from __future__ import annotations

import asyncio
import importlib
import os
import time
from collections.abc import AsyncIterator, Coroutine, Generator, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol, TypeVar

import httpx
import numpy.typing as npt

from . import _protocol as p
from . import errors
from ._version import __version__
from .skeleton import Channels
from .types import Columns, Frames, Match, MotionStats, SearchResults, Take

T = TypeVar("T")

#: Where the client looks when no URL is given (as the command line does).
DEFAULT_URL = "http://127.0.0.1:8080"

#: Seconds between attempts after a broken connection, doubling.
BACKOFF_S = 0.2

#: Ranges one batch request asks for at most (the server's limit, ``limits::MAX_RANGES``).
MAX_RANGES = 256

#: Characters of ``ranges=`` one request carries at most: within the 8 KiB request line a
#: proxy's defaults allow (nginx's ``large_client_header_buffers``), with room for the rest.
MAX_RANGES_CHARS = 6000


def _url_sized(parts: list[tuple[Take, int, int]]) -> list[list[tuple[Take, int, int]]]:
    """``parts`` in requests of at most ``MAX_RANGES`` parts and ``MAX_RANGES_CHARS``
    characters of ``ranges=``, in order."""
    groups: list[list[tuple[Take, int, int]]] = [[]]
    chars = 0
    for part in parts:
        n = len(p.ranges_spec([(part[0].id, part[1], part[2])])) + 1
        if groups[-1] and (len(groups[-1]) >= MAX_RANGES or chars + n > MAX_RANGES_CHARS):
            groups.append([])
            chars = 0
        groups[-1].append(part)
        chars += n
    return groups


@dataclass(frozen=True)
class Ingested:
    """One file of a folder's ingest: the take stored, or why not."""

    path: Path
    take: Take | None
    error: errors.MocapstoreError | None


class _Bar(Protocol):
    def update(self, n: int) -> object: ...
    def close(self) -> object: ...


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        """Close the kept-alive connections."""
        pass


def _progress(total: int, show: bool) -> _Bar:
    """A tqdm bar (a dependency; imported by name, as it ships no type hints), if wanted."""
    if show:
        bar: _Bar = importlib.import_module("tqdm").tqdm(total=total, unit="take")
        return bar
    return _NoBar()


class _Base:
    """What both clients hold and how they turn arguments into operations."""

    def __init__(self, url: str | None, token: str | None, retries: int) -> None:
        self.url = (url or os.environ.get("MOCAP_SERVER") or DEFAULT_URL).rstrip("/")
        if not self.url.startswith(("http://", "https://")):
            said = "url=" if url else "MOCAP_SERVER="
            raise ValueError(
                f"{said}{self.url!r} has no scheme: write it as http://{self.url} (or https://)"
            )
        token = token if token is not None else os.environ.get("MOCAP_TOKEN")
        #: The token requests carry (``token=`` or ``MOCAP_TOKEN``), if any.
        self.token = token
        self._headers = {"user-agent": f"mocapstore-python/{__version__}"}
        if token:
            self._headers["authorization"] = f"Bearer {token.strip()}"
        self._retries = retries
        self._api_checked = False
        #: Whether this client, or the code that made it, has had an answer from the
        #: server: until then a refused connection means no server, and is not retried.
        self.reached = False
        # Point names per take (they never change): a range's names without a second call.
        self._takes: dict[str, Take] = {}

    def _checked(self, req: p.Request, r: p.Response) -> p.Response:
        self.reached = True
        named = "x-mocapstore-api" in r.headers
        if not self._api_checked and (named or r.status < 400):
            p.check_api(r.headers)
            self._api_checked = True
        return p.hinted(req, r)

    def _unreachable(self, e: httpx.TransportError, attempt: int) -> errors.ConnectionFailed:
        """The error of a server that could not be reached, saying what to do."""
        if isinstance(e, httpx.ConnectError) and not self.reached:
            return errors.ConnectionFailed(
                f"{self.url}: {e}. Is the server running? Start one with `mocapstore serve`, "
                "or set MOCAP_SERVER (or url=) to where it runs"
            )
        tried = f" (tried {attempt + 1} times)" if attempt else ""
        return errors.ConnectionFailed(f"{self.url}: {e}{tried}")

    def _retry(self, req: p.Request, e: httpx.TransportError, attempt: int) -> bool:
        """Whether a request that failed to get an answer is sent again. A server never
        reached is not waited for: refused at the first call, it is not running (or not
        there); one that answered before may be restarting."""
        never_reached = isinstance(e, httpx.ConnectError) and not self.reached
        return req.safe and attempt < self._retries and not never_reached

    @staticmethod
    def _retried_delete(req: p.Request, attempt: int, r: p.Response) -> p.Response:
        """A delete retried after its answer was lost finds the take gone: done."""
        if req.method == "DELETE" and attempt > 0 and r.status == 404:
            return p.Response(204, r.headers, b"")
        return r

    def _take_op(self, id: str) -> p.Op[Take]:
        if id in self._takes:
            return self._takes[id]
        t: Take = yield from p.take(id)
        self._takes[id] = t
        return t

    def _frames_op(
        self,
        id: str,
        start: int | None,
        end: int | None,
        t0: float | None,
        t1: float | None,
        points: Sequence[str] | None,
        fps: float | None,
        root: str | None,
        up: str | None,
        unit: str | None,
    ) -> p.Op[Frames]:
        points = p.names(points)
        t = yield from self._take_op(id)
        query = p.params(
            start=start,
            end=end,
            t0=t0,
            t1=t1,
            points=points,
            fps=fps,
            root=root,
            up=up,
            unit=unit,
        )
        f: Frames = yield from p.frames(t, query, points, root)
        return f

    def _ranges_op(
        self,
        parts: Sequence[tuple[str | Take, int, int] | Match],
        points: Sequence[str] | None,
        fps: float | None,
        root: str | None,
        up: str | None,
        unit: str | None,
    ) -> p.Op[list[Frames]]:
        points = p.names(points)
        takes: list[tuple[Take, int, int]] = []
        for part in parts:
            take, start, end = part.part() if isinstance(part, Match) else part
            t = take if isinstance(take, Take) else (yield from self._take_op(take))
            takes.append((t, int(start), int(end)))
        query = p.params(points=points, fps=fps, root=root, up=up, unit=unit)
        out: list[Frames] = []
        for group in _url_sized(takes):
            got = yield from p.ranges(group, query, points, root)
            out.extend(got)
        return out

    @staticmethod
    def _search_op(
        like: str | Take | os.PathLike[str] | bytes,
        t0: float | None,
        t1: float | None,
        k: int,
        per_take: int,
        filters: dict[str, Any],
        labels: p.Labels | None,
    ) -> p.Op[SearchResults]:
        query = [
            *p.params(t0=t0, t1=t1, k=k, per_take=per_take, **filters),
            *p.label_filters(labels),
        ]
        if isinstance(like, Take):
            like = like.id
        if isinstance(like, bytes):
            return p.search("/v1/search", query, like)
        if isinstance(like, str) and not os.path.exists(like):
            return p.search(f"/v1/takes/{like}/similar", query, None)
        path = Path(like)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such clip to search with")
        return p.search("/v1/search", query, path.read_bytes())

    @staticmethod
    def _range_query(
        start: int | None,
        end: int | None,
        t0: float | None,
        t1: float | None,
        fps: float | None,
        root: str | None,
        up: str | None,
        unit: str | None,
    ) -> p.Params:
        return p.params(start=start, end=end, t0=t0, t1=t1, fps=fps, root=root, up=up, unit=unit)

    @staticmethod
    def _columns_query(
        key: str,
        names: Sequence[str] | None,
        start: int | None,
        end: int | None,
        t0: float | None,
        t1: float | None,
    ) -> p.Params:
        """The query of an analog or outputs read: the names asked for under ``key`` and
        the range (columns are not resampled or transformed)."""
        return [*p.params(**{key: names}), *p.params(start=start, end=end, t0=t0, t1=t1)]

    @staticmethod
    def _ingest_body(
        source: str | os.PathLike[str] | npt.ArrayLike,
        fps: float | None,
        point_names: Sequence[str] | None,
    ) -> tuple[bytes, str | None]:
        """The upload's bytes, and the name a file gives the take."""
        if isinstance(source, (str, os.PathLike)):
            path = Path(source)
            return path.read_bytes(), path.stem
        if fps is None:
            raise ValueError("an array of positions needs fps= (it has no clock of its own)")
        if point_names is not None:
            return p.json_doc(source, fps, p.names(point_names) or ()), None
        return p.npy_bytes(source), None

    @staticmethod
    def _ingest_query(name: str | None, **fields: Any) -> p.Params:
        return p.params(name=name, **fields)

    @staticmethod
    def _filters(**fields: Any) -> p.Params:
        return p.params(**fields)

    @staticmethod
    def _motion_stats_op(
        ids: Sequence[str] | None,
        filters: dict[str, Any],
        labels: p.Labels | None,
        points: Sequence[str] | None,
        options: dict[str, Any],
    ) -> p.Op[MotionStats]:
        names = p.names(points)
        if ids is not None:
            if any(v is not None for v in filters.values()) or labels:
                raise ValueError("give ids= or filters (library, tag, labels, ...), not both")
            body: dict[str, Any] = {"ids": list(ids)}
            body.update({k: v for k, v in options.items() if v is not None})
            if names is not None:
                body["points"] = list(names)
            return p.motion_stats([], body)
        query = p.params(**filters, **options, points=names) + p.label_filters(labels)
        return p.motion_stats(query, None)


def _stream_body(
    fps: float,
    points: int | Sequence[str],
    name: str | None,
    library: str | None,
    tags: Sequence[str] | None,
    unit: str | None,
    max_error_mm: float | None,
    mean_error_mm: float | None,
    codec: str | None,
    chunk_seconds: float | None,
    labels: p.Labels | None = None,
) -> dict[str, Any]:
    body: dict[str, Any] = {
        "fps": fps,
        "points": points if isinstance(points, int) else list(points),
    }
    if labels:
        body["labels"] = dict(labels)
    for k, v in [
        ("name", name),
        ("library", library),
        ("tags", list(tags) if tags is not None else None),
        ("unit", unit),
        ("max_error_mm", max_error_mm),
        ("mean_error_mm", mean_error_mm),
        ("codec", codec),
        ("chunk_seconds", chunk_seconds),
    ]:
        if v is not None:
            body[k] = v
    return body


class Stream:
    """A live take being recorded ([`Client.stream`]). Each append is numbered with the
    frame it starts at, so a retry (after a 503, or a connection broken before the answer
    came) neither loses nor repeats a frame. Finished when the ``with`` block ends.

    ``take`` is the take's record from the moment the stream opens (``take.id`` is the id
    to read it by, live or finished); ``finish`` replaces it with the finished take's."""

    def __init__(self, client: Client, info: dict[str, Any], take: Take) -> None:
        self._client = client
        self.info = info
        self.id: str = info["id"]
        self.points: int = int(info["points"])
        self.take: Take = take
        self._finished = False
        # An append failed (its frames may be stored or not): resynchronise before the next.
        self._unsure = False

    @property
    def frames_received(self) -> int:
        """Frames the server holds of this stream: the next append's first frame."""
        return int(self.info["frames_received"])

    def append(
        self, frames: npt.ArrayLike, *, captured_ms: int | None = None, flush: bool = False
    ) -> None:
        """Append frames ``(n, points, 3)``, NaN where missing (``captured_ms``: when the
        last was captured, ms since the epoch, for watchers' delay)."""
        body, _ = p.f32_frames(frames, self.points)
        if self._unsure:
            # An append failed: it may have been stored. Ask where the stream is.
            self.info = self._client._run(p.stream_info(self.id))
            self._unsure = False
        try:
            self.info = self._client._run(
                p.append(self.id, body, self.frames_received, flush, captured_ms)
            )
        except errors.MocapstoreError:
            self._unsure = True
            raise

    def flush(self) -> None:
        """Commit what is pending now (readable by range at once)."""
        self.info = self._client._run(p.append(self.id, b"", self.frames_received, True, None))

    def finish(self) -> Take:
        """Close the stream; the stored take (also ``take`` from now on)."""
        if not self._finished:
            self.take = self._client._run(p.finish_stream(self.id))
            self._finished = True
        return self.take

    def __enter__(self) -> Stream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()


class AsyncStream:
    """[`Stream`] for [`AsyncClient`]: ``async with client.stream(...) as s``."""

    def __init__(self, client: AsyncClient, info: dict[str, Any], take: Take) -> None:
        self._client = client
        self.info = info
        self.id: str = info["id"]
        self.points: int = int(info["points"])
        self.take: Take = take
        self._finished = False
        # An append failed (its frames may be stored or not): resynchronise before the next.
        self._unsure = False

    @property
    def frames_received(self) -> int:
        """Frames the server holds of this stream: the next append's first frame."""
        return int(self.info["frames_received"])

    async def append(
        self, frames: npt.ArrayLike, *, captured_ms: int | None = None, flush: bool = False
    ) -> None:
        """Append frames ``(n, points, 3)`` (see [`Stream.append`])."""
        body, _ = p.f32_frames(frames, self.points)
        if self._unsure:
            self.info = await self._client._run(p.stream_info(self.id))
            self._unsure = False
        try:
            self.info = await self._client._run(
                p.append(self.id, body, self.frames_received, flush, captured_ms)
            )
        except errors.MocapstoreError:
            self._unsure = True
            raise

    async def flush(self) -> None:
        """Commit what is pending now."""
        self.info = await self._client._run(
            p.append(self.id, b"", self.frames_received, True, None)
        )

    async def finish(self) -> Take:
        """Close the stream; the stored take (also ``take`` from now on)."""
        if not self._finished:
            self.take = await self._client._run(p.finish_stream(self.id))
            self._finished = True
        return self.take

    async def __aenter__(self) -> AsyncStream:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.finish()


class _OpeningStream:
    """What [`AsyncClient.stream`] returns: a stream being opened, to ``await`` (the
    stream) or to use as ``async with`` (the stream, finished when the block ends)."""

    def __init__(self, opening: Coroutine[Any, Any, AsyncStream]) -> None:
        self._opening = opening
        self._stream: AsyncStream | None = None

    def __await__(self) -> Generator[Any, None, AsyncStream]:
        return self._opening.__await__()

    async def __aenter__(self) -> AsyncStream:
        self._stream = await self._opening
        return self._stream

    async def __aexit__(self, *exc: object) -> None:
        if self._stream is not None:
            await self._stream.finish()


class Client(_Base):
    """A blocking client of one server. ``url`` and ``token`` default to ``MOCAP_SERVER``
    and ``MOCAP_TOKEN``; connections are kept alive between calls. Use it as a context
    manager, or call ``close()``.

    Not to be shared across processes (``fork``): make one per process."""

    def __init__(
        self,
        url: str | None = None,
        token: str | None = None,
        *,
        timeout: float = 120.0,
        retries: int = 5,
    ) -> None:
        super().__init__(url, token, retries)
        self._http = httpx.Client(base_url=self.url, headers=self._headers, timeout=timeout)

    def close(self) -> None:
        """Close the kept-alive connections."""
        self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # Transport ---------------------------------------------------------------------------

    def _run(self, op: p.Op[T]) -> T:
        try:
            req = next(op)
            while True:
                req = op.send(self._send(req))
        except StopIteration as done:
            result: T = done.value
            return result

    def _send(self, req: p.Request) -> p.Response:
        attempt = 0
        while True:
            try:
                r = self._exchange(req)
            except httpx.TransportError as e:
                if self._retry(req, e, attempt):
                    time.sleep(BACKOFF_S * 2**attempt)
                    attempt += 1
                    continue
                raise self._unreachable(e, attempt) from e
            r = self._checked(req, r)
            if r.status in (429, 503) and attempt < self._retries:
                time.sleep(p.retry_after(r.headers))
                attempt += 1
                continue
            return self._retried_delete(req, attempt, r)

    def _exchange(self, req: p.Request) -> p.Response:
        if req.to is None:
            r = self._http.request(
                req.method,
                req.path,
                params=tuple(req.params),
                content=req.content,
                json=req.json,
            )
            return p.Response(r.status_code, r.headers, r.content)
        with self._http.stream(req.method, req.path, params=tuple(req.params)) as r:
            if r.status_code >= 400:
                return p.Response(r.status_code, r.headers, r.read())
            partial = req.to.with_name(req.to.name + ".partial")
            try:
                with open(partial, "wb") as f:
                    for chunk in r.iter_bytes():
                        f.write(chunk)
            except httpx.TransportError as e:
                # The server cut its answer short (it failed part way): not retried.
                raise errors.ConnectionFailed(f"{req.path}: the answer was cut short: {e}") from e
            finally:
                if partial.exists() and not r.is_stream_consumed:
                    partial.unlink()
            partial.replace(req.to)
            return p.Response(r.status_code, r.headers, b"")

    # Takes -------------------------------------------------------------------------------

    def take(self, id: str) -> Take:
        """A stored take's record."""
        return self._run(p.take(id))

    def takes(
        self,
        *,
        library: str | None = None,
        tag: str | None = None,
        name_prefix: str | None = None,
        codec: str | None = None,
        layout: str | None = None,
        labels: p.Labels | None = None,
        page_size: int = 500,
    ) -> Iterator[Take]:
        """Every take of a selection, oldest first, fetched a page at a time as the iterator
        is read (takes stored meanwhile come at the end; none twice). ``labels``: takes
        with every one of these labels (``{"content": "walk"}``)."""
        filters = self._filters(
            library=library, tag=tag, name_prefix=name_prefix, codec=codec, layout=layout
        ) + p.label_filters(labels)
        cursor: str | None = None
        while True:
            page = self._run(p.page(filters, cursor, page_size))
            yield from page.takes
            if page.cursor is None:
                return
            cursor = page.cursor

    def update(
        self,
        id: str,
        *,
        name: str | None = None,
        library: str | None = None,
        tags: Sequence[str] | None = None,
        labels: Mapping[str, str | int | float | None] | None = None,
    ) -> Take:
        """Rename a take, move it to another library, replace its tags and/or set its
        ``labels`` (a value of ``None`` removes that label; the others are kept)."""
        t = self._run(p.update(id, name, library, tags, labels))
        self._takes.pop(id, None)
        return t

    def delete(self, id: str) -> None:
        """Delete a take (needs an admin token on a server with tokens)."""
        self._run(p.delete(id))
        self._takes.pop(id, None)

    def upload_skeleton(
        self, file: bytes | str | os.PathLike[str], *, format: str | None = None
    ) -> dict[str, Any]:
        """Store a rig to put takes on (``skeleton=`` its ``id``): a glTF character (its
        bind pose; glb and gltf exports on it are the character playing the take), an FBX
        character or a BVH hierarchy. The same file again is the same skeleton."""
        data = file if isinstance(file, bytes) else Path(file).read_bytes()
        return self._run(p.upload_skeleton(data, format))

    def skeletons(self, *, layout: str | None = None) -> list[dict[str, Any]]:
        """The stored skeletons, newest first (``layout="uploaded"``: the rigs uploaded
        on their own)."""
        return self._run(p.skeletons(layout))

    def stats(
        self,
        *,
        library: str | None = None,
        tag: str | None = None,
        codec: str | None = None,
        labels: p.Labels | None = None,
    ) -> dict[str, Any]:
        """Totals over the library, by codec and by library."""
        filters = self._filters(library=library, tag=tag, codec=codec)
        return self._run(p.stats(filters + p.label_filters(labels)))

    def motion_stats(
        self,
        *,
        library: str | None = None,
        tag: str | None = None,
        name_prefix: str | None = None,
        codec: str | None = None,
        layout: str | None = None,
        labels: p.Labels | None = None,
        ids: Sequence[str] | None = None,
        points: Sequence[str] | None = None,
        by: str = "points",
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> MotionStats:
        """Normalisation statistics of a selection's motion, computed by the server in one
        pass over the frames its range answers give with the same ``fps``, ``root``, ``up``
        and ``unit`` (and kept, so asking again reads only takes added or changed): per
        layout, each point's mean and standard deviation of positions and of velocities.
        The takes by filters, or by ``ids`` (a training split); ``points`` the same points
        of every take; ``by="roles"`` the body's 20 roles, as ``Windows(roles=True)``."""
        filters = dict(
            library=library, tag=tag, name_prefix=name_prefix, codec=codec, layout=layout
        )
        options = dict(by=by, fps=fps, root=root, up=up, unit=unit)
        return self._run(self._motion_stats_op(ids, filters, labels, points, options))

    def search(
        self,
        like: str | Take | os.PathLike[str] | bytes,
        *,
        t0: float | None = None,
        t1: float | None = None,
        k: int = 10,
        per_take: int = 1,
        library: str | None = None,
        tag: str | None = None,
        name_prefix: str | None = None,
        labels: p.Labels | None = None,
        skeleton: str | None = None,
        fps: float | None = None,
        min_duration_s: float | None = None,
        max_duration_s: float | None = None,
        index: Literal["auto", "exact", "approximate"] | None = None,
    ) -> SearchResults:
        """The ranges of stored takes whose motion is most like ``like``'s: a stored take
        (its id or record; ``t0``/``t1`` seconds of it, all of it by default), a clip file
        (any format ingest reads) or a clip's bytes. The ``k`` best, at most ``per_take``
        from one take (ranges that do not overlap), never the query's own range, among the
        takes the token reaches that match the filters. ``results.parts()`` are the ranges
        as [`ranges`] reads them in one request. ``index="exact"`` scores every take,
        ``"approximate"`` the takes a graph of the archive's windows proposes (the server
        answers 503, retried, while it first builds it); by default the server goes
        approximate past 40,000 windows (``results.searched["index"]`` says which)."""
        filters = dict(
            library=library,
            tag=tag,
            name_prefix=name_prefix,
            skeleton=skeleton,
            fps=fps,
            min_duration_s=min_duration_s,
            max_duration_s=max_duration_s,
            index=index,
        )
        return self._run(self._search_op(like, t0, t1, k, per_take, filters, labels))

    def ingest(
        self,
        source: str | os.PathLike[str] | npt.ArrayLike,
        *,
        name: str | None = None,
        library: str | None = None,
        tags: Sequence[str] | None = None,
        unit: str | None = None,
        fps: float | None = None,
        max_error_mm: float | None = None,
        mean_error_mm: float | None = None,
        keep: str | None = None,
        codec: str | None = None,
        point_names: Sequence[str] | None = None,
        labels: p.Labels | None = None,
        animation: int | str | None = None,
    ) -> Take:
        """Store a file (BVH, C3D, TRC, JSON, NPY, FBX, glTF/GLB; named after the file unless
        ``name`` is given) or an array of positions ``(frames, points, 3)`` with its ``fps``
        (NaN where missing; with ``point_names`` it keeps them, else points are numbered).
        A file of several animations (FBX stacks, glTF animations) is a take for each, named
        ``name/animation`` and labelled ``animation``; the first is returned (the others:
        ``takes(name_prefix=name + "/")``), unless ``animation`` (its place from 0, or its name)
        picks one. A slow
        upload is not retried: if it times out, look for the take before sending it again
        (it may have been stored)."""
        body, stem = self._ingest_body(source, fps, point_names)
        query = self._ingest_query(
            name if name is not None else stem,
            library=library,
            tags=tags,
            unit=unit,
            fps=fps,
            max_error_mm=max_error_mm,
            mean_error_mm=mean_error_mm,
            keep=keep,
            codec=codec,
            labels=p.labels_json(labels),
            animation=animation,
        )
        return self._run(p.ingest(body, query))

    # Frames ------------------------------------------------------------------------------

    def frames(
        self,
        id: str,
        *,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
        points: Sequence[str] | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> Frames:
        """A range of a take (frames ``start:end`` or seconds ``t0:t1``; all by default) as
        float32 positions ``(frames, points, 3)``, NaN where missing, decoded by the server
        with its transforms: ``fps`` (resampled), ``root`` (``keep``, ``in-place``,
        ``extract``: a ``root_motion`` point), ``up`` (``y``, ``z``), ``unit`` (``mm``,
        ``m``, …)."""
        return self._run(self._frames_op(id, start, end, t0, t1, points, fps, root, up, unit))

    def ranges(
        self,
        parts: Sequence[tuple[str | Take, int, int] | Match],
        *,
        points: Sequence[str] | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> list[Frames]:
        """Several ranges, ``(take, start, end)`` in the takes' own frames (end excluded;
        the take by id, or its record from ``takes()``, which saves a lookup; or a [`Match`]
        a search found), of one take
        or many, each as [`frames`] gives it, in one request per ``MAX_RANGES`` parts (fewer
        when their ids would pass ``MAX_RANGES_CHARS`` of URL): what reading a shuffled batch
        of windows costs once instead of once per window."""
        return self._run(self._ranges_op(parts, points, fps, root, up, unit))

    def export(
        self,
        id: str,
        path: str | os.PathLike[str],
        *,
        format: str | None = None,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
        skeleton: str | None = None,
        feet: str | None = None,
    ) -> Path:
        """A take (or a range of it) written to ``path`` in any format the server writes
        (``glb``, ``gltf``, ``bvh``, ``c3d``, ``trc``, ``csv``, ``json``, ``npy``, ``f32``;
        by default the file's extension), streamed to disk as it is decoded. ``skeleton``
        puts the take on another skeleton (``bvh``, ``glb``, ``gltf``, ``fbx``): a standard
        rig (``"mixamo"``, ``"smpl"``), a stored skeleton's id or ``"take:ID"``; with
        ``feet="lock"`` its feet are held still while the source's stand."""
        to = Path(path)
        query = [
            *p.params(
                format=format or to.suffix.lstrip(".").lower() or None,
                skeleton=skeleton,
                feet=feet,
            ),
            *self._range_query(start, end, t0, t1, fps, root, up, unit),
        ]
        return self._run(p.download(f"/v1/takes/{id}/frames", query, to))

    def channels(
        self,
        id: str,
        *,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> Channels:
        """A skeleton take's channel values ``(frames, channels)`` and its skeleton, over a
        range and with the same transforms as [`Client.frames`] (a 409 ``Conflict`` for a
        take whose codec did not keep its animation)."""
        q = self._range_query(start, end, t0, t1, fps, root, up, unit)
        return self._run(p.channels(id, q))

    def analog(
        self,
        id: str,
        *,
        channels: Sequence[str] | None = None,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
    ) -> Columns:
        """A C3D take's analog channels (``channels``: their labels; all by default) over
        a range, at the analog rate and in their units (force plates in N and N·mm, EMG in
        V; a 400 naming the take's channels for an unknown one)."""
        q = self._columns_query("channels", channels, start, end, t0, t1)
        return self._run(p.columns(id, "analog", q))

    def outputs(
        self,
        id: str,
        *,
        names: Sequence[str] | None = None,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
    ) -> Columns:
        """A C3D take's model outputs (``names``: e.g. ``LHipAngles``; all by default;
        ``take.raw["meta"]["outputs"]`` lists them): joint angles, forces, moments and
        powers a modelling package (Vicon's Plug-in Gait) wrote among the file's points,
        kept apart from the markers, three columns each in the output's own unit (a 400
        naming the take's outputs for an unknown one)."""
        q = self._columns_query("names", names, start, end, t0, t1)
        return self._run(p.columns(id, "outputs", q))

    def ingest_folder(
        self,
        path: str | os.PathLike[str],
        *,
        concurrency: int = 4,
        progress: bool = True,
        labels_from_name: str | None = None,
        sidecar_labels: bool = True,
        **fields: Any,
    ) -> list[Ingested]:
        """Store every take file under ``path`` (.bvh .c3d .trc .npy .fbx .glb .gltf, and
        .json holding a take; label files and hidden files are passed over), ``concurrency``
        at a time, each named after its file, with ``fields`` as [`Client.ingest`] takes
        them; a progress bar (``tqdm``). A file the server refuses is reported in its
        result, not raised; a ``path`` that is not there or holds no take file raises
        ``FileNotFoundError``.

        Each take is labelled as ``mocapstore ingest`` labels it: by its name read with
        ``labels_from_name`` (``"{dataset}_{content}_{style}_{n}"``), then the label file
        beside it with its name (``.json``, or ``.yaml`` with PyYAML), then ``labels``."""
        files = p.take_files(Path(path))
        bar = _progress(len(files), progress)
        given = dict(fields.pop("labels", None) or {})

        def one(f: Path) -> Ingested:
            try:
                labels = p.folder_labels(f, labels_from_name, sidecar_labels, given)
                return Ingested(f, self.ingest(f, labels=labels, **fields), None)
            except errors.MocapstoreError as e:
                return Ingested(f, None, e)
            except ValueError as e:  # a label file that holds no labels
                return Ingested(f, None, errors.MocapstoreError(str(e)))
            finally:
                bar.update(1)

        with ThreadPoolExecutor(max(1, concurrency)) as pool:
            out = list(pool.map(one, files))
        bar.close()
        return out

    # Live streams ------------------------------------------------------------------------

    def stream(
        self,
        fps: float,
        points: int | Sequence[str],
        *,
        name: str | None = None,
        library: str | None = None,
        tags: Sequence[str] | None = None,
        unit: str | None = None,
        max_error_mm: float | None = None,
        mean_error_mm: float | None = None,
        codec: str | None = None,
        chunk_seconds: float | None = None,
        labels: p.Labels | None = None,
    ) -> Stream:
        """Open a live take of ``points`` (a count, or their names) at ``fps``; use it as a
        context manager (finished when the block ends)."""
        body = _stream_body(
            fps,
            points,
            name,
            library,
            tags,
            unit,
            max_error_mm,
            mean_error_mm,
            codec,
            chunk_seconds,
            labels,
        )
        return Stream(self, *self._run(p.open_stream(body)))

    def export_library(
        self,
        path: str | os.PathLike[str],
        *,
        library: str | None = None,
        tag: str | None = None,
        format: str = "json",
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
        labels: p.Labels | None = None,
        skeleton: str | None = None,
        feet: str | None = None,
    ) -> Path:
        """Every take of a selection in one format, as the server's ZIP (a file per take and
        ``manifest.csv``), streamed to ``path``; with ``skeleton`` (and ``feet``) every take
        on one skeleton, as [`Client.export`] puts one."""
        query = p.params(
            library=library,
            tag=tag,
            format=format,
            fps=fps,
            root=root,
            up=up,
            unit=unit,
            skeleton=skeleton,
            feet=feet,
        ) + p.label_filters(labels)
        return self._run(p.download("/v1/export", query, Path(path)))


class AsyncClient(_Base):
    """[`Client`] for ``asyncio``: the same methods, awaited (``takes`` is an async
    iterator); files are read and written off the event loop."""

    def __init__(
        self,
        url: str | None = None,
        token: str | None = None,
        *,
        timeout: float = 120.0,
        retries: int = 5,
    ) -> None:
        super().__init__(url, token, retries)
        self._http = httpx.AsyncClient(base_url=self.url, headers=self._headers, timeout=timeout)

    async def aclose(self) -> None:
        """Close the kept-alive connections."""
        await self._http.aclose()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    async def _run(self, op: p.Op[T]) -> T:
        try:
            req = next(op)
            while True:
                req = op.send(await self._send(req))
        except StopIteration as done:
            result: T = done.value
            return result

    async def _send(self, req: p.Request) -> p.Response:
        attempt = 0
        while True:
            try:
                r = await self._exchange(req)
            except httpx.TransportError as e:
                if self._retry(req, e, attempt):
                    await asyncio.sleep(BACKOFF_S * 2**attempt)
                    attempt += 1
                    continue
                raise self._unreachable(e, attempt) from e
            r = self._checked(req, r)
            if r.status in (429, 503) and attempt < self._retries:
                await asyncio.sleep(p.retry_after(r.headers))
                attempt += 1
                continue
            return self._retried_delete(req, attempt, r)

    async def _exchange(self, req: p.Request) -> p.Response:
        if req.to is None:
            r = await self._http.request(
                req.method,
                req.path,
                params=tuple(req.params),
                content=req.content,
                json=req.json,
            )
            return p.Response(r.status_code, r.headers, r.content)
        async with self._http.stream(req.method, req.path, params=tuple(req.params)) as r:
            if r.status_code >= 400:
                return p.Response(r.status_code, r.headers, await r.aread())
            partial = req.to.with_name(req.to.name + ".partial")
            f = await asyncio.to_thread(open, partial, "wb")
            try:
                async for chunk in r.aiter_bytes():
                    await asyncio.to_thread(f.write, chunk)
            except httpx.TransportError as e:
                raise errors.ConnectionFailed(f"{req.path}: the answer was cut short: {e}") from e
            finally:
                f.close()
                if not r.is_stream_consumed:
                    partial.unlink(missing_ok=True)
            partial.replace(req.to)
            return p.Response(r.status_code, r.headers, b"")

    async def take(self, id: str) -> Take:
        """A stored take's record."""
        return await self._run(p.take(id))

    async def takes(
        self,
        *,
        library: str | None = None,
        tag: str | None = None,
        name_prefix: str | None = None,
        codec: str | None = None,
        layout: str | None = None,
        labels: p.Labels | None = None,
        page_size: int = 500,
    ) -> AsyncIterator[Take]:
        """Every take of a selection, oldest first, a page at a time."""
        filters = self._filters(
            library=library, tag=tag, name_prefix=name_prefix, codec=codec, layout=layout
        ) + p.label_filters(labels)
        cursor: str | None = None
        while True:
            page = await self._run(p.page(filters, cursor, page_size))
            for t in page.takes:
                yield t
            if page.cursor is None:
                return
            cursor = page.cursor

    async def update(
        self,
        id: str,
        *,
        name: str | None = None,
        library: str | None = None,
        tags: Sequence[str] | None = None,
        labels: Mapping[str, str | int | float | None] | None = None,
    ) -> Take:
        """Rename a take, move it to another library, replace its tags and/or set its
        ``labels`` (a value of ``None`` removes that label; the others are kept)."""
        t = await self._run(p.update(id, name, library, tags, labels))
        self._takes.pop(id, None)
        return t

    async def delete(self, id: str) -> None:
        """Delete a take."""
        await self._run(p.delete(id))
        self._takes.pop(id, None)

    async def upload_skeleton(
        self, file: bytes | str | os.PathLike[str], *, format: str | None = None
    ) -> dict[str, Any]:
        """Store a rig to put takes on (see [`Client.upload_skeleton`])."""
        data = file if isinstance(file, bytes) else Path(file).read_bytes()
        return await self._run(p.upload_skeleton(data, format))

    async def skeletons(self, *, layout: str | None = None) -> list[dict[str, Any]]:
        """The stored skeletons, newest first."""
        return await self._run(p.skeletons(layout))

    async def stats(
        self,
        *,
        library: str | None = None,
        tag: str | None = None,
        codec: str | None = None,
        labels: p.Labels | None = None,
    ) -> dict[str, Any]:
        """Totals over the library, by codec and by library."""
        filters = self._filters(library=library, tag=tag, codec=codec)
        return await self._run(p.stats(filters + p.label_filters(labels)))

    async def motion_stats(
        self,
        *,
        library: str | None = None,
        tag: str | None = None,
        name_prefix: str | None = None,
        codec: str | None = None,
        layout: str | None = None,
        labels: p.Labels | None = None,
        ids: Sequence[str] | None = None,
        points: Sequence[str] | None = None,
        by: str = "points",
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> MotionStats:
        """Normalisation statistics of a selection's motion, computed by the server in one
        pass over the frames its range answers give with the same ``fps``, ``root``, ``up``
        and ``unit`` (and kept, so asking again reads only takes added or changed): per
        layout, each point's mean and standard deviation of positions and of velocities.
        The takes by filters, or by ``ids`` (a training split); ``points`` the same points
        of every take; ``by="roles"`` the body's 20 roles, as ``Windows(roles=True)``."""
        filters = dict(
            library=library, tag=tag, name_prefix=name_prefix, codec=codec, layout=layout
        )
        options = dict(by=by, fps=fps, root=root, up=up, unit=unit)
        return await self._run(self._motion_stats_op(ids, filters, labels, points, options))

    async def search(
        self,
        like: str | Take | os.PathLike[str] | bytes,
        *,
        t0: float | None = None,
        t1: float | None = None,
        k: int = 10,
        per_take: int = 1,
        library: str | None = None,
        tag: str | None = None,
        name_prefix: str | None = None,
        labels: p.Labels | None = None,
        skeleton: str | None = None,
        fps: float | None = None,
        min_duration_s: float | None = None,
        max_duration_s: float | None = None,
        index: Literal["auto", "exact", "approximate"] | None = None,
    ) -> SearchResults:
        """The ranges of stored takes whose motion is most like ``like``'s: a stored take
        (its id or record; ``t0``/``t1`` seconds of it, all of it by default), a clip file
        (any format ingest reads) or a clip's bytes. The ``k`` best, at most ``per_take``
        from one take (ranges that do not overlap), never the query's own range, among the
        takes the token reaches that match the filters. ``results.parts()`` are the ranges
        as [`ranges`] reads them in one request. ``index="exact"`` scores every take,
        ``"approximate"`` the takes a graph of the archive's windows proposes (the server
        answers 503, retried, while it first builds it); by default the server goes
        approximate past 40,000 windows (``results.searched["index"]`` says which)."""
        filters = dict(
            library=library,
            tag=tag,
            name_prefix=name_prefix,
            skeleton=skeleton,
            fps=fps,
            min_duration_s=min_duration_s,
            max_duration_s=max_duration_s,
            index=index,
        )
        return await self._run(self._search_op(like, t0, t1, k, per_take, filters, labels))

    async def ingest(
        self,
        source: str | os.PathLike[str] | npt.ArrayLike,
        *,
        name: str | None = None,
        library: str | None = None,
        tags: Sequence[str] | None = None,
        unit: str | None = None,
        fps: float | None = None,
        max_error_mm: float | None = None,
        mean_error_mm: float | None = None,
        keep: str | None = None,
        codec: str | None = None,
        point_names: Sequence[str] | None = None,
        labels: p.Labels | None = None,
        animation: int | str | None = None,
    ) -> Take:
        """Store a file or an array of positions (see [`Client.ingest`])."""
        # Reading a file (or serialising an array) off the event loop.
        body, stem = await asyncio.to_thread(self._ingest_body, source, fps, point_names)
        query = self._ingest_query(
            name if name is not None else stem,
            library=library,
            tags=tags,
            unit=unit,
            fps=fps,
            max_error_mm=max_error_mm,
            mean_error_mm=mean_error_mm,
            keep=keep,
            codec=codec,
            labels=p.labels_json(labels),
            animation=animation,
        )
        return await self._run(p.ingest(body, query))

    async def export(
        self,
        id: str,
        path: str | os.PathLike[str],
        *,
        format: str | None = None,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
        skeleton: str | None = None,
        feet: str | None = None,
    ) -> Path:
        """A take (or a range of it) written to ``path`` (see [`Client.export`])."""
        to = Path(path)
        query = [
            *p.params(
                format=format or to.suffix.lstrip(".").lower() or None,
                skeleton=skeleton,
                feet=feet,
            ),
            *self._range_query(start, end, t0, t1, fps, root, up, unit),
        ]
        return await self._run(p.download(f"/v1/takes/{id}/frames", query, to))

    async def export_library(
        self,
        path: str | os.PathLike[str],
        *,
        library: str | None = None,
        tag: str | None = None,
        format: str = "json",
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
        labels: p.Labels | None = None,
        skeleton: str | None = None,
        feet: str | None = None,
    ) -> Path:
        """Every take of a selection as the server's ZIP (see [`Client.export_library`])."""
        query = p.params(
            library=library,
            tag=tag,
            format=format,
            fps=fps,
            root=root,
            up=up,
            unit=unit,
            skeleton=skeleton,
            feet=feet,
        ) + p.label_filters(labels)
        return await self._run(p.download("/v1/export", query, Path(path)))

    async def frames(
        self,
        id: str,
        *,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
        points: Sequence[str] | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> Frames:
        """A range of a take as float32 positions (see [`Client.frames`])."""
        return await self._run(self._frames_op(id, start, end, t0, t1, points, fps, root, up, unit))

    async def ranges(
        self,
        parts: Sequence[tuple[str | Take, int, int] | Match],
        *,
        points: Sequence[str] | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> list[Frames]:
        """Several ranges in one request (see [`Client.ranges`])."""
        return await self._run(self._ranges_op(parts, points, fps, root, up, unit))

    def stream(
        self,
        fps: float,
        points: int | Sequence[str],
        *,
        name: str | None = None,
        library: str | None = None,
        tags: Sequence[str] | None = None,
        unit: str | None = None,
        max_error_mm: float | None = None,
        mean_error_mm: float | None = None,
        codec: str | None = None,
        chunk_seconds: float | None = None,
        labels: p.Labels | None = None,
    ) -> _OpeningStream:
        """Open a live take (see [`Client.stream`]): ``async with client.stream(...) as s``,
        or ``s = await client.stream(...)`` and ``await s.finish()``."""
        body = _stream_body(
            fps,
            points,
            name,
            library,
            tags,
            unit,
            max_error_mm,
            mean_error_mm,
            codec,
            chunk_seconds,
            labels,
        )

        async def opening() -> AsyncStream:
            return AsyncStream(self, *await self._run(p.open_stream(body)))

        return _OpeningStream(opening())

    async def channels(
        self,
        id: str,
        *,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
        fps: float | None = None,
        root: str | None = None,
        up: str | None = None,
        unit: str | None = None,
    ) -> Channels:
        """A skeleton take's channel values and skeleton (see [`Client.channels`])."""
        q = self._range_query(start, end, t0, t1, fps, root, up, unit)
        return await self._run(p.channels(id, q))

    async def analog(
        self,
        id: str,
        *,
        channels: Sequence[str] | None = None,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
    ) -> Columns:
        """A C3D take's analog channels over a range (see [`Client.analog`])."""
        q = self._columns_query("channels", channels, start, end, t0, t1)
        return await self._run(p.columns(id, "analog", q))

    async def outputs(
        self,
        id: str,
        *,
        names: Sequence[str] | None = None,
        start: int | None = None,
        end: int | None = None,
        t0: float | None = None,
        t1: float | None = None,
    ) -> Columns:
        """A C3D take's model outputs over a range (see [`Client.outputs`])."""
        q = self._columns_query("names", names, start, end, t0, t1)
        return await self._run(p.columns(id, "outputs", q))

    async def ingest_folder(
        self,
        path: str | os.PathLike[str],
        *,
        concurrency: int = 4,
        progress: bool = True,
        labels_from_name: str | None = None,
        sidecar_labels: bool = True,
        **fields: Any,
    ) -> list[Ingested]:
        """Store every take file under ``path`` (see [`Client.ingest_folder`])."""
        files = p.take_files(Path(path))
        bar = _progress(len(files), progress)
        slots = asyncio.Semaphore(max(1, concurrency))
        given = dict(fields.pop("labels", None) or {})

        async def one(f: Path) -> Ingested:
            async with slots:
                try:
                    labels = await asyncio.to_thread(
                        p.folder_labels, f, labels_from_name, sidecar_labels, given
                    )
                    return Ingested(f, await self.ingest(f, labels=labels, **fields), None)
                except errors.MocapstoreError as e:
                    return Ingested(f, None, e)
                except ValueError as e:  # a label file that holds no labels
                    return Ingested(f, None, errors.MocapstoreError(str(e)))
                finally:
                    bar.update(1)

        out = list(await asyncio.gather(*(one(f) for f in files)))
        bar.close()
        return out
