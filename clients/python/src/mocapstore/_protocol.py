"""What the client says to the server and how it reads the answers, without any I/O.

Each operation is a generator that yields the [`Request`]s it needs and is sent back their
[`Response`]s, then returns its result. [`mocapstore.Client`] runs them with blocking I/O
and [`mocapstore.AsyncClient`] with ``await``: the two clients share every rule (query
fields, shapes, errors, paging) and differ only in how bytes move.
"""

from __future__ import annotations

import io
import json
import re
from collections.abc import Generator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from . import errors
from ._version import API
from .skeleton import Channels
from .skeleton import parse as parse_bvh
from .types import Columns, Frames, MotionStats, SearchResults, Take

T = TypeVar("T")

Params = list[tuple[str, str]]


@dataclass(frozen=True)
class Request:
    """One HTTP request. ``safe``: repeating it cannot change what the server holds twice
    (reads, deletes), so it may be retried after a broken connection. ``to``: the body is
    written to this file as it arrives (a download), not kept in memory."""

    method: str
    path: str
    params: Params
    content: bytes | None = None
    json: Any = None
    safe: bool = True
    to: Path | None = None


@dataclass(frozen=True)
class Response:
    """One HTTP answer (its body empty if it went to a file)."""

    status: int
    headers: Mapping[str, str]
    content: bytes


Op = Generator[Request, Response, T]

Scalar = str | int | float | bool | None

#: A take's labels as given: key → text or number.
Labels = Mapping[str, str | int | float]


def label_text(v: str | int | float) -> str:
    """A label value as a query writes it (a whole number without a point)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


def label_filters(labels: Labels | None) -> Params:
    """``label.<key>=<value>`` conditions: takes with every one of these labels."""
    return [(f"label.{k}", label_text(v)) for k, v in (labels or {}).items()]


def labels_json(labels: Labels | None) -> str | None:
    """Labels as the ``labels`` ingest field carries them (a JSON object), or ``None``."""
    return json.dumps(dict(labels)) if labels else None


def params(**fields: Scalar | Sequence[str]) -> Params:
    """Query fields, leaving out those that are ``None``; sequences joined by commas."""
    out: Params = []
    for k, v in fields.items():
        if v is None:
            continue
        if isinstance(v, bool):
            out.append((k, "true" if v else "false"))
        elif isinstance(v, (str, int, float)):
            out.append((k, str(v)))
        else:
            out.append((k, ",".join(str(x) for x in v)))
    return out


def names(points: Sequence[str] | None) -> tuple[str, ...] | None:
    """Point names as given (a list, a tuple, an array of strings), refusing one bare
    string, which would otherwise be read as its letters."""
    if points is None:
        return None
    if isinstance(points, str):
        raise TypeError(f"points is a list of names: points=[{points!r}]")
    return tuple(str(p) for p in points)


def check_api(headers: Mapping[str, str]) -> None:
    """Refuse a server that speaks another API than this client (called on the first
    answer that names one, or the first success: a proxy's error page is not the server)."""
    got = headers.get("x-mocapstore-api")
    if got is None:
        raise errors.IncompatibleServer(
            "the server does not say which API it speaks (no x-mocapstore-api header): it "
            f"is not mocapstore, or older than this client (API {API}); upgrade the server"
        )
    if got != API:
        version = headers.get("x-mocapstore-version", "?")
        raise errors.IncompatibleServer(
            f"the server (mocapstore {version}) speaks API {got}, this client API {API}: "
            "install the client of the server's version (pip install mocapstore=="
            f"{version})"
        )


def raise_for(r: Response) -> Response:
    """The answer if it is a success, else the exception of its error."""
    if r.status < 400:
        return r
    code, message = "", ""
    try:
        body = json.loads(r.content)
        code = str(body["error"]["code"])
        message = str(body["error"]["message"])
    except (ValueError, KeyError, TypeError):
        message = r.content[:500].decode("utf-8", "replace") or f"HTTP {r.status}"
    if r.status in (429, 503):
        wait = retry_after(r.headers)
        raise errors.Busy(message, status=r.status, code=code, retry_after=wait)
    raise errors.from_status(r.status, code, message)


_TAKE_PATH = re.compile(r"^/v1/takes/([^/]+)")
_ID = re.compile(r"^[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{12}$")


def hinted(req: Request, r: Response) -> Response:
    """An error answer with what to do added to its message, where the client knows more
    than the server: a 401 names where the token comes from; a 404 of a take asked for by
    something that is not an id (a name) says how to find it by name."""
    hint = ""
    if r.status == 401:
        hint = "the token comes from token= or MOCAP_TOKEN: check that it is set and valid"
    elif r.status == 404:
        m = _TAKE_PATH.match(req.path)
        if m and not _ID.match(m.group(1)):
            name = m.group(1)
            hint = (
                f"{name!r} is not a take id (ids look like 0192f0c1-7d2e-7a1b-9c3d-1e2f3a4b5c6d); "
                f"names are not ids: find it with takes(name_prefix={name!r})"
            )
    if not hint:
        return r
    try:
        body = json.loads(r.content)
        body["error"]["message"] = f"{body['error']['message']}; {hint}"
    except (ValueError, KeyError, TypeError):
        said = r.content[:500].decode("utf-8", "replace") or f"HTTP {r.status}"
        body = {"error": {"code": "", "message": f"{said}; {hint}"}}
    return Response(r.status, r.headers, json.dumps(body).encode())


def retry_after(headers: Mapping[str, str], default: float = 1.0) -> float:
    """Seconds the server asks a client to wait (``Retry-After``, in seconds)."""
    try:
        return max(0.0, float(headers.get("retry-after", default)))
    except ValueError:
        return default


def json_of(r: Response) -> Any:
    return json.loads(raise_for(r).content)


# Operations ------------------------------------------------------------------------------


def take(id: str) -> Op[Take]:
    r = yield Request("GET", f"/v1/takes/{id}", [])
    return Take.from_json(json_of(r))


@dataclass(frozen=True)
class Page:
    takes: list[Take]
    cursor: str | None


def page(filters: Params, cursor: str | None, limit: int) -> Op[Page]:
    """One page of a listing, oldest first (a cursor's order stays valid while takes are
    added: new takes come on later pages)."""
    q = [*filters, ("sort", "created"), ("order", "asc"), ("limit", str(limit))]
    if cursor is not None:
        q.append(("cursor", cursor))
    r = yield Request("GET", "/v1/takes", q)
    v = json_of(r)
    return Page([Take.from_json(t) for t in v["items"]], v.get("next_cursor"))


def update(
    id: str,
    name: str | None,
    library: str | None,
    tags: Sequence[str] | None,
    labels: Mapping[str, str | int | float | None] | None = None,
) -> Op[Take]:
    body: dict[str, Any] = {}
    if labels is not None:
        body["labels"] = dict(labels)
    if name is not None:
        body["name"] = name
    if library is not None:
        body["library"] = library
    if tags is not None:
        body["tags"] = list(tags)
    r = yield Request("PATCH", f"/v1/takes/{id}", [], json=body, safe=False)
    return Take.from_json(json_of(r))


def delete(id: str) -> Op[None]:
    r = yield Request("DELETE", f"/v1/takes/{id}", [])
    raise_for(r)


def upload_skeleton(data: bytes, format: str | None) -> Op[dict[str, Any]]:
    """A rig uploaded on its own (``POST /v1/skeletons``). Safe to repeat: the same file
    is the same skeleton."""
    r = yield Request("POST", "/v1/skeletons", params(format=format), content=data)
    v: dict[str, Any] = json_of(r)
    return v


def skeletons(layout: str | None) -> Op[list[dict[str, Any]]]:
    """The stored skeletons (``GET /v1/skeletons``), newest first."""
    r = yield Request("GET", "/v1/skeletons", params(layout=layout))
    v: list[dict[str, Any]] = json_of(r)["items"]
    return v


def stream_info(id: str) -> Op[dict[str, Any]]:
    """An open stream's state (where its next frame goes: ``frames_received``)."""
    r = yield Request("GET", f"/v1/streams/{id}", [])
    v: dict[str, Any] = json_of(r)
    return v


def stats(filters: Params) -> Op[dict[str, Any]]:
    r = yield Request("GET", "/v1/stats", filters)
    v: dict[str, Any] = json_of(r)
    return v


def motion_stats(query: Params, body: dict[str, Any] | None) -> Op[MotionStats]:
    """The statistics of a selection: by its filters (GET), or of takes named by id (POST)."""
    if body is None:
        r = yield Request("GET", "/v1/motion-stats", query)
    else:
        r = yield Request("POST", "/v1/motion-stats", [], json=body)
    return MotionStats.from_json(json_of(r))


def search(path: str, query: Params, clip: bytes | None) -> Op[SearchResults]:
    """Motion like a query's: a stored take's range (``path`` its ``similar`` route) or a
    clip's (``POST /v1/search`` with the file as the body)."""
    if clip is None:
        r = yield Request("GET", path, query)
    else:
        r = yield Request("POST", "/v1/search", query, content=clip)
    return SearchResults.from_json(json_of(r))


def npy_bytes(array: npt.ArrayLike) -> bytes:
    """An array of positions, ``(frames, points, 3)``, as NPY bytes (float32)."""
    a = np.asarray(array, dtype=np.float32)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"positions are (frames, points, 3), got shape {a.shape}")
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def json_doc(array: npt.ArrayLike, fps: float, point_names: Sequence[str]) -> bytes:
    """Positions with their point names, as the JSON format (NaN → null)."""
    a = np.asarray(array, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[1] != len(point_names):
        raise ValueError(
            f"positions are (frames, {len(point_names)}, 3) for {len(point_names)} names, "
            f"got shape {a.shape}"
        )
    frames = [[None if np.isnan(p).any() else [float(x) for x in p] for p in f] for f in a.tolist()]
    return json.dumps({"fps": fps, "points": list(point_names), "frames": frames}).encode()


def ingest(body: bytes, query: Params) -> Op[Take]:
    """Store a file's bytes; the take as stored."""
    r = yield Request("POST", "/v1/takes", query, content=body, safe=False)
    report = json_of(r)
    stored: Take = yield from take(report["id"])
    return stored


def frame_names(t: Take, points: Sequence[str] | None, root: str | None) -> tuple[str, ...]:
    """The point names of a positions answer: those asked for in their order (else the
    take's), and ``root_motion`` after them when the root's path is extracted (and
    ``root_motion_forward``, its heading, when the answer holds it: see ``f32_answer``)."""
    names = tuple(points) if points is not None else t.point_names
    if root == "extract":
        names = (*names, "root_motion")
    return names


def with_heading(names: tuple[str, ...], width: int) -> tuple[str, ...]:
    """``names`` (of [`frame_names`]) of an answer of ``width`` points: with the extracted
    root's heading, ``root_motion_forward``, when the answer holds it (the body told which
    way it faces: the heading comes as a point ahead of the path)."""
    if len(names) + 1 == width and names[-1:] == ("root_motion",):
        return (*names, "root_motion_forward")
    return names


def header_int(h: Mapping[str, str], name: str) -> int:
    return int(h[name])


def header_float(h: Mapping[str, str], name: str) -> float:
    return float(h[name])


def frames(t: Take, query: Params, points: Sequence[str] | None, root: str | None) -> Op[Frames]:
    """A range of frames as float32 positions, from the raw f32 answer (no copy)."""
    r = yield Request("GET", f"/v1/takes/{t.id}/frames", [*query, ("format", "f32")])
    raise_for(r)
    return f32_answer(r.headers, r.content, frame_names(t, points, root))


def f32_answer(h: Mapping[str, str], body: bytes | memoryview, names: tuple[str, ...]) -> Frames:
    """A raw f32 answer (or a batch's part) with its headers as [`Frames`], a view of the
    bytes (no copy)."""
    n, p = header_int(h, "x-frames"), header_int(h, "x-points")
    data = np.frombuffer(body, dtype="<f4")
    if data.size != n * p * 3:
        raise errors.MocapstoreError(
            f"the answer holds {data.size} values, not {n} frames x {p} points x 3"
        )
    names = with_heading(names, p)
    if len(names) != p:
        raise errors.MocapstoreError(f"the answer has {p} points, the take names {len(names)}")
    return Frames(
        data=data.reshape(n, p, 3),
        point_names=names,
        fps=header_float(h, "x-fps"),
        source_fps=header_float(h, "x-source-fps"),
        start=header_int(h, "x-start-frame"),
        metres_per_unit=header_float(h, "x-metres-per-unit"),
    )


def ranges_spec(parts: Sequence[tuple[str, int, int]]) -> str:
    """The ``ranges`` field of a batch: ``ID:START-END`` for each part, comma-separated."""
    return ",".join(f"{id}:{start}-{end}" for id, start, end in parts)


def multipart(r: Response) -> list[tuple[dict[str, str], memoryview]]:
    """The parts of a ``multipart/mixed`` answer, each its headers (lower-case) and its body
    (a view of the answer, no copy), read by their ``content-length``."""
    ctype = r.headers.get("content-type", "")
    marker = "boundary="
    if not ctype.startswith("multipart/mixed") or marker not in ctype:
        raise errors.MocapstoreError(f"a batch answer is multipart/mixed, not {ctype!r}")
    delim = b"--" + ctype.split(marker, 1)[1].split(";")[0].strip().strip('"').encode()
    body = r.content
    view = memoryview(body)
    out: list[tuple[dict[str, str], memoryview]] = []
    pos = body.find(delim)
    while pos >= 0:
        pos += len(delim)
        if body[pos : pos + 2] == b"--":
            return out
        head_end = body.find(b"\r\n\r\n", pos)
        if head_end < 0:
            break
        headers: dict[str, str] = {}
        for line in body[pos:head_end].decode("latin-1").split("\r\n"):
            if ":" in line:
                k, v = line.split(":", 1)
                headers[k.strip().lower()] = v.strip()
        start = head_end + 4
        n = int(headers.get("content-length", "-1"))
        if n < 0 or start + n > len(body):
            break
        out.append((headers, view[start : start + n]))
        pos = start + n
        if body[pos : pos + 2 + len(delim)] != b"\r\n" + delim:
            break
        pos += 2
    raise errors.MocapstoreError(f"the batch answer was cut short after {len(out)} parts")


def ranges(
    parts: Sequence[tuple[Take, int, int]],
    query: Params,
    points: Sequence[str] | None,
    root: str | None,
) -> Op[list[Frames]]:
    """Several ranges in one request (``GET /v1/ranges``), each as [`frames`] reads it."""
    spec = ranges_spec([(t.id, s, e) for t, s, e in parts])
    r = yield Request("GET", "/v1/ranges", [("ranges", spec), *query, ("format", "f32")])
    raise_for(r)
    got = multipart(r)
    if len(got) != len(parts):
        raise errors.MocapstoreError(f"asked for {len(parts)} ranges, the answer has {len(got)}")
    out: list[Frames] = []
    for (t, _, _), (h, body) in zip(parts, got, strict=True):
        # x-sequence: the header's older name, from servers before x-take.
        named = h.get("x-take", h.get("x-sequence"))
        if named != t.id:
            raise errors.MocapstoreError(f"a part of take {named}, not {t.id}")
        out.append(f32_answer(h, body, frame_names(t, points, root)))
    return out


def download(path: str, query: Params, to: Path) -> Op[Path]:
    """An answer written to a file as it arrives."""
    r = yield Request("GET", path, query, to=to)
    raise_for(r)
    return to


# Live streams ---------------------------------------------------------------------------


def open_stream(body: dict[str, Any]) -> Op[tuple[dict[str, Any], Take]]:
    """Open a live take; its state (``id``, ``frames_received``, …) and its record."""
    r = yield Request("POST", "/v1/streams", [], json=body, safe=False)
    v: dict[str, Any] = json_of(r)
    t: Take = yield from take(v["id"])
    return v, t


def f32_frames(array: npt.ArrayLike, points: int) -> tuple[bytes, int]:
    """Frames ``(frames, points, 3)`` (or ``(frames, points * 3)``) as little-endian f32,
    and how many."""
    a = np.asarray(array, dtype="<f4")
    if a.ndim == 2 and a.shape[1] == points * 3:
        a = a.reshape(a.shape[0], points, 3)
    if a.ndim != 3 or a.shape[1:] != (points, 3):
        raise ValueError(f"frames of this stream are (n, {points}, 3), got shape {a.shape}")
    return np.ascontiguousarray(a).tobytes(), int(a.shape[0])


def append(
    id: str, body: bytes, first: int, flush: bool, captured_ms: int | None
) -> Op[dict[str, Any]]:
    """Append frames numbered from ``first``: the server drops those it has, so the request
    is safe to repeat after a broken connection."""
    q = params(first=first, flush=flush or None, captured_ms=captured_ms)
    r = yield Request("POST", f"/v1/streams/{id}/frames", q, content=body, safe=True)
    v: dict[str, Any] = json_of(r)
    return v


def finish_stream(id: str) -> Op[Take]:
    r = yield Request("POST", f"/v1/streams/{id}/finish", [], json={}, safe=False)
    raise_for(r)
    t: Take = yield from take(id)
    return t


# Skeletons ------------------------------------------------------------------------------


def columns(id: str, what: str, query: Params) -> Op[Columns]:
    """Columns over a range (``what``: ``analog`` or ``outputs``), from the JSON answer."""
    r = yield Request("GET", f"/v1/takes/{id}/{what}", [*query, ("format", "json")])
    raise_for(r)
    doc = json.loads(r.content)
    cols = doc["channels"]
    values = np.array(
        [[np.nan if v is None else v for v in row] for row in doc["values"]], dtype=np.float64
    ).reshape(len(doc["values"]), len(cols))
    return Columns(
        values=values,
        labels=tuple(c["label"] for c in cols),
        units=tuple(c["unit"] for c in cols),
        rate=float(doc["rate"]),
        t0=float(doc["t0"]),
        start=header_int(r.headers, "x-start-frame"),
    )


def channels(id: str, query: Params) -> Op[Channels]:
    """A skeleton take's channel values, from the BVH the server writes."""
    r = yield Request("GET", f"/v1/takes/{id}/frames", [*query, ("format", "bvh")])
    raise_for(r)
    c = parse_bvh(r.content, start=header_int(r.headers, "x-start-frame"))
    return replace(c, fps=header_float(r.headers, "x-fps"))


#: The files a folder's ingest picks up (a ``.json`` only when it holds a take).
TAKE_SUFFIXES = (".bvh", ".c3d", ".trc", ".json", ".npy", ".fbx", ".glb", ".gltf")


def is_take_json(path: Path) -> bool:
    """Whether a JSON file holds a take (``points`` and ``frames``), not labels or settings:
    a dataset's label file beside each take (``{"content": 7, "style": 0}``) is none."""
    try:
        with path.open("rb") as f:
            doc = json.load(f)
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and "points" in doc and "frames" in doc


#: The files beside a take, with its name, that may hold its labels.
LABEL_SUFFIXES = (".json", ".yaml", ".yml")


def sidecar_labels(take: Path) -> dict[str, Any] | None:
    """The labels in the files beside ``take`` with its name (``walk_001.json`` beside
    ``walk_001.bvh``: an object of key → value; YAML when PyYAML is installed), merged;
    ``None`` when there are none. A file that is not such an object raises ``ValueError``
    naming it."""
    out: dict[str, Any] = {}
    found = False
    for suffix in LABEL_SUFFIXES:
        f = take.with_suffix(suffix)
        if f == take or not f.is_file():
            continue
        text = f.read_text()
        if suffix == ".json":
            doc = json.loads(text)
        else:
            try:
                import yaml  # type: ignore[import-untyped]
            except ImportError:
                continue
            doc = yaml.safe_load(text)
        if not isinstance(doc, dict):
            raise ValueError(f"label file {f}: not an object of key → value")
        out.update(doc)
        found = True
    return out if found else None


def name_labels(pattern: str, stem: str) -> dict[str, Any] | None:
    """The labels a file name gives by ``pattern`` (``{dataset}_{content}_{style}_{n}``:
    each field the shortest text up to the literal after it, the last one the rest; ``{}``
    matched, not kept; a value written as a number is one), or ``None`` if it does not
    fit. The server's ``mocapstore ingest --labels-from-name`` reads names the same way."""
    import re

    parts = re.split(r"(\{[^{}]*\})", pattern)
    regex = ""
    keys: list[tuple[str, str | None]] = []
    for i, part in enumerate(parts):
        if part.startswith("{") and part.endswith("}"):
            key = part[1:-1]
            last = all(not q for q in parts[i + 1 :])
            group = f"g{len(keys)}"
            keys.append((group, key if key not in ("", "_") else None))
            regex += f"(?P<{group}>.+)" if last else f"(?P<{group}>.+?)"
        else:
            regex += re.escape(part)
    m = re.fullmatch(regex, stem)
    if m is None:
        return None
    number = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
    out: dict[str, Any] = {}
    for group, key in keys:
        if key is None:
            continue
        v = m.group(group)
        out[key] = float(v) if number.fullmatch(v) else v
        if isinstance(out[key], float) and out[key].is_integer():
            out[key] = int(out[key])
    return out


def folder_labels(
    take: Path, pattern: str | None, sidecars: bool, given: Labels | None
) -> dict[str, Any] | None:
    """A take file's labels as a folder's ingest gives them: its name's by ``pattern``,
    its label files' over them, ``given`` over those; ``None`` when it has none."""
    out: dict[str, Any] = {}
    if pattern is not None:
        out.update(name_labels(pattern, take.stem) or {})
    if sidecars:
        out.update(sidecar_labels(take) or {})
    out.update(given or {})
    return out or None


def take_files(root: Path) -> list[Path]:
    """The take files under ``root`` (or ``root`` itself), sorted; hidden files, and JSON
    that holds no take, left out. A ``root`` that is not there, or holds no take file, is an
    error, not an empty list: a mistyped path must not pass for an empty dataset."""
    if root.is_file():
        return [root]
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such folder or file")
    found = sorted(
        p
        for p in root.rglob("*")
        if p.is_file()
        and p.suffix.lower() in TAKE_SUFFIXES
        and not any(part.startswith(".") for part in p.relative_to(root).parts)
        and (p.suffix.lower() != ".json" or is_take_json(p))
    )
    if not found:
        raise FileNotFoundError(
            f"{root}: holds no take file ({', '.join(TAKE_SUFFIXES)}, hidden files passed over)"
        )
    return found
