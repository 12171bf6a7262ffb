"""``python -m mocapstore.bench URL``: how fast a library reads as training data through
this client — windows/s and frames/s for ``--seconds`` windows at ``--fps``, and frames/s
for whole takes — to set beside the server's own decode figure (``mocapstore bench``)."""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ThreadPoolExecutor

from .client import Client
from .data import Windows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m mocapstore.bench", description=__doc__)
    ap.add_argument("url", nargs="?", default=None, help="the server (default MOCAP_SERVER)")
    ap.add_argument("--library")
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--windows", type=int, default=2000, help="windows to read at most")
    ap.add_argument("--concurrency", type=int, default=8)
    a = ap.parse_args(argv)

    t = time.perf_counter()
    w = Windows(
        a.url,
        library=a.library,
        seconds=a.seconds,
        fps=a.fps,
        concurrency=a.concurrency,
        cache_bytes=0,
    )
    listed = time.perf_counter() - t
    n = min(len(w), a.windows)
    t = time.perf_counter()
    frames = 0
    with ThreadPoolExecutor(a.concurrency) as pool:
        for x in pool.map(w.__getitem__, w.order(shuffle=True, seed=0)[:n]):
            frames += x.shape[0]
    dt = time.perf_counter() - t
    print(f"{len(w)} windows of {a.seconds} s at {a.fps} fps listed in {listed:.2f} s")
    print(f"windows: {n / dt:,.0f} windows/s, {frames / dt:,.0f} frames/s ({n} read, shuffled)")

    with Client(a.url) as c:
        takes = list(c.takes(library=a.library))
        t = time.perf_counter()
        with ThreadPoolExecutor(a.concurrency) as pool:
            got = sum(len(f) for f in pool.map(lambda tk: c.frames(tk.id), takes))
        dt = time.perf_counter() - t
    print(f"whole takes: {got / dt:,.0f} frames/s ({len(takes)} takes, {got} frames)")


if __name__ == "__main__":
    main()
