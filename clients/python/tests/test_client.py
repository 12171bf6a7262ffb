"""The client against a real server: every method, answers bit for bit as the server's
own routes give them, gaps as NaN, paging that sees every take once, errors that carry the
server's code, and a clear refusal of a server of another API."""

from __future__ import annotations

import asyncio
import csv
import http.server
import io
import json
import math
import socket
import struct
import tempfile
import threading
import uuid
import zipfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import numpy.typing as npt
import pytest

import mocapstore
from mocapstore import _protocol
from mocapstore.types import nominal_rate

NAMES = ["head", "lhand", "rhand", "lfoot", "rfoot"]


def walker(frames: int, gaps: bool = False) -> npt.NDArray[np.float32]:
    """A small moving figure, in mm; with gaps, the left hand missing for a stretch."""
    t = np.arange(frames, dtype=np.float64)[:, None] / 60.0
    base = np.array([[0, 1700, 0], [-400, 1000, 0], [400, 1000, 0], [-150, 80, 0], [150, 80, 0]])
    k = np.arange(5)
    wave = [300 * np.sin(t + k), 20 * np.cos(2 * t + k), 500 * t + 0 * k]
    a: npt.NDArray[np.float32] = (base[None, :, :] + np.stack(wave, axis=-1)).astype(np.float32)
    if gaps:
        a[20:35, 1, :] = np.nan
    return a


@pytest.fixture
def client(server: str) -> Iterator[mocapstore.Client]:
    with mocapstore.Client(server) as c:
        yield c


def library() -> str:
    return f"py-{uuid.uuid4().hex[:12]}"


def test_ingest_array_and_read_frames_bit_for_bit(client: mocapstore.Client, server: str) -> None:
    lib = library()
    take = client.ingest(
        walker(120, gaps=True),
        name="walk",
        library=lib,
        fps=60,
        point_names=NAMES,
        unit="mm",
        tags=["a", "b"],
    )
    assert (take.name, take.library, take.frames, take.points) == ("walk", lib, 120, 5)
    assert take.point_names == tuple(NAMES)
    assert take.tags == ("a", "b")
    f = client.frames(take.id)
    assert f.shape == (120, 5, 3) and f.data.dtype == np.float32
    assert f.point_names == tuple(NAMES) and f.fps == 60 and f.start == 0
    raw = httpx.get(f"{server}/v1/takes/{take.id}/frames?format=f32").content
    assert f.data.tobytes() == raw, "the array is the f32 answer, bit for bit"
    # Gaps are NaN exactly where the JSON answer says null.
    doc = httpx.get(f"{server}/v1/takes/{take.id}/frames?format=json").json()
    nulls = np.array([[p is None for p in fr] for fr in doc["frames"]])
    assert (np.isnan(f.data).any(axis=2) == nulls).all()
    assert nulls[20:35, 1].all() and nulls.sum() == 15
    # Within the bound of what was stored.
    ok = ~np.isnan(walker(120, gaps=True))
    assert np.abs(f.data[ok] - walker(120, gaps=True)[ok]).max() <= take.max_bound_mm + 1e-3
    # By name, by frame, by seconds.
    assert np.array_equal(f["lhand"], f.data[:, 1, :], equal_nan=True)
    assert len(f[10:20]) == 10 and len(f.between(0.5, 1.0)) == 30
    assert f.between(0.5, 1.0).data[0].tobytes() == f.data[30].tobytes()


def test_ranges_points_and_transforms_name_what_they_hold(
    client: mocapstore.Client, server: str
) -> None:
    take = client.ingest(walker(120), name="w", library=library(), fps=60, point_names=NAMES)
    f = client.frames(take.id, t0=0.5, t1=1.5, points=["rfoot", "head"], fps=30, unit="m", up="z")
    doc = httpx.get(
        f"{server}/v1/takes/{take.id}/frames",
        params={"t0": 0.5, "t1": 1.5, "points": "rfoot,head", "fps": 30, "unit": "m", "up": "z"},
    ).json()
    assert list(f.point_names) == doc["points"] == ["rfoot", "head"]
    assert f.fps == 30 and f.source_fps == 60 and f.start == 30 and f.metres_per_unit == 1.0
    assert np.allclose(f.data, np.array(doc["frames"], dtype=np.float32))
    with pytest.raises(mocapstore.BadRequest) as e:
        client.frames(take.id, unit="furlong")
    assert e.value.code == "bad_request" and "furlong" in e.value.message
    with pytest.raises(mocapstore.OutOfRange):
        client.frames(take.id, start=500, end=600)
    with pytest.raises(mocapstore.NotFound) as nf:
        client.frames("no-such-take")
    assert nf.value.status == 404 and nf.value.code == "not_found"


def test_a_batch_of_ranges_is_each_range_bit_for_bit(
    client: mocapstore.Client, monkeypatch: pytest.MonkeyPatch
) -> None:
    lib = library()
    a = client.ingest(walker(200, gaps=True), name="a", library=lib, fps=60, point_names=NAMES)
    b = client.ingest(walker(90), name="b", library=lib, fps=60, point_names=NAMES)
    parts = [(a.id, 0, 60), (b.id, 10, 70), (a.id, 15, 45), (a.id, 100, 200), (b.id, 0, 90)]
    for kw in [{}, {"fps": 30.0, "unit": "m"}, {"points": ["rhand", "lhand"], "up": "z"}]:
        got = client.ranges(parts, **kw)  # type: ignore[arg-type]
        assert len(got) == len(parts)
        for (id, s, e), f in zip(parts, got, strict=True):
            one = client.frames(id, start=s, end=e, **kw)  # type: ignore[arg-type]
            assert f.data.tobytes() == one.data.tobytes(), (id, s, e, kw)
            assert (f.point_names, f.fps, f.start, f.metres_per_unit) == (
                one.point_names,
                one.fps,
                one.start,
                one.metres_per_unit,
            )
    # More parts than one request may carry: split, in order.
    monkeypatch.setattr(mocapstore.client, "MAX_RANGES", 2)  # three requests
    assert [f.start for f in client.ranges(parts)] == [0, 10, 15, 100, 0]
    monkeypatch.setattr(mocapstore.client, "MAX_RANGES", 256)
    monkeypatch.setattr(mocapstore.client, "MAX_RANGES_CHARS", 100)  # two ids a request
    groups = mocapstore.client._url_sized([(a, s, e) for _, s, e in parts])
    assert [len(g) for g in groups] == [2, 2, 1]
    assert [f.start for f in client.ranges(parts)] == [0, 10, 15, 100, 0]
    # A batch the server cannot answer whole is an error, with the server's code.
    with pytest.raises(mocapstore.NotFound):
        client.ranges([(a.id, 0, 10), (str(uuid.uuid4()), 0, 10)])
    with pytest.raises(mocapstore.MocapstoreError) as refused:
        client.ranges([(a.id, 0, 10), (b.id, 80, 120)])
    assert refused.value.status == 416


def test_a_batch_cut_short_is_an_error() -> None:
    head = "--b\r\ncontent-length: 12\r\nx-take: t\r\n\r\n"
    whole = (head + "x" * 12 + "\r\n--b--\r\n").encode()
    r = _protocol.Response(200, {"content-type": "multipart/mixed; boundary=b"}, whole)
    assert [bytes(body) for _, body in _protocol.multipart(r)] == [b"x" * 12]
    for cut in (len(whole) - 4, len(head) + 5, 0):
        short = _protocol.Response(200, r.headers, whole[:cut])
        with pytest.raises(mocapstore.MocapstoreError, match="cut short"):
            _protocol.multipart(short)


def test_a_skeleton_take_extracts_its_root(client: mocapstore.Client, corpus: Path | None) -> None:
    if corpus is None:
        pytest.skip("no corpus")
    take = client.ingest(corpus / "bvh" / "cmu" / "131_02.bvh", library=library())
    assert take.name == "131_02" and take.skeleton is not None
    f = client.frames(take.id, end=50, root="extract")
    # The path on the floor, and the heading as a point half a metre ahead of it.
    assert f.point_names[-2:] == ("root_motion", "root_motion_forward")
    assert f.shape == (50, take.points + 2, 3)
    ahead = (f.data[:, -1] - f.data[:, -2]) * f.metres_per_unit
    assert np.allclose(np.linalg.norm(ahead, axis=1), 0.5, atol=1e-4)
    still = client.frames(take.id, end=50, root="in-place")
    assert np.allclose(still.data[:, 0, [0, 2]], 0.0, atol=1e-4)


def test_model_outputs_and_analog_come_as_columns_in_their_units(
    client: mocapstore.Client, corpus: Path | None
) -> None:
    if corpus is None:
        pytest.skip("no corpus")
    take = client.ingest(corpus / "c3d" / "c3dio__sample_03__gait-pig.c3d", library=library())
    listed = take.raw["meta"]["outputs"]
    angles = [o["name"] for o in listed if o["kind"] == "angle"]
    assert angles, listed
    # Kept apart from the markers.
    assert not set(angles) & set(take.point_names)
    o = client.outputs(take.id, names=angles[:2], start=10, end=30)
    assert o.labels == tuple(f"{n}.{a}" for n in angles[:2] for a in "xyz")
    assert o.values.shape == (20, 6) and o.start == 10 and len(o) == 20
    assert o.rate == pytest.approx(take.fps) and o.t0 == pytest.approx(10 / take.fps)
    unit = {x["name"]: x["unit"] for x in listed}
    assert o.units == tuple(unit[n] for n in angles[:2] for _ in "xyz")
    # Angles, not millimetres read as metres: a joint angle of tens of degrees.
    assert np.nanmax(np.abs(o.values)) > 1.0
    whole = client.outputs(take.id)
    assert len(whole) == take.frames and len(whole.labels) == 3 * len(listed)
    first = f"{angles[0]}.x"
    assert np.array_equal(o[first], whole[first][10:30], equal_nan=True)
    with pytest.raises(mocapstore.BadRequest, match=angles[0]):
        client.outputs(take.id, names=["NoSuchOutput"])
    with pytest.raises(KeyError, match=first):
        o["nope"]
    a = client.analog(take.id, t0=0.0, t1=0.5)
    assert a.rate > take.fps and len(a) == round(0.5 * a.rate)
    assert a.values.shape == (len(a), len(a.labels)) and len(a.units) == len(a.labels)


def test_takes_pages_see_every_take_once_while_takes_are_added(client: mocapstore.Client) -> None:
    lib = library()
    first = [client.ingest(walker(30), name=f"t{i}", library=lib, fps=60).id for i in range(5)]
    seen: list[str] = []
    added: list[str] = []
    for t in client.takes(library=lib, page_size=2):
        seen.append(t.id)
        if len(added) < 3:
            added.append(client.ingest(walker(30), name="late", library=lib, fps=60).id)
    assert sorted(seen) == sorted(first + added), "every take, once"
    assert len(seen) == len(set(seen))
    assert [t.id for t in client.takes(library=lib)] == first + added, "oldest first"


def test_update_delete_take_and_stats(client: mocapstore.Client) -> None:
    lib = library()
    take = client.ingest(walker(60), name="x", library=lib, fps=60)
    moved = client.update(take.id, name="y", tags=["keep"])
    assert (moved.name, moved.tags) == ("y", ("keep",))
    assert client.take(take.id).name == "y"
    s = client.stats(library=lib)
    assert s["total"]["takes"] == 1
    client.delete(take.id)
    with pytest.raises(mocapstore.NotFound):
        client.take(take.id)
    assert client.stats(library=lib)["total"]["takes"] == 0


def test_export_writes_what_the_server_answers(
    client: mocapstore.Client, server: str, tmp_path: Path
) -> None:
    lib = library()
    take = client.ingest(walker(60), name="e", library=lib, fps=60, point_names=NAMES)
    # Every format the server writes for a marker take, by extension or named.
    for fmt in ["glb", "gltf", "c3d", "trc", "csv", "json", "npy", "f32"]:
        out = client.export(take.id, tmp_path / f"e.{fmt}", fps=30)
        want = httpx.get(f"{server}/v1/takes/{take.id}/frames?format={fmt}&fps=30").content
        assert out.read_bytes() == want and len(want) > 0, fmt
        named = client.export(take.id, tmp_path / f"e-{fmt}.bin", format=fmt, fps=30)
        assert named.read_bytes() == want, fmt
    assert (tmp_path / "e.glb").read_bytes()[:4] == b"glTF"
    with pytest.raises(mocapstore.Conflict):
        client.export(take.id, tmp_path / "e.bvh")
    assert not (tmp_path / "e.bvh").exists()
    z = client.export_library(tmp_path / "lib.zip", library=lib, format="c3d")
    names = zipfile.ZipFile(z).namelist()
    assert names == [f"{lib}/e.c3d", "manifest.csv"]


def test_a_library_comes_out_on_one_rig(
    client: mocapstore.Client, server: str, corpus: Path | None, tmp_path: Path
) -> None:
    if corpus is None:
        pytest.skip("no corpus")
    lib = library()
    cmu = client.ingest(corpus / "bvh" / "cmu" / "01_01.bvh", library=lib)
    client.ingest(corpus / "bvh" / "bandai" / "dataset-1_walk_normal_001.bvh", library=lib)
    one = client.export(cmu.id, tmp_path / "walk.bvh", t1=1.0, skeleton="mixamo", feet="lock")
    want = httpx.get(
        f"{server}/v1/takes/{cmu.id}/frames?format=bvh&t1=1.0&skeleton=mixamo&feet=lock"
    ).content
    assert one.read_bytes() == want and b"ROOT mixamorig:Hips" in want
    z = zipfile.ZipFile(
        client.export_library(tmp_path / "lib.zip", library=lib, format="bvh", skeleton="smpl")
    )
    files = [n for n in z.namelist() if n.endswith(".bvh")]
    assert len(files) == 2
    for n in files:
        assert z.read(n).startswith(b"HIERARCHY\nROOT pelvis"), n
    # Its joints' places in a position format; C3D keeps the lab's markers.
    places = client.export(cmu.id, tmp_path / "walk.npy", t1=1.0, skeleton="smpl")
    assert places.read_bytes()[:6] == b"\x93NUMPY"
    with pytest.raises(mocapstore.BadRequest):
        client.export(cmu.id, tmp_path / "walk.c3d", skeleton="mixamo")
    # A character uploaded as a skeleton: a GLB on it is the character playing the take.
    rig = client.upload_skeleton(corpus / "gltf" / "mixamo_ybot_character.glb")
    assert rig["character"] is True and rig["joints"] == 67
    assert rig["id"] in [s["id"] for s in client.skeletons(layout="uploaded")]
    glb = client.export(cmu.id, tmp_path / "ybot.glb", t1=1.0, skeleton=rig["id"])
    doc = json.loads(glb.read_bytes()[20 : 20 + struct.unpack("<I", glb.read_bytes()[12:16])[0]])
    assert len(doc["skins"]) == 1 and len(doc["meshes"]) == 2 and len(doc["animations"]) == 1


def test_the_async_client_does_the_same(server: str) -> None:
    async def run() -> None:
        async with mocapstore.AsyncClient(server) as c:
            lib = library()
            take = await c.ingest(walker(60), name="a", library=lib, fps=60, point_names=NAMES)
            f = await c.frames(take.id, points=["head"])
            assert f.shape == (60, 1, 3) and f.point_names == ("head",)
            (g,) = await c.ranges([(take.id, 0, 60)], points=["head"])
            assert g.data.tobytes() == f.data.tobytes()
            assert [t.id async for t in c.takes(library=lib)] == [take.id]
            assert (await c.update(take.id, library=lib + "-b")).library == lib + "-b"
            assert (await c.stats(library=lib + "-b"))["total"]["takes"] == 1
            s = await c.motion_stats(ids=[take.id], points=["head"])
            assert s.takes == 1 and s.groups[0].points == ("head",) and s.frames == 60
            assert (await c.motion_stats(library=lib + "-b")).groups[0].points == tuple(NAMES)
            await c.delete(take.id)
            with pytest.raises(mocapstore.NotFound):
                await c.take(take.id)

    asyncio.run(run())


class _NotMocapstore(http.server.BaseHTTPRequestHandler):
    def do_GET(self) -> None:
        body = json.dumps({"items": [], "next_cursor": None}).encode()
        self.send_response(200)
        self.send_header("content-length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: object) -> None:
        pass


def test_a_server_of_another_api_is_refused_clearly() -> None:
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _NotMocapstore)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{srv.server_address[1]}"
        with (
            mocapstore.Client(url) as c,
            pytest.raises(mocapstore.IncompatibleServer, match="x-mocapstore-api"),
        ):
            list(c.takes())
    finally:
        srv.shutdown()
    with pytest.raises(mocapstore.IncompatibleServer, match="speaks API 2"):
        _protocol.check_api({"x-mocapstore-api": "2", "x-mocapstore-version": "9.0.0"})


def test_defaults_come_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MOCAP_SERVER", "http://example.invalid:1/")
    monkeypatch.setenv("MOCAP_TOKEN", "secret")
    with mocapstore.Client() as c:
        assert c.url == "http://example.invalid:1"
        assert c._headers["authorization"] == "Bearer secret"
        with pytest.raises(mocapstore.ConnectionFailed):
            c.take("x")


def test_channels_are_the_bvh_the_server_writes(
    client: mocapstore.Client, server: str, corpus: Path | None, tmp_path: Path
) -> None:
    if corpus is None:
        pytest.skip("no corpus")
    path = corpus / "bvh" / "cmu" / "131_02.bvh"
    take = client.ingest(path, library=library(), codec="bvh-lossless")
    ch = client.channels(take.id, start=10, end=60)
    bvh = httpx.get(f"{server}/v1/takes/{take.id}/frames?format=bvh&start=10&end=60").content
    assert ch.bvh == bvh and ch.to_bvh(tmp_path / "t.bvh").read_bytes() == bvh
    assert ch.start == 10 and len(ch) == 50 and abs(ch.fps - take.fps) < 1e-9
    sk = ch.skeleton
    assert sk.names[0] == "Hips" and sk.parents[0] == -1 and sk.joints[0].rotation_order
    assert ch.values.shape == (50, len(sk.channel_names))
    # bvh-lossless: the values as uploaded (the file's MOTION lines 10..60).
    text = path.read_text().split("MOTION")[1].strip().splitlines()
    uploaded = np.array(" ".join(text[2 + 10 : 2 + 60]).split(), dtype=np.float64)
    assert np.array_equal(ch.values.ravel(), uploaded)
    assert ch.joint("Hips").shape == (50, 6)
    # Positions of the same range: one point per joint and End Site.
    assert client.frames(take.id, start=10, end=60).point_names == sk.names
    with pytest.raises(mocapstore.Conflict):
        client.channels(client.ingest(walker(30), library=library(), fps=30).id)


def test_a_folder_is_ingested_with_its_refusals_reported(
    client: mocapstore.Client, tmp_path: Path
) -> None:
    good = tmp_path / "a.npy"
    np.save(good, walker(30))
    (tmp_path / "sub").mkdir()
    np.save(tmp_path / "sub" / "b.npy", walker(40))
    (tmp_path / "bad.trc").write_text("not a trc\n")
    (tmp_path / "bad.glb").write_bytes(b"glTF\x02\x00\x00\x00")
    (tmp_path / "notes.txt").write_text("ignored")
    # A dataset's label file beside a take, and a hidden file: neither is a take.
    (tmp_path / "a.json").write_text('{"content": 7, "style": 0}')
    (tmp_path / ".b.npy").write_bytes(b"hidden")
    lib = library()
    out = client.ingest_folder(tmp_path, library=lib, fps=60, progress=False)
    assert [o.path.name for o in out] == ["a.npy", "bad.glb", "bad.trc", "b.npy"]
    stored = {o.path.name: o.take for o in out if o.take is not None}
    assert stored["a.npy"].frames == 30 and stored["b.npy"].frames == 40
    for name in ("bad.trc", "bad.glb"):
        bad = next(o for o in out if o.path.name == name)
        assert isinstance(bad.error, mocapstore.Unreadable) and bad.take is None, bad
    assert sorted(t.name for t in client.takes(library=lib)) == ["a", "b"]


def test_labels_from_files_names_and_edits(client: mocapstore.Client, tmp_path: Path) -> None:
    lib = library()
    np.save(tmp_path / "d1_walk_happy_001.npy", walker(30))
    np.save(tmp_path / "d1_run_sad_002.npy", walker(30))
    (tmp_path / "d1_walk_happy_001.json").write_text('{"content": "stroll", "subject": {"id": 4}}')
    out = client.ingest_folder(
        tmp_path,
        library=lib,
        fps=60,
        progress=False,
        labels_from_name="{dataset}_{content}_{style}_{n}",
        labels={"session": "s1"},
    )
    assert all(o.take is not None for o in out), out
    by = {t.name: t for t in client.takes(library=lib)}
    # The label file over the name, the given labels over both; numbers as numbers.
    assert by["d1_walk_happy_001"].labels == {
        "dataset": "d1",
        "content": "stroll",
        "style": "happy",
        "n": 1,
        "subject.id": 4,
        "session": "s1",
    }
    assert by["d1_run_sad_002"].labels["n"] == 2
    assert [t.name for t in client.takes(library=lib, labels={"content": "run"})] == [
        "d1_run_sad_002"
    ]
    assert client.stats(library=lib, labels={"session": "s1"})["total"]["takes"] == 2
    t = client.update(by["d1_run_sad_002"].id, labels={"style": None, "take": 3.0})
    assert t.labels == {"dataset": "d1", "content": "run", "n": 2, "session": "s1", "take": 3}
    one = client.ingest(walker(20), library=lib, fps=60, labels={"content": "bow", "n": 1.5})
    assert one.labels == {"content": "bow", "n": 1.5}
    assert _protocol.name_labels("{a}-{}-x{b}", "p-q-x7") == {"a": "p", "b": 7}
    assert _protocol.name_labels("{a}-{b}", "nothing") is None


def test_frames_as_a_table(client: mocapstore.Client) -> None:
    take = client.ingest(walker(40, gaps=True), library=library(), fps=60, point_names=NAMES)
    f = client.frames(take.id, end=30)
    df = f.to_pandas()
    assert list(df.columns) == ["frame", "time", "point", "x", "y", "z"]
    assert len(df) == 30 * 5
    row = df[(df.frame == 25) & (df.point == "lhand")].iloc[0]
    assert np.isnan(row.x) and abs(row.time - 25 / 60) < 1e-12
    head = df[(df.frame == 3) & (df.point == "head")].iloc[0]
    assert (head.x, head.y, head.z) == tuple(float(v) for v in f["head"][3])


def test_a_folder_with_a_progress_bar(client: mocapstore.Client, tmp_path: Path) -> None:
    np.save(tmp_path / "one.npy", walker(30))
    out = client.ingest_folder(tmp_path, library=library(), fps=60, progress=True)
    assert [o.take is not None for o in out] == [True]


def test_slices_keep_their_place_and_names_must_be_a_list(client: mocapstore.Client) -> None:
    take = client.ingest(walker(120), library=library(), fps=60, point_names=NAMES)
    f = client.frames(take.id, start=30, fps=30)
    assert f.start == 30 and f[5:10].start == 40 and f.between(1.0, 2.0).start == 90
    with pytest.raises(TypeError, match="sliced by frame"):
        f[0]  # type: ignore[call-overload]
    with pytest.raises(TypeError, match=r"points=\['head'\]"):
        client.frames(take.id, points="head")
    with pytest.raises(ValueError, match="fps="):
        client.ingest(walker(10))


def test_a_delete_whose_answer_was_lost_is_done() -> None:
    calls: list[str] = []

    def answer(request: httpx.Request) -> httpx.Response:
        calls.append(request.method)
        h = {"x-mocapstore-api": "1"}
        if len(calls) == 1:
            raise httpx.ReadError("lost", request=request)
        return httpx.Response(
            404, headers=h, json={"error": {"code": "not_found", "message": "gone"}}
        )

    c = mocapstore.Client("http://mock")
    c._http = httpx.Client(base_url="http://mock", transport=httpx.MockTransport(answer))
    c.delete("x")
    assert calls == ["DELETE", "DELETE"]
    with pytest.raises(mocapstore.NotFound):
        c.delete("y")  # a first answer of 404 is still an error


def test_joint_names_with_spaces(client: mocapstore.Client) -> None:
    bvh = (
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Xrotation Yrotation\n  JOINT Left Leg\n  {\n    OFFSET 10 -40 0\n"
        "    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n    {\n"
        "      OFFSET 0 -40 0\n    }\n  }\n}\nMOTION\nFrames: 3\nFrame Time: 0.0333333\n"
        + "".join(f"{f} 90 0 {f} 1 2 3 4 5\n" for f in range(3))
    )
    path = Path(tempfile.mkdtemp()) / "spaces.bvh"
    path.write_text(bvh)
    take = client.ingest(path, library=library(), codec="bvh-lossless")
    ch = client.channels(take.id)
    assert ch.skeleton.names == ("Hips", "Left Leg", "Left Leg_End")
    assert ch.joint("Left Leg").tolist() == [[3.0, 4.0, 5.0]] * 3
    assert client.frames(take.id).point_names == ch.skeleton.names


def test_errors_say_what_to_do(client: mocapstore.Client) -> None:
    t = client.ingest(walker(120), library=library(), fps=60, point_names=NAMES, name="walk one")
    with pytest.raises(ValueError, match=r"has no scheme: write it as http://localhost:8080"):
        mocapstore.Client("localhost:8080")
    # A take's name where its id goes.
    with pytest.raises(mocapstore.NotFound, match=r"names are not ids.*name_prefix='walk one'"):
        client.take("walk one")
    with pytest.raises(mocapstore.NotFound) as e:
        client.take("0192f0c1-7d2e-7a1b-9c3d-1e2f3a4b5c6d")  # an id, just not one stored
    assert "name_prefix" not in str(e.value)
    # A point the take lacks: its points are listed.
    with pytest.raises(mocapstore.BadRequest, match=r"its 5 points are head, lhand, rhand"):
        client.frames(t.id, points=["Hips"])
    # A range given in seconds is refused in seconds.
    with pytest.raises(mocapstore.OutOfRange, match=r"t1=5 s is past .* lasts 2\.000000 s"):
        client.frames(t.id, t0=0, t1=5)
    # Nothing listens: said at once, with what to do.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with (
        mocapstore.Client(f"http://127.0.0.1:{port}") as down,
        pytest.raises(mocapstore.ConnectionFailed, match=r"Is the server running.*MOCAP_SERVER"),
    ):
        down.take(t.id)


def test_a_401_names_the_token() -> None:
    def answer(request: httpx.Request) -> httpx.Response:
        return httpx.Response(
            401,
            headers={"x-mocapstore-api": "1"},
            json={"error": {"code": "unauthorized", "message": "a bearer token is needed"}},
        )

    c = mocapstore.Client("http://mock")
    c._http = httpx.Client(base_url="http://mock", transport=httpx.MockTransport(answer))
    with pytest.raises(
        mocapstore.Unauthorized, match=r"bearer token is needed; the token .*token="
    ):
        list(c.takes())
    with pytest.raises(mocapstore.Unauthorized, match="MOCAP_TOKEN"):
        c.take("x")


def test_a_second_at_30_fps_is_30_frames_for_every_corpus_take(
    client: mocapstore.Client, corpus: Path | None
) -> None:
    """``t0 <= t < t1`` whatever rate the file states: BVH's ``Frame Time: 0.0333333``
    (30.00003 fps) gave 31 frames before."""
    if corpus is None:
        pytest.skip("no corpus")
    lib = library()
    files = sorted(corpus.glob("bvh/**/*.bvh")) + sorted(corpus.glob("c3d/**/*.c3d"))
    assert len(files) > 200
    checked = short = 0
    for f in files:
        try:
            t = client.ingest(f, library=lib, codec="quant")
        except mocapstore.MocapstoreError:
            continue  # the corpus holds files the server refuses on purpose
        if t.frames / t.fps < 1.0 - 1e-6 or t.points == 0:
            short += 1
            continue
        got = client.frames(t.id, t0=0, t1=1, fps=30)
        assert got.data.shape[0] == 30, f"{f.name}: {t.fps} fps gave {got.data.shape[0]}"
        own = client.frames(t.id, t0=0, t1=1)
        want = math.ceil(nominal_rate(t.fps) - 1e-9)
        assert own.data.shape[0] == want, f"{f.name}: {t.fps} fps"
        checked += 1
    assert checked > 200, (checked, short)


def test_an_exported_file_reads_back_by_its_manifest_alone(
    client: mocapstore.Client, server: str, tmp_path: Path
) -> None:
    lib = library()
    take = client.ingest(walker(120), name="m", library=lib, fps=60, point_names=NAMES)
    # root=extract follows the pelvis: this figure has none, so its feet stand in for it.
    r = httpx.patch(
        f"{server}/v1/takes/{take.id}", json={"body": {"roles": {"pelvis": ["lfoot", "rfoot"]}}}
    )
    assert r.status_code == 200, r.text
    for root, names in [(None, NAMES), ("extract", [*NAMES, "root_motion"])]:
        z = client.export_library(
            tmp_path / "lib.zip", library=lib, format="npy", fps=30, unit="m", root=root
        )
        with zipfile.ZipFile(z) as archive:
            rows = list(csv.DictReader(io.StringIO(archive.read("manifest.csv").decode())))
            (row,) = rows
            assert row["skipped"] == "", row
            a = np.load(io.BytesIO(archive.read(row["file"])))
        points = json.loads(row["points"])
        # What reading the file needs, and nothing from the server: its shape, unit, rate.
        assert points[: len(names)] == names, points
        assert a.shape == (int(row["frames"]), len(points), 3)
        assert float(row["metres_per_unit"]) == 1.0 and float(row["fps"]) == 30
        want = client.frames(take.id, fps=30, unit="m", root=root)
        assert np.array_equal(a, want.data, equal_nan=True)


def test_search_finds_motion_and_its_ranges_read_in_one_request(
    client: mocapstore.Client, corpus: Path | None, server: str
) -> None:
    if corpus is None:
        pytest.skip("no corpus")
    lib = library()
    bandai = corpus / "bvh" / "bandai"
    names = ["walk_normal", "walk_happy", "bow_normal", "bow_happy", "dash_normal"]
    takes = {
        n: client.ingest(bandai / f"dataset-1_{n}_001.bvh", library=lib, codec="quant")
        for n in names
    }
    query = takes["walk_normal"]
    found = client.search(query, t0=1.0, t1=3.0, k=3, library=lib)
    assert found.query["take"] == query.id and found.searched["takes"] == 5
    # Another stretch of the same walk may come first; the nearest other take is a walk.
    others = [m for m in found if m.take != query.id]
    assert len(found) == 3 and others[0].name == "dataset-1_walk_happy_001", found
    assert [m.score for m in found] == sorted(m.score for m in found)
    assert all(m.take != query.id or m.t1 <= 1.0 or m.t0 >= 3.0 for m in found)
    # Every range found in one request, each the frames of its seconds.
    frames = client.ranges(found.parts())
    for m, f in zip(found, frames, strict=True):
        assert f.start == m.start and len(f) == m.end - m.start
        assert f.start / f.source_fps == pytest.approx(m.t0, abs=1 / f.source_fps)
    assert [len(f) for f in client.ranges(list(found))] == [len(f) for f in frames]
    # The approximate index (built on the first ask, retried while it is) answers the same.
    approximate = client.search(query, t0=1.0, t1=3.0, k=3, library=lib, index="approximate")
    assert approximate.searched["index"] == "approximate"
    assert approximate.parts() == found.parts()
    assert found.searched["index"] == "exact"
    # A clip file finds its stored take first, at the range asked.
    clip = client.search(bandai / "dataset-1_bow_happy_001.bvh", t0=1.0, t1=3.0, k=1, library=lib)
    assert clip[0].take == takes["bow_happy"].id and (clip[0].t0, clip[0].t1) == (1.0, 3.0)
    with pytest.raises(FileNotFoundError):
        client.search(Path("/no/such/clip.bvh"))
    with pytest.raises(mocapstore.NotFound):
        client.search("no-such-take")

    async def run() -> None:
        async with mocapstore.AsyncClient(server) as c:
            again = await c.search(query.id, t0=1.0, t1=3.0, k=3, library=lib)
            assert again.parts() == found.parts()

    asyncio.run(run())
