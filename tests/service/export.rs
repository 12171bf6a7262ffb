//! A library as files people open (issue 35): `GET /v1/export` streams every take of a
//! selection as one ZIP through the one read path, without holding the archive; `mocapstore
//! export --format` writes the same files and manifest into a folder, and resumes.

use crate::common;

use std::collections::{BTreeMap, HashSet};
use std::io::{Cursor, Read};
use std::path::Path;

use mocapstore::corpus;
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use mocapstore::service::export::{self, COLUMNS, MANIFEST, ZIP_BYTES};

/// `s` as a query string value.
fn urlencode(s: &str) -> String {
    s.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' => {
                char::from(b).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// A manifest's lines as column → value maps (RFC 4180: quoted fields may hold commas).
fn manifest_rows(text: &str) -> Vec<BTreeMap<String, String>> {
    let mut rows = Vec::new();
    let mut fields = Vec::new();
    let mut field = String::new();
    let mut quoted = false;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                field.push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field)),
            ('\r', false) => {}
            ('\n', false) => {
                fields.push(std::mem::take(&mut field));
                rows.push(std::mem::take(&mut fields));
            }
            (c, _) => field.push(c),
        }
    }
    let head = rows.remove(0);
    assert_eq!(head, COLUMNS, "the manifest's columns");
    rows.into_iter()
        .map(|r| {
            assert_eq!(r.len(), COLUMNS.len(), "{r:?}");
            head.iter().cloned().zip(r).collect()
        })
        .collect()
}

/// A ZIP's entries, in order, read (and CRC-checked) by the zip crate's reader.
fn entries(zip: &[u8]) -> Vec<(String, Vec<u8>)> {
    let mut a = zip::ZipArchive::new(Cursor::new(zip)).unwrap();
    (0..a.len())
        .map(|i| {
            let mut f = a.by_index(i).unwrap();
            let mut bytes = Vec::new();
            f.read_to_end(&mut bytes).unwrap();
            (f.name().unwrap().to_string(), bytes)
        })
        .collect()
}

fn blake3_hex(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// Every corpus BVH stored in one library (and one of them twice, under the same name): the
/// library as GLB at 30 fps is one ZIP of a file per take that Python's `zipfile` reads,
/// each file the very answer `GET …/frames` gives, the manifest lists every take with its
/// file's size and digest, and the export holds no more than its largest take's answer.
#[tokio::test(flavor = "multi_thread")]
async fn library_export_streams_the_corpus_bvh_as_one_zip() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let mut files: Vec<_> = ["cmu", "bandai", "misc"]
        .iter()
        .flat_map(|d| std::fs::read_dir(root.join("bvh").join(d)).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    files.sort();
    files.push(files[0].clone());
    let mut ids = Vec::new();
    for batch in files.chunks(4) {
        let mut set = tokio::task::JoinSet::new();
        for (i, f) in batch.iter().enumerate() {
            let (client, base, f) = (srv.client.clone(), srv.base.clone(), f.clone());
            set.spawn(async move {
                let name = f.file_stem().unwrap().to_string_lossy().into_owned();
                let r = client
                    .post(format!("{base}/v1/takes?name={name}&library=corpus"))
                    .body(std::fs::read(&f).unwrap())
                    .send()
                    .await
                    .unwrap();
                assert_eq!(r.status(), 201, "{}", f.display());
                let v: serde_json::Value = r.json().await.unwrap();
                (i, v["id"].as_str().unwrap().to_string())
            });
        }
        let mut got: Vec<_> = set.join_all().await;
        got.sort();
        ids.extend(got.into_iter().map(|(_, id)| id));
    }
    // A marker take in another library stays out of the selection.
    let (status, _) = srv
        .post(
            "name=walk&library=markers",
            formats::write(&walker(120, 6, 60.0, 1, 0.1), Format::Json).unwrap(),
        )
        .await;
    assert_eq!(status, 201);

    let (status, headers, zip) = srv.get("/v1/export?library=corpus&format=glb&fps=30").await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&zip));
    assert_eq!(headers["content-type"], "application/zip");
    assert_eq!(headers["x-takes"], ids.len().to_string().as_str());
    assert!(headers["content-disposition"]
        .to_str()
        .unwrap()
        .contains("corpus-glb.zip"));
    let peak_export = common::gauge(&srv, "mocapstore_answer_bytes_held_peak").await;
    common::answers_released(&srv).await;

    let all = entries(&zip);
    let (last, manifest) = all.last().unwrap();
    assert_eq!(last, MANIFEST, "the manifest comes last");
    let manifest = String::from_utf8(manifest.clone()).unwrap();
    let rows = manifest_rows(&manifest);
    assert_eq!(rows.len(), ids.len());
    assert_eq!(all.len(), ids.len() + 1);
    let listed: HashSet<&str> = rows.iter().map(|r| r["id"].as_str()).collect();
    assert_eq!(listed, ids.iter().map(String::as_str).collect());
    // Named from take names, made unique.
    let first = files[0].file_stem().unwrap().to_string_lossy().into_owned();
    assert!(rows
        .iter()
        .any(|r| r["file"] == format!("corpus/{first}.glb")));
    assert_eq!(
        rows.last().unwrap()["file"],
        format!("corpus/{first}_2.glb")
    );
    for (row, (name, bytes)) in rows.iter().zip(&all) {
        assert_eq!(&row["file"], name);
        assert_eq!(row["skipped"], "", "{row:?}");
        assert_eq!(row["bytes"], bytes.len().to_string(), "{name}");
        assert_eq!(row["blake3"], blake3_hex(bytes), "{name}");
        assert_eq!(row["fps"], "30");
        assert_eq!(row["library"], "corpus");
        // The file's unit; its points are named in the file itself (glTF nodes), so the
        // manifest names none (an NPY's are named: the Python client's test).
        assert!(
            row["metres_per_unit"].parse::<f64>().unwrap() > 0.0,
            "{row:?}"
        );
        assert_eq!(row["points"], "", "{row:?}");
        assert!(row["max_error_mm"].parse::<f64>().unwrap() <= 1.0 + 1e-9);
    }
    // The one read path: a file in the ZIP is the range answer, byte for byte.
    for (row, (_, bytes)) in rows.iter().zip(&all).step_by(12) {
        let (status, _, body) = srv
            .get(&format!("/v1/takes/{}/frames?format=glb&fps=30", row["id"]))
            .await;
        assert_eq!(status, 200);
        assert!(body == *bytes, "{}", row["file"]);
    }
    // An independent reader: every entry's CRC checks out in Python's zipfile.
    if let Some(python) = common::python() {
        let path = std::env::temp_dir().join(format!("mocapstore-{}.zip", uuid::Uuid::now_v7()));
        std::fs::write(&path, &zip).unwrap();
        let out = std::process::Command::new(python)
            .args([
                "-c",
                "import sys, zipfile; z = zipfile.ZipFile(sys.argv[1]); \
                 assert z.testzip() is None; print(len(z.namelist()))",
            ])
            .arg(&path)
            .output()
            .unwrap();
        let _ = std::fs::remove_file(&path);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            String::from_utf8_lossy(&out.stdout).trim(),
            (ids.len() + 1).to_string()
        );
    }
    srv.stop().await;

    // What the export held against what one take's answer holds: a fresh server over the
    // same store reads every take alone; the export held at most the largest of those, the
    // ZIP's own pieces and its manifest — not the archive, nor anything per take.
    let mut t = t;
    t.reopen().await;
    let alone = common::start(t.store.clone(), 64 << 20).await;
    for id in &ids {
        let (status, _, _) = alone
            .get(&format!("/v1/takes/{id}/frames?format=glb&fps=30"))
            .await;
        assert_eq!(status, 200);
    }
    let peak_alone = common::gauge(&alone, "mocapstore_answer_bytes_held_peak").await;
    let manifest_bound =
        (ids.len() * std::mem::size_of::<export::Entry>() + 2 * manifest.len()) as u64;
    assert!(
        peak_export <= peak_alone + ZIP_BYTES + manifest_bound,
        "the export held {peak_export} bytes; one take alone {peak_alone}"
    );
    alone.stop().await;
    t.reopen().await;
    t.finish().await;
}

/// A take the format cannot hold is skipped and the manifest says why; a request no take
/// could answer is refused before anything is sent.
#[tokio::test]
async fn export_skips_what_a_format_cannot_hold_and_refuses_what_none_can() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let (status, r) = srv
        .post(
            "name=walk&library=m",
            formats::write(&walker(120, 6, 60.0, 1, 0.1), Format::Json).unwrap(),
        )
        .await;
    assert_eq!(status, 201, "{r}");
    let (status, _, zip) = srv.get("/v1/export?library=m&format=bvh").await;
    assert_eq!(status, 200);
    let all = entries(&zip);
    assert_eq!(all.len(), 1, "only the manifest");
    let rows = manifest_rows(std::str::from_utf8(&all[0].1).unwrap());
    assert_eq!(rows[0]["id"], r["id"].as_str().unwrap());
    assert!(rows[0]["skipped"].contains("no skeleton"), "{rows:?}");
    assert_eq!(rows[0]["bytes"], "");

    // A name a spreadsheet would run as a formula is written inert (OWASP: a ' before it).
    let formula = "=cmd|'/C calc'!A0";
    let query: String = format!("name={}&library=x", urlencode(formula));
    let (status, r) = srv
        .post(
            &query,
            formats::write(&walker(30, 3, 60.0, 2, 0.0), Format::Json).unwrap(),
        )
        .await;
    assert_eq!(status, 201, "{r}");
    assert_eq!(r["name"], formula, "the take keeps its name");
    let (_, _, zip) = srv.get("/v1/export?library=x&format=json").await;
    let all = entries(&zip);
    let text = std::str::from_utf8(&all.last().unwrap().1).unwrap();
    assert!(text.contains("\"'=cmd|'/C calc'!A0\""), "{text}");
    assert_eq!(manifest_rows(text)[0]["name"], format!("'{formula}"));

    // An empty selection is an empty export: the manifest's header alone.
    let (status, _, zip) = srv.get("/v1/export?library=none").await;
    assert_eq!(status, 200);
    assert_eq!(entries(&zip)[0].1, export::manifest_head().as_bytes());

    for q in [
        "format=xyz",
        "format=gltf&unit=mm",
        "format=c3d&root=in-place",
        "fps=0",
        "root=sideways",
    ] {
        let (status, _, body) = srv.get(&format!("/v1/export?library=m&{q}")).await;
        assert_eq!(status, 400, "{q}: {}", String::from_utf8_lossy(&body));
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert!(v["error"]["message"].is_string(), "{q}: {v}");
    }
    srv.stop().await;
    t.finish().await;
}

/// `mocapstore export DIR --format bvh`: the files and manifest the ZIP holds, written into a
/// folder; a second run fetches nothing, a file changed since is fetched again, and a run
/// with other options is refused.
#[tokio::test(flavor = "multi_thread")]
async fn the_command_line_writes_the_same_files_and_resumes() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let body = formats::write(&walker(90, 6, 30.0, 2, 0.0), Format::Json).unwrap();
    for name in ["a", "b", "a"] {
        let (status, r) = srv
            .post(&format!("name={name}&library=cli"), body.clone())
            .await;
        assert_eq!(status, 201, "{r}");
    }
    let dir = std::env::temp_dir().join(format!("mocapstore-files-{}", uuid::Uuid::now_v7()));
    let d = dir.display().to_string();
    let run = |extra: &[&str]| {
        let mut args = vec![
            "export",
            &d,
            "--format",
            "trc",
            "--library",
            "cli",
            "--server",
            &srv.base,
        ];
        args.extend_from_slice(extra);
        common::mocapstore(&args)
    };
    let (ok, out, err) = run(&["--fps", "60"]);
    assert!(ok, "{out}{err}");
    assert!(out.contains("3 files written, 0 already there"), "{out}");
    let (_, _, zip) = srv.get("/v1/export?library=cli&format=trc&fps=60").await;
    for (name, bytes) in entries(&zip) {
        let on_disk = std::fs::read(dir.join(&name)).unwrap();
        assert!(on_disk == bytes, "{name}: the folder and the ZIP differ");
    }
    assert!(dir.join("cli/a_2.trc").is_file());

    let (ok, out, err) = run(&["--fps", "60"]);
    assert!(
        ok && out.contains("0 files written, 3 already there"),
        "{out}{err}"
    );
    std::fs::write(dir.join("cli/b.trc"), b"changed").unwrap();
    let (ok, out, err) = run(&["--fps", "60"]);
    assert!(
        ok && out.contains("1 files written, 2 already there"),
        "{out}{err}"
    );
    assert_eq!(
        std::fs::read(dir.join(MANIFEST)).unwrap(),
        entries(&zip).last().unwrap().1
    );
    let (ok, _, err) = run(&[]);
    assert!(!ok && err.contains("other options"), "{err}");
    let _ = std::fs::remove_dir_all(Path::new(&dir));
    srv.stop().await;
    t.finish().await;
}

/// `mocapstore export DIR --format fbx` (issue 49): a library of a skeleton take and a
/// marker take as FBX files, the same bytes as `/v1/export?format=fbx` gives, the skeleton's
/// read back as an FBX of the take's frames, the manifest listing both.
#[tokio::test(flavor = "multi_thread")]
async fn the_command_line_writes_a_library_as_fbx() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let bvh = mocapstore::motion::synthetic::dancer_bvh(60, 30.0, 3, 4).into_bytes();
    let markers = formats::write(&walker(45, 6, 30.0, 2, 0.0), Format::Json).unwrap();
    let mut frames = BTreeMap::new();
    // The walker's markers do not tell which way is up: given at ingest, as a user must
    // for a take FBX (Y up) turns upright.
    for (name, body, n, up) in [("dancer", bvh, 60, ""), ("markers", markers, 45, "&up=y")] {
        let (status, r) = srv
            .post(&format!("name={name}&library=fbx-cli{up}"), body)
            .await;
        assert_eq!(status, 201, "{r}");
        frames.insert(format!("fbx-cli/{name}.fbx"), n);
    }
    let dir = std::env::temp_dir().join(format!("mocapstore-fbx-{}", uuid::Uuid::now_v7()));
    let d = dir.display().to_string();
    let (ok, out, err) = common::mocapstore(&[
        "export",
        &d,
        "--format",
        "fbx",
        "--library",
        "fbx-cli",
        "--server",
        &srv.base,
    ]);
    let manifest = std::fs::read_to_string(dir.join(MANIFEST)).unwrap_or_default();
    assert!(
        ok && out.contains("2 files written"),
        "{out}{err}\n{manifest}"
    );
    let (status, _, zip) = srv.get("/v1/export?library=fbx-cli&format=fbx").await;
    assert_eq!(status, 200);
    let entries = entries(&zip);
    assert_eq!(entries.len(), 3, "two takes and the manifest");
    for (name, bytes) in &entries {
        let on_disk = std::fs::read(dir.join(name)).unwrap();
        assert!(on_disk == *bytes, "{name}: the folder and the ZIP differ");
        if name == MANIFEST {
            let text = String::from_utf8(bytes.clone()).unwrap();
            assert!(frames.keys().all(|f| text.contains(f.as_str())), "{text}");
            continue;
        }
        assert!(bytes.starts_with(b"Kaydara FBX Binary  \0"), "{name}");
        if name.ends_with("markers.fbx") {
            // FBX in reads skeletons (issue 49); marker FBX is checked against ufbx and
            // assimp in tests/service/fbx.rs.
            continue;
        }
        let back = formats::read_as(Format::Fbx, bytes, &Default::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(Some(&back.motion.frame_count()), frames.get(name), "{name}");
    }
    let _ = std::fs::remove_dir_all(Path::new(&dir));
    srv.stop().await;
    t.finish().await;
}

/// A damaged take is skipped (the manifest says why) and the export goes on; a take whose
/// answer needs more than the caller's share minus what the export holds is still written,
/// as it would be alone.
#[tokio::test(flavor = "multi_thread")]
async fn export_skips_a_damaged_take_and_writes_one_as_large_as_the_share_allows() {
    let t = common::sqlite().await;
    let config = mocapstore::http::Config {
        limits: mocapstore::limits::Limits {
            answer_share_bytes: 1 << 20,
            ..mocapstore::limits::Limits::default()
        },
        ..mocapstore::http::Config::default()
    };
    let srv = common::start_with(t.store.clone(), config).await;
    let mut ids = Vec::new();
    for (name, frames) in [("small", 120), ("large", 20_000)] {
        let (status, r) = srv
            .post(
                &format!("name={name}&library=d&codec=raw"),
                formats::write(&walker(frames, 40, 120.0, 1, 0.0), Format::Json).unwrap(),
            )
            .await;
        assert_eq!(status, 201, "{r}");
        ids.push(r["id"].as_str().unwrap().to_string());
    }
    // Alone, the large take's answer reserves past the 1 MiB share (one may).
    let (status, _, alone) = srv
        .get(&format!("/v1/takes/{}/frames?format=json", ids[1]))
        .await;
    assert_eq!(status, 200);
    let one_peak = common::gauge(&srv, "mocapstore_answer_bytes_one_peak").await;
    assert!(one_peak > 1 << 20, "the answer held {one_peak} bytes");

    // One byte of the small take's first chunk damaged.
    let mocapstore::store::Store::Sqlite(pool) = &t.store else {
        unreachable!()
    };
    let (mut payload,): (Vec<u8>,) = sqlx::query_as(
        "SELECT payload FROM chunks WHERE key = (SELECT key FROM takes WHERE id = $1) << 32",
    )
    .bind(&ids[0])
    .fetch_one(pool)
    .await
    .unwrap();
    let last = payload.len() - 1;
    payload[last] ^= 0x10;
    sqlx::query(
        "UPDATE chunks SET payload = $1 WHERE key = (SELECT key FROM takes WHERE id = $2) << 32",
    )
    .bind(payload)
    .bind(&ids[0])
    .execute(pool)
    .await
    .unwrap();

    let (status, _, zip) = srv.get("/v1/export?library=d&format=json").await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&zip));
    let all = entries(&zip);
    let rows = manifest_rows(std::str::from_utf8(&all.last().unwrap().1).unwrap());
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0]["id"], ids[0]);
    assert!(!rows[0]["skipped"].is_empty(), "{rows:?}");
    assert_eq!(rows[0]["bytes"], "");
    assert_eq!(rows[1]["skipped"], "");
    assert_eq!(all.len(), 2, "the large take's file and the manifest");
    assert!(all[0].1 == alone, "the large take's file is its answer");
    srv.stop().await;
    t.finish().await;
}

/// A token limited to some libraries exports their takes only, whatever the query names.
#[tokio::test]
async fn an_export_reaches_only_the_libraries_of_its_token() {
    let t = common::sqlite().await;
    let writer = common::token(&t.store, "writer", "write", None).await;
    let secret = common::token(&t.store, "reader", "read", Some(&["a"])).await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    for library in ["a", "b"] {
        let r = srv
            .client
            .post(format!("{}/v1/takes?name=walk&library={library}", srv.base))
            .bearer_auth(&writer)
            .body(formats::write(&walker(60, 6, 60.0, 1, 0.0), Format::Json).unwrap())
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
    }
    for query in ["", "?library=b"] {
        let r = srv
            .client
            .get(format!("{}/v1/export{query}", srv.base))
            .bearer_auth(&secret)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        let zip = r.bytes().await.unwrap();
        let all = entries(&zip);
        let rows = manifest_rows(std::str::from_utf8(&all.last().unwrap().1).unwrap());
        assert!(
            rows.iter().all(|r| r["library"] == "a"),
            "{query}: {rows:?}"
        );
        assert_eq!(rows.len(), usize::from(query.is_empty()), "{query}");
    }
    srv.stop().await;
    t.finish().await;
}
