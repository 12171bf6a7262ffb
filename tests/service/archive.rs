//! `mocapstore verify`, `export` and `import` as an archivist runs them: verify names a take
//! whose chunk was damaged and exits non-zero; export writes every take to open files and its
//! exact bitstream, and import stores the very same bytes again, in SQLite or Postgres.

use crate::common;

use std::path::Path;

use mocapstore::motion::formats::{self, Format, ReadOptions};
use mocapstore::motion::synthetic::walker;
use mocapstore::store::Store;
use serde_json::{json, Value};

use common::mocapstore;

const BVH: &str = "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition \
    Zposition Zrotation Xrotation Yrotation\nJOINT Leg\n{\nOFFSET 10 -40 0\nCHANNELS 3 Zrotation \
    Xrotation Yrotation\nEnd Site\n{\nOFFSET 0 -40 0\n}\n}\n}\nMOTION\n";

/// A library of every kind of take: each input format, gaps, a shared basis, a live stream.
async fn fill(srv: &common::Server) -> Vec<String> {
    let mut ids = Vec::new();
    let mut bvh = format!("{BVH}Frames: 90\nFrame Time: 0.0333333\n");
    for f in 0..90 {
        bvh += &format!(
            "{} 90 0 {} {} 0 {} 0 0\n",
            f as f64 * 0.5,
            f % 7,
            f % 3,
            f % 5
        );
    }
    let gaps = walker(300, 6, 120.0, 3, 0.1);
    let uploads = [
        ("bvh", bvh.into_bytes(), "max_error_mm=1"),
        (
            "json",
            formats::write(&gaps, Format::Json).unwrap(),
            "max_error_mm=0.5",
        ),
        (
            "trc",
            formats::write(&gaps, Format::Trc).unwrap(),
            "mean_error_mm=2",
        ),
        (
            "npy",
            formats::write(&gaps, Format::Npy).unwrap(),
            "fps=120&unit=mm&codec=raw",
        ),
        ("c3d", c3d_with_outputs(), "max_error_mm=1"),
    ];
    for (name, body, q) in uploads {
        let (status, r) = srv
            .post(
                &format!("name={name}&library=lib&tags=a,b&labels=content:walk,n:2&{q}"),
                body,
            )
            .await;
        assert_eq!(status, 201, "{name}: {r}");
        ids.push(r["id"].as_str().unwrap().to_string());
    }
    // A basis for the walker's layout, then a take coded with it.
    let (status, _, job) = srv
        .post_json(
            "/v1/bases",
            &json!({"ids": [ids[1].clone()], "max_iterations": 5}),
        )
        .await;
    assert_eq!(status, 202, "{job}");
    let job_path = format!("/v1/jobs/{}", job["id"].as_str().unwrap());
    common::wait_for_job(srv, &job_path).await;
    let (status, r) = srv
        .post(
            "name=shared&library=lib&codec=lsdt-frame",
            formats::write(&walker(240, 6, 120.0, 4, 0.0), Format::Json).unwrap(),
        )
        .await;
    assert_eq!(status, 201, "{r}");
    ids.push(r["id"].as_str().unwrap().to_string());
    // A take recorded live.
    let (_, _, s) = srv
        .post_json(
            "/v1/streams",
            &json!({"name": "live", "library": "lib", "fps": 60, "points": 6}),
        )
        .await;
    let sid = s["id"].as_str().unwrap().to_string();
    let frames = walker(150, 6, 60.0, 5, 0.0);
    let (status, _, r) = srv
        .post_json(
            &format!("/v1/streams/{sid}/frames"),
            &json!({"frames": frames.positions().chunks(18).collect::<Vec<_>>()}),
        )
        .await;
    assert_eq!(status, 200, "{r}");
    let (status, _, _) = srv
        .post_json(&format!("/v1/streams/{sid}/finish"), &json!({}))
        .await;
    assert_eq!(status, 200);
    ids.push(sid);
    ids
}

/// A C3D of markers and two model outputs (an angle and a moment) between them.
fn c3d_with_outputs() -> Vec<u8> {
    use mocapstore::motion::formats::c3d::write::{write, Out};
    use mocapstore::motion::outputs::{Kind, Output, Outputs};
    let m = walker(120, 6, 100.0, 5, 0.0);
    let output = |name: &str, kind, unit: &str, slot| Output {
        name: name.into(),
        kind,
        unit: unit.into(),
        slot,
    };
    let values = (0..120 * 6)
        .map(|i| (i as f32 * 0.1).sin() * 30.0)
        .collect();
    let o = Outputs::new(
        vec![
            output("LHipAngles", Kind::Angle, "deg", 1),
            output("LHipMoment", Kind::Moment, "Nmm", 3),
        ],
        values,
    )
    .unwrap();
    write(&Out {
        motion: &m,
        analog: None,
        outputs: Some(&o),
        parameters: None,
        first_frame: 1,
    })
    .unwrap()
}

/// Everything the store holds of a take: its row (as JSON), chunk payloads and model
/// outputs.
async fn stored(store: &Store, id: &str) -> (Value, Vec<u8>, Vec<Vec<u8>>, Option<Vec<u8>>) {
    let row = store.get(id).await.unwrap().unwrap();
    let header = row.header.clone();
    let chunks = store
        .chunks(id, 0, i64::MAX)
        .await
        .unwrap()
        .into_iter()
        .map(|c| c.payload)
        .collect();
    let take = mocapstore::service::fetch::parse(store, row).await.unwrap();
    let mut v = serde_json::to_value(&take).unwrap();
    // The store's own bookkeeping, not the take.
    v.as_object_mut().unwrap().remove("created_at");
    (v, header, chunks, store.outputs(id).await.unwrap())
}

fn url_of(t: &common::TestStore) -> String {
    t.url().to_string()
}

#[tokio::test]
async fn verify_names_a_damaged_take_and_export_import_round_trips_byte_for_byte() {
    let mut a = common::sqlite().await;
    let srv = common::start(a.store.clone(), 8 << 20).await;
    let ids = fill(&srv).await;
    srv.stop().await;
    a.reopen().await; // a stopped server closes its pool
    let url = url_of(&a);

    let (ok, out, err) = mocapstore(&["verify", "--database-url", &url]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains("7 takes") && out.contains("0 problems"),
        "{out}"
    );

    // Export, then import into a fresh store of every backend: the same bytes.
    let dir = std::env::temp_dir().join(format!("mocapstore-export-{}", uuid::Uuid::now_v7()));
    let d = dir.display().to_string();
    let (ok, out, err) = mocapstore(&["export", &d, "--database-url", &url]);
    assert!(ok, "{out}{err}");
    assert!(out.contains("exported 7 takes"), "{out}");
    let (ok, _, err) = mocapstore(&["export", &d, "--database-url", &url]);
    assert!(!ok && err.contains("holds an export already"), "{err}");
    check_files(&dir);
    for b in common::all().await {
        let (ok, out, err) = mocapstore(&["import", &d, "--database-url", &url_of(&b)]);
        assert!(ok, "{}: {out}{err}", b.name);
        assert!(out.contains("imported 7 takes"), "{out}");
        for id in &ids {
            assert_eq!(
                stored(&b.store, id).await,
                stored(&a.store, id).await,
                "{}: take {id}",
                b.name
            );
        }
        let (ok, out, _) = mocapstore(&["import", &d, "--database-url", &url_of(&b)]);
        assert!(ok && out.contains("7 were stored already"), "{out}");
        let (ok, out, err) = mocapstore(&["verify", "--database-url", &url_of(&b)]);
        assert!(ok, "{}: {out}{err}", b.name);
        b.finish().await;
    }

    // One damaged byte in one chunk of one take: verify names that take, exits non-zero.
    let victim = &ids[2];
    let mocapstore::store::Store::Sqlite(pool) = &a.store else {
        unreachable!()
    };
    let (payload,): (Vec<u8>,) = sqlx::query_as(
        "SELECT payload FROM chunks WHERE key = (SELECT key FROM takes WHERE id = $1) << 32",
    )
    .bind(victim)
    .fetch_one(pool)
    .await
    .unwrap();
    let mut bad = payload.clone();
    let last = bad.len() - 1;
    bad[last] ^= 0x10;
    sqlx::query(
        "UPDATE chunks SET payload = $1 WHERE key = (SELECT key FROM takes WHERE id = $2) << 32",
    )
    .bind(bad)
    .bind(victim)
    .execute(pool)
    .await
    .unwrap();
    let (ok, out, _) = mocapstore(&["verify", "--database-url", &url]);
    assert!(!ok, "a damaged chunk makes verify fail: {out}");
    let bad_lines: Vec<&str> = out.lines().filter(|l| l.starts_with("BAD")).collect();
    assert_eq!(bad_lines.len(), 1, "{out}");
    assert!(
        bad_lines[0].contains(victim.as_str()) && bad_lines[0].contains("chunk 0"),
        "{out}"
    );
    let (ok, out, _) = mocapstore(&["verify", "--database-url", &url, "--library", "elsewhere"]);
    assert!(ok && out.contains("0 takes"), "{out}");
    let (ok, _, err) = mocapstore(&["verify", "--database-url", "sqlite:///nonexistent/x.db"]);
    assert!(!ok && err.contains("no database"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
    a.finish().await;
}

/// Every exported file reads back as the format it claims, with the take's frame count.
fn check_files(dir: &Path) {
    let manifest = std::fs::read_to_string(dir.join("manifest.jsonl")).unwrap();
    for line in manifest.lines() {
        let v: Value = serde_json::from_str(line).unwrap();
        let bytes = std::fs::read(dir.join(v["file"].as_str().unwrap())).unwrap();
        let opts = ReadOptions {
            fps: Some(v["fps"].as_f64().unwrap()),
            ..ReadOptions::default()
        };
        let m = formats::read(&bytes, &opts).unwrap().motion;
        assert_eq!(
            m.frame_count() as i64,
            v["frames"].as_i64().unwrap(),
            "{line}"
        );
        assert!(dir.join(v["bitstream"].as_str().unwrap()).is_file());
        if let Some(sk) = v["skeleton"].as_str() {
            // A skeleton take: its animation as BVH, its skeleton stored once beside it.
            assert!(v["file"].as_str().unwrap().ends_with(".bvh"), "{line}");
            assert!(m.skeleton.is_some());
            assert!(dir.join(format!("skeletons/{sk}.mcsk")).is_file());
        }
    }
}
