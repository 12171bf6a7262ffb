"""Live streams from a script, through a proxy that refuses every third append with 503 and
loses the answer of every fifth after the server took it: the stored take holds every
frame sent, once, in order."""

from __future__ import annotations

import asyncio
import http.server
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import numpy.typing as npt
import pytest

import mocapstore
from mocapstore import _protocol

HOP = {"transfer-encoding", "connection", "content-length", "keep-alive"}


class Faults:
    def __init__(self) -> None:
        self.appends = 0
        self.refused = 0
        self.lost = 0
        self.lock = threading.Lock()


def proxy(upstream: str, faults: Faults) -> http.server.ThreadingHTTPServer:
    class Handler(http.server.BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def _forward(self, method: str) -> None:
            n = int(self.headers.get("content-length") or 0)
            body = self.rfile.read(n) if n else b""
            append = "/frames" in self.path and method == "POST"
            with faults.lock:
                k = faults.appends = faults.appends + append
            if append and k % 3 == 0:
                faults.refused += 1
                msg = b'{"error":{"code":"busy","message":"try again"}}'
                self.send_response(503)
                for h, v in [("retry-after", "0"), ("x-mocapstore-api", "1")]:
                    self.send_header(h, v)
                self.send_header("content-length", str(len(msg)))
                self.end_headers()
                self.wfile.write(msg)
                return
            headers = {k: v for k, v in self.headers.items() if k.lower() not in HOP | {"host"}}
            r = httpx.request(method, upstream + self.path, content=body, headers=headers)
            if append and k % 5 == 0:
                # The server took the frames; the answer never reaches the client.
                faults.lost += 1
                self.close_connection = True
                return
            self.send_response(r.status_code)
            for h, v in r.headers.items():
                if h.lower() not in HOP:
                    self.send_header(h, v)
            self.send_header("content-length", str(len(r.content)))
            self.end_headers()
            self.wfile.write(r.content)

        def do_GET(self) -> None:
            self._forward("GET")

        def do_POST(self) -> None:
            self._forward("POST")

        def log_message(self, *args: object) -> None:
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    return srv


@pytest.fixture
def flaky(server: str) -> Iterator[tuple[str, Faults]]:
    faults = Faults()
    srv = proxy(server, faults)
    try:
        yield f"http://127.0.0.1:{srv.server_address[1]}", faults
    finally:
        srv.shutdown()


def motion(frames: int, points: int) -> npt.NDArray[np.float32]:
    f = np.arange(frames, dtype=np.float32)[:, None, None]
    p = np.arange(points, dtype=np.float32)[None, :, None]
    xyz = np.array([1.0, 2.0, 3.0], dtype=np.float32)[None, None, :]
    a: npt.NDArray[np.float32] = (10 * f + 100 * p + xyz).astype(np.float32)
    if frames > 7 and points > 1:
        a[7, 1, :] = np.nan
    return a


def test_a_stream_through_refusals_and_lost_answers_keeps_every_frame_once(
    flaky: tuple[str, Faults], server: str
) -> None:
    url, faults = flaky
    sent = motion(300, 4)
    with (
        mocapstore.Client(url, retries=8) as c,
        c.stream(60, ["a", "b", "c", "d"], name="live", library=f"py-{uuid.uuid4().hex[:8]}") as s,
    ):
        for i in range(0, 300, 20):
            s.append(sent[i : i + 20], captured_ms=1_700_000_000_000 + i)
            assert s.frames_received == i + 20
        s.flush()
    assert faults.refused >= 4 and faults.lost >= 2, vars(faults)
    take = s.finish()
    assert take.frames == 300 and take.point_names == ("a", "b", "c", "d")
    with mocapstore.Client(server) as direct:
        got = direct.frames(take.id)
    assert np.array_equal(np.isnan(got.data), np.isnan(sent))
    ok = ~np.isnan(sent)
    assert np.abs(got.data[ok] - sent[ok]).max() <= take.max_bound_mm + 1e-3


def test_an_append_that_would_leave_a_gap_is_refused(server: str) -> None:
    with mocapstore.Client(server) as c:
        s = c.stream(30, 2, name="gap")
        # The take's record from the moment it opens: its id is the stream's.
        assert s.take.id == s.id and s.take.name == "gap"
        s.append(motion(10, 2))
        s.info["frames_received"] = 15  # as if the client had lost count
        with pytest.raises(mocapstore.Conflict, match="send from frame 10"):
            s.append(motion(5, 2))
        s.info["frames_received"] = 10
        s.append(motion(5, 2))
        assert s.finish().frames == 15
        with pytest.raises(ValueError, match=r"\(n, 2, 3\)"):
            s.append(np.zeros((3, 3, 3)))


def test_the_async_client_streams_and_reads_channels(server: str, corpus: Path | None) -> None:
    async def run() -> None:
        async with mocapstore.AsyncClient(server) as c:
            async with c.stream(30, 2, name="async") as s:
                # The record is there from the start, the take live.
                assert s.take.id == s.id and s.take.name == "async"
                await s.append(motion(10, 2))
                await s.append(motion(10, 2)[5:])
                await s.flush()
            assert s.take.frames == 15
            # Awaited, the stream is the caller's to finish.
            s2 = await c.stream(30, 2, name="awaited")
            assert s2.take.id == s2.id
            await s2.append(motion(4, 2))
            assert (await s2.finish()).frames == 4
            if corpus is not None:
                t = await c.ingest(corpus / "bvh" / "cmu" / "131_02.bvh", codec="bvh-lossless")
                ch = await c.channels(t.id, end=5)
                assert ch.values.shape[0] == 5 and ch.skeleton.names[0] == "Hips"

    asyncio.run(run())


def test_after_a_failed_append_the_stream_asks_where_it_is(server: str) -> None:
    with mocapstore.Client(server) as c:
        s = c.stream(30, 2, name="resync")
        s.append(motion(10, 2))
        real = c._exchange
        state = {"fail": True}

        def once(req: _protocol.Request) -> _protocol.Response:
            r = real(req)
            if state["fail"] and "/frames" in req.path:
                state["fail"] = False
                raise mocapstore.ConnectionFailed("the answer was lost")
            return r

        c._retries = 0  # the lost answer is not retried here: the caller sees the failure
        c._exchange = once  # type: ignore[method-assign]
        with pytest.raises(mocapstore.ConnectionFailed):
            s.append(motion(10, 2)[5:])  # stored by the server as 10..15; its answer lost
        # The next append goes after them (numbered from 10 it would be dropped as a repeat).
        s.append(motion(15, 2)[10:])
        assert s.frames_received == 20 and s.finish().frames == 20
