#!/usr/bin/env python3
"""Fold `perf script` stacks (stdin) into one line per stack (root;…;leaf count, the input
of inferno-flamegraph or flamegraph.pl) written to argv[1], and print the share of samples
in each part of a range read (scripts/profile-reads, docs/PROFILING.md). A sample counts
for the first part, in this order, that one of its frames names."""
import collections, re, sys

PARTS = [
    ("SQLite connection worker threads (sqlx)", r"sqlx_sqlite::connection::worker"),
    ("stamp lookups (service::stamps, batched)", r"service::stamps::"),
    ("stamp lookup (a query of its own)", r"coding_stamp"),
    ("decode or copy of chunks", r"decode_next"),
    ("writing the format", r"write_some|rawf32"),
    ("rest of the handler (plan, headers)", r"takes::frames::"),
    # count_requests: the metrics layer's name before a368536, for profiles of older builds.
    ("middleware (auth, audit, metrics, routing)", r"auth::front|count_requests|metrics::Counting|metrics::RequestCounter"),
    ("socket writes", r"poll_write|poll_flush|writev"),
    ("socket reads, HTTP parsing", r"poll_read|parse_headers|Http1Transaction>::parse"),
    ("scheduler, parking", r"park|Parker|run_task|steal|schedule"),
]

stacks, frames = collections.Counter(), []
def flush():
    if frames:
        stacks[";".join(reversed(frames))] += 1
    frames.clear()
for line in sys.stdin:
    if not line.strip():
        flush()
    elif line[0] in " \t" and not re.match(r"^\s*\S+\s+\d+(/\d+)?\s", line):
        parts = line.strip().split(" ", 1)
        if len(parts) == 2:
            frames.append(re.sub(r"\+0x[0-9a-f]+$", "", parts[1].rsplit(" (", 1)[0]))
flush()
with open(sys.argv[1], "w") as f:
    for s, n in stacks.items():
        f.write(f"{s} {n}\n")
total = sum(stacks.values()) or 1
shares = collections.Counter()
for s, n in stacks.items():
    shares[next((name for name, pat in PARTS if re.search(pat, s)), "other")] += n
print(f"{total} samples of the server")
for name, n in shares.most_common():
    print(f"{100 * n / total:5.1f}%  {name}")
