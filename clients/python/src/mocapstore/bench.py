"""``python -m mocapstore.bench URL``: how fast a library reads as training data through
this client — windows/s and frames/s for ``--seconds`` windows at ``--fps`` (shuffled), and
frames/s for whole takes (several to a request) — beside what the server spent on them:
its CPU per window and the source frames it reads per second of its CPU (from its
``/metrics``, when the token may read them), and this process's CPU per window. When the
client's CPU per window is the smaller, the reading is limited by the server's decode, not
by the client."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import httpx

from .client import Client
from .data import Windows
from .types import Take

#: Bytes of answer one request of whole takes asks for at most.
BATCH_BYTES = 4 << 20


def server_counters(c: Client) -> tuple[float, float] | None:
    """The server's CPU seconds and decoded frames so far, or ``None`` if its metrics are
    not readable here (another token's scope, no ``/proc``)."""
    try:
        r = c._http.get("/metrics")
    except httpx.HTTPError:
        return None
    if r.status_code != 200:
        return None
    got: dict[str, float] = {}
    for line in r.text.splitlines():
        name, _, value = line.partition(" ")
        if name in ("process_cpu_seconds_total", "mocapstore_decoded_frames_total"):
            got[name] = float(value)
    if len(got) < 2:
        return None
    return got["process_cpu_seconds_total"], got["mocapstore_decoded_frames_total"]


def measure(c: Client, run: Callable[[], int], items: int, what: str, one: str) -> None:
    """Run ``run`` (it returns the frames it read) over ``items`` of ``one`` and print its
    rates and CPU costs under ``what``."""
    before = server_counters(c)
    wall, cpu = time.perf_counter(), time.process_time()
    frames = run()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"{what}: {items / wall:,.0f} {one}s/s, {frames / wall:,.0f} frames/s ({items} read)")
    print(f"  client CPU: {1e3 * cpu / items:.3f} ms per {one}")
    after = server_counters(c)
    if before is None or after is None:
        print("  server CPU: not known (/metrics is not readable with this token)")
        return
    server_cpu = after[0] - before[0]
    decoded = after[1] - before[1]
    print(f"  server CPU: {1e3 * server_cpu / items:.3f} ms per {one}")
    if server_cpu > 0:
        print(
            f"  server: {decoded / server_cpu:,.0f} source frames per server CPU second "
            f"({decoded:,.0f} read; decoded, or from its cache of decoded chunks)"
        )
    side = "server" if server_cpu >= cpu else "client"
    print(f"  limited by the {side}'s CPU")


def main(argv: list[str] | None = None) -> None:
    """Run the bench with command-line ``argv`` (``sys.argv`` by default)."""
    ap = argparse.ArgumentParser(prog="python -m mocapstore.bench", description=__doc__)
    ap.add_argument("url", nargs="?", default=None, help="the server (default MOCAP_SERVER)")
    ap.add_argument("--library")
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--windows", type=int, default=4000, help="windows to read at most")
    ap.add_argument("--concurrency", type=int, default=4)
    ap.add_argument("--batch-size", type=int, default=64, help="windows per request")
    a = ap.parse_args(argv)

    t = time.perf_counter()
    w = Windows(
        a.url,
        library=a.library,
        seconds=a.seconds,
        fps=a.fps,
        concurrency=a.concurrency,
        batch_size=a.batch_size,
        cache_bytes=0,
    )
    listed = time.perf_counter() - t
    n = min(len(w), a.windows)
    print(f"{len(w)} windows of {a.seconds} s at {a.fps} fps listed in {listed:.2f} s")
    with Client(a.url) as c:

        def windows() -> int:
            return sum(x.shape[0] for x in w.many(w.order(shuffle=True, seed=0)[:n]))

        measure(c, windows, n, "windows, shuffled", "window")
        takes = list(c.takes(library=a.library))

        # Whole takes, several to a request (at most BATCH_BYTES of answer each).
        groups: list[list[tuple[str | Take, int, int]]] = [[]]
        size = 0
        for tk in takes:
            b = tk.frames * len(tk.point_names) * 12
            if groups[-1] and size + b > BATCH_BYTES:
                groups.append([])
                size = 0
            groups[-1].append((tk, 0, tk.frames))
            size += b

        def whole() -> int:
            with ThreadPoolExecutor(a.concurrency) as pool:
                got = pool.map(c.ranges, groups)
                return sum(len(f) for fs in got for f in fs)

        measure(c, whole, len(takes), "whole takes", "take")


if __name__ == "__main__":
    main()
