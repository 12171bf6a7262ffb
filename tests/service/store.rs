//! The store on both backends: atomic takes, checked chunks, nothing half-written.

use crate::common;

use mocapstore::store::{
    ChunkAppend, ChunkRow, Closer, Error, LabelRow, NewStream, NewTake, Store, StreamClaim,
    StreamOwnerRow, TakeRow, TakeTotals,
};

fn take(id: &str, n: usize) -> NewTake {
    let chunks: Vec<ChunkRow> = (0..n)
        .map(|i| {
            let payload: Vec<u8> = (0..100 + i).map(|b| (b * 7 + i) as u8).collect();
            ChunkRow {
                idx: i as i64,
                first_frame: (i * 120) as i64,
                frames: 120,
                crc32c: crc32c::crc32c(&payload),
                payload,
            }
        })
        .collect();
    NewTake {
        row: TakeRow {
            id: id.to_string(),
            name: format!("take {id}"),
            library: "lib".into(),
            tags: vec!["walk".into(), "test".into()],
            labels: vec![
                LabelRow {
                    key: "content".into(),
                    value: "walk".into(),
                    number: false,
                },
                LabelRow {
                    key: "style".into(),
                    value: "0".into(),
                    number: true,
                },
            ],
            fps: 120.0,
            totals: TakeTotals {
                frames: 120 * n as i64,
                duration_s: n as f64,
                raw_bytes: 1000,
                stored_bytes: 100,
                ratio: 10.0,
                mean_mm: 0.5,
                rms_mm: 0.55,
                max_mm: 0.99,
                kg_percent: 0.1,
            },
            points: 31,
            metres_per_unit: 0.001,
            layout: "abc".into(),
            source_format: "bvh".into(),
            codec: "quant".into(),
            max_bound_mm: 1.0,
            mean_bound_mm: None,
            header: vec![1, 2, 3, 255],
            meta: br#"{"points": ["a", "b"], "decision": {"winner": "quant"}}"#.to_vec(),
            created_at: 1_700_000_000_000,
            live_until: None,
            skeleton_id: None,
            body_rev: 0,
        },
        chunks,
        basis: None,
        skeleton: None,
        errors: None,
        analog: None,
        parameters: None,
        outputs: None,
        stream: None,
    }
}

#[tokio::test]
async fn takes_round_trip_atomically_on_every_backend() {
    for t in common::all().await {
        let s = &t.store;
        let new = take("one", 3);
        s.insert(&new).await.unwrap();
        let mut want = new.row.clone();
        want.tags.sort();
        assert_eq!(s.get("one").await.unwrap().unwrap(), want, "{}", t.name);
        assert!(s.get("none").await.unwrap().is_none());
        let chunks = s.chunks("one", 1, 3).await.unwrap();
        assert_eq!(chunks, new.chunks[1..3].to_vec(), "{}", t.name);

        // A duplicate id is a conflict and changes nothing.
        assert!(
            matches!(s.insert(&new).await, Err(Error::Conflict(_))),
            "{}",
            t.name
        );
        assert_eq!(s.count().await.unwrap(), 1);

        // A take whose chunks cannot all be written leaves nothing behind.
        let mut bad = take("two", 2);
        bad.chunks[1].idx = 0; // duplicate primary key, after the row and tags went in
        assert!(s.insert(&bad).await.is_err(), "{}", t.name);
        assert!(s.get("two").await.unwrap().is_none(), "{}", t.name);
        assert_eq!(
            (s.count().await.unwrap(), s.chunk_count().await.unwrap()),
            (1, 3),
            "{}",
            t.name
        );

        // Deleting removes chunks and tags too.
        assert!(s.delete("one").await.unwrap());
        assert!(!s.delete("one").await.unwrap());
        assert_eq!(s.chunk_count().await.unwrap(), 0, "{}", t.name);
        t.finish().await;
    }
}

/// A body is written only over the record it was derived from: a meta or a re-encoding
/// written from a record read before a correction does not undo it, on every backend.
#[tokio::test]
async fn a_body_write_from_a_stale_record_changes_nothing() {
    for t in common::all().await {
        let s = &t.store;
        let new = take("body", 2);
        s.insert(&new).await.unwrap();
        let read = s.get("body").await.unwrap().unwrap();
        let mut corrected = read.clone();
        corrected.meta = r#"{"points": ["a", "b"], "axes": {"up": "y"}}"#.into();
        assert!(s.set_meta(&corrected).await.unwrap(), "{}", t.name);
        let stored = s.get("body").await.unwrap().unwrap();
        assert_eq!(stored.body_rev, read.body_rev + 1, "{}", t.name);
        // Derived from the record read before: refused, the correction stays.
        let mut stale = read.clone();
        stale.meta = r#"{"points": ["a", "b"], "axes": {"up": "z"}}"#.into();
        assert!(!s.set_meta(&stale).await.unwrap(), "{}", t.name);
        stale.totals.stored_bytes = 50;
        assert!(
            !s.update_encoding(&stale, &new.chunks, true, None)
                .await
                .unwrap(),
            "{}",
            t.name
        );
        assert_eq!(s.get("body").await.unwrap().unwrap(), stored, "{}", t.name);
        // From the record as it is now: written.
        let mut fresh = stored.clone();
        fresh.totals.stored_bytes = 50;
        assert!(s
            .update_encoding(&fresh, &new.chunks, true, None)
            .await
            .unwrap());
        assert_eq!(
            s.get("body").await.unwrap().unwrap().totals.stored_bytes,
            50
        );
        t.finish().await;
    }
}

#[tokio::test]
async fn altered_chunks_fail_their_checksum() {
    for t in common::all().await {
        t.store.insert(&take("x", 2)).await.unwrap();
        let q = "UPDATE chunks SET payload = $1 \
            WHERE key = (SELECT key FROM takes WHERE id = 'x') * 4294967296 + 1";
        match &t.store {
            Store::Sqlite(p) => sqlx::query(q)
                .bind(vec![0u8; 5])
                .execute(p)
                .await
                .map(|_| ()),
            Store::Postgres(p) => sqlx::query(q)
                .bind(vec![0u8; 5])
                .execute(p)
                .await
                .map(|_| ()),
        }
        .unwrap();
        assert!(t.store.chunks("x", 0, 1).await.is_ok());
        assert!(
            matches!(t.store.chunks("x", 0, 2).await, Err(Error::Corrupt(_))),
            "{}",
            t.name
        );
        t.finish().await;
    }
}

#[tokio::test]
async fn bad_urls_are_refused() {
    assert!(matches!(Store::open("mysql://x").await, Err(Error::Url(_))));
}

/// A stored record whose metadata does not parse is an error wherever it is read (500, and
/// a problem `verify` names), never a take with empty metadata; it can still be deleted.
#[tokio::test]
async fn a_corrupt_meta_row_is_an_error_not_an_empty_record() {
    for mut t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let m = mocapstore::motion::synthetic::walker(60, 3, 60.0, 2, 0.0);
        let body = mocapstore::motion::formats::json::write(&m);
        let (status, report) = srv.post("max_error_mm=1", body).await;
        assert_eq!(status, 201, "{report}");
        let id = report["id"].as_str().unwrap().to_string();
        let (status, ok) = srv.get_json(&format!("/v1/takes/{id}")).await;
        assert_eq!(status, 200);
        assert_eq!(ok["meta"]["point_names"].as_array().unwrap().len(), 3);

        let q = "UPDATE takes SET meta = $1 WHERE id = $2";
        // Packed as the store packs records, so that it is its JSON that does not parse.
        let corrupt = mocapstore::store::packed::pack(r#"{"point_names": "not a list"}"#).unwrap();
        match &t.store {
            Store::Sqlite(p) => sqlx::query(q)
                .bind(&corrupt)
                .bind(&id)
                .execute(p)
                .await
                .map(|_| ()),
            Store::Postgres(p) => sqlx::query(q)
                .bind(&corrupt)
                .bind(&id)
                .execute(p)
                .await
                .map(|_| ()),
        }
        .unwrap();
        // A server that has not read the take since (this one did, taking its motion
        // features at ingest, and may answer from the reader it keeps by the take's coding).
        srv.stop().await;
        t.reopen().await;
        let srv = common::start(t.store.clone(), 8 << 20).await;
        for path in [
            format!("/v1/takes/{id}"),
            format!("/v1/takes/{id}/frames?start=0&end=5"),
            "/v1/takes".to_string(),
        ] {
            let (status, body) = srv.get_json(&path).await;
            assert_eq!(status, 500, "{}: {path}: {body}", t.name);
            assert_eq!(body["error"]["code"], "internal", "{path}");
        }
        let report = mocapstore::service::archive::verify(&t.store, &Default::default(), |_| {})
            .await
            .unwrap();
        assert_eq!(report.problems.len(), 1, "{:?}", report.problems);
        assert!(
            report.problems[0].id == id && report.problems[0].what.contains("meta"),
            "{:?}",
            report.problems
        );
        assert_eq!(srv.delete(&format!("/v1/takes/{id}")).await, 204);
        srv.stop().await;
        t.finish().await;
    }
}

/// Migrations on a store written before them. 0005: a take under a max bound keeps it; one
/// under a mean bound alone keeps its mean and gets the loosest max (it was coded to none),
/// and both read back as typed bounds through the service.
#[tokio::test]
async fn old_databases_migrate_bounds_and_table_names() {
    use sqlx::sqlite::{SqliteConnectOptions, SqlitePoolOptions};
    use std::str::FromStr;

    let dir = std::env::temp_dir().join(format!("mocapstore-migrate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let url = format!("sqlite://{}", dir.join("old.db").display());
    {
        let pool = SqlitePoolOptions::new()
            .connect_with(
                SqliteConnectOptions::from_str(&url)
                    .unwrap()
                    .create_if_missing(true),
            )
            .await
            .unwrap();
        let mut before = sqlx::migrate!("migrations/sqlite");
        let first: Vec<_> = before
            .migrations
            .iter()
            .filter(|m| m.version < 5)
            .cloned()
            .collect();
        assert_eq!(first.len(), 4);
        before.migrations = first.into();
        before.run(&pool).await.unwrap();
        for (id, kind, mm) in [("a", "max", 1.0), ("b", "mean", 3.0)] {
            sqlx::query(
                "INSERT INTO sequences (id, name, library, fps, frames, points, duration_s, \
                 metres_per_unit, layout, source_format, codec, bound_kind, bound_mm, raw_bytes, \
                 stored_bytes, ratio, mean_mm, rms_mm, max_mm, kg_percent, header, meta, \
                 created_at) VALUES ($1, $1, '', 120, 1, 1, 0.01, 0.001, 'l', 'c3d', 'quant', \
                 $2, $3, 12, 10, 1.2, 0.5, 0.5, 71.0, 0, x'00', '{}', 1)",
            )
            .bind(id)
            .bind(kind)
            .bind(mm)
            .execute(&pool)
            .await
            .unwrap();
        }
        for q in [
            "INSERT INTO chunks (sequence_id, idx, first_frame, frames, crc32c, payload) \
             VALUES ('a', 0, 0, 1, 7, x'00')",
            "INSERT INTO sequence_tags (sequence_id, tag) VALUES ('a', 'walk')",
        ] {
            sqlx::query(q).execute(&pool).await.unwrap();
        }
        pool.close().await;
    }
    let store = Store::open(&url).await.unwrap();
    let a = store.get("a").await.unwrap().unwrap();
    assert_eq!((a.max_bound_mm, a.mean_bound_mm), (1.0, None));
    // Migration 0012 renamed the tables (sequences → takes, sequence_id → take_id): the
    // take keeps its chunk and tag, and deleting it still deletes them.
    assert_eq!(a.tags, vec!["walk".to_string()]);
    assert_eq!(store.chunk_index("a").await.unwrap().len(), 1);
    assert!(store.delete("a").await.unwrap());
    assert!(store.chunk_index("a").await.unwrap().is_empty());
    let b = store.get("b").await.unwrap().unwrap();
    assert_eq!(
        (b.max_bound_mm, b.mean_bound_mm),
        (mocapstore::limits::MAX_BOUND_MM, Some(3.0))
    );
    store.close().await;
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A live take's stream rows: one claim wins, and the server that lost the stream can no
/// longer write it (each write names its owner), the same chunk stored twice is stored once.
#[tokio::test]
async fn a_stream_taken_over_fences_its_old_server_on_every_backend() {
    for t in common::all().await {
        let s = &t.store;
        let owner = |n: &str| StreamOwnerRow {
            server: n.into(),
            url: format!("http://{n}"),
        };
        let mut new = take("live", 0);
        new.row.totals.frames = 0;
        new.row.live_until = Some(1_000);
        new.stream = Some(NewStream {
            owner: owner("a"),
            state: "{}".into(),
        });
        s.insert(&new).await.unwrap();
        let chunk = take("x", 1).chunks.remove(0);
        let totals = TakeTotals {
            frames: 120,
            ..new.row.totals
        };
        let append = |server: &'static str| ChunkAppend {
            server,
            live_until: 2_000,
            frames_received: 130,
            state: "{\"n\": 1}",
            meta: None,
        };
        assert!(s
            .append_chunk("live", &totals, &chunk, &append("a"))
            .await
            .unwrap());
        // Sent again (its answer lost): stored once; with the take's meta, which it writes.
        let meta = br#"{"points": ["a", "b"], "axes": {"up": "y"}}"#;
        assert!(s
            .append_chunk(
                "live",
                &totals,
                &chunk,
                &ChunkAppend {
                    meta: Some(meta.as_slice()),
                    ..append("a")
                }
            )
            .await
            .unwrap());
        assert_eq!(s.chunk_index("live").await.unwrap().len(), 1, "{}", t.name);
        assert_eq!(
            s.get("live").await.unwrap().unwrap().meta,
            meta.to_vec(),
            "{}",
            t.name
        );
        let row = s.stream("live").await.unwrap().unwrap();
        assert_eq!(
            (row.frames, row.frames_received, row.live_until, row.owner),
            (120, 130, 2_000, Some(owner("a"))),
            "{}",
            t.name
        );
        // Before the lease runs out nobody else claims it; after, one claim wins.
        fn claim(o: &StreamOwnerRow, now: i64) -> StreamClaim<'_> {
            StreamClaim {
                owner: o,
                now,
                live_until: now + 5_000,
                frames: 120,
                frames_received: 130,
                meta: b"{}",
            }
        }
        let (b, c) = (owner("b"), owner("c"));
        assert!(!s.claim_stream("live", &claim(&b, 1_500)).await.unwrap());
        assert!(s.claim_stream("live", &claim(&b, 2_500)).await.unwrap());
        assert!(
            !s.claim_stream("live", &claim(&c, 2_500)).await.unwrap(),
            "{}: the row changed (received reset, lease renewed): a second claim loses",
            t.name
        );
        let row = s.stream("live").await.unwrap().unwrap();
        assert_eq!((row.owner, row.frames_received), (Some(b.clone()), 120));
        // The old owner is fenced off.
        assert!(!s.note_received("live", "a", 140, 9_000).await.unwrap());
        assert!(!s.renew_lease("live", "a", 9_000).await.unwrap());
        let mut next = chunk.clone();
        next.idx = 1;
        next.first_frame = 120;
        assert!(!s
            .append_chunk("live", &totals, &next, &append("a"))
            .await
            .unwrap());
        assert!(s.note_received("live", "b", 125, 9_000).await.unwrap());
        assert_eq!(s.chunk_index("live").await.unwrap().len(), 1, "{}", t.name);
        // Nor may it close the take; an orphan close needs the lease run out and the
        // frames it read.
        let close = |by| s.close_live("live", &[9], b"{}", by);
        assert!(!close(Closer::Owner("a")).await.unwrap(), "{}", t.name);
        let orphan = |before, frames| Closer::Orphan { before, frames };
        assert!(
            !close(orphan(8_000, 120)).await.unwrap(),
            "lease still runs"
        );
        assert!(!close(orphan(10_000, 60)).await.unwrap(), "frames changed");
        assert!(close(Closer::Owner("b")).await.unwrap());
        assert!(s.stream("live").await.unwrap().is_none(), "closed");
        t.finish().await;
    }
}

/// Write `takes` (rows, their records' text and chunks) into `db` as the store did at
/// migration 0017: the migrations up to it, and each take's record as JSON text in `meta`.
/// A take as migration 0017's store held it.
#[derive(Clone)]
struct OldTake {
    row: TakeRow,
    /// Its record, JSON text.
    text: String,
    chunks: Vec<ChunkRow>,
    /// Its error series, in `take_errors` then.
    errors: Option<Vec<u8>>,
    /// With a row in every other table of a take's: a skeleton, a basis, analog channels
    /// (their header and a chunk), parameters, outputs and features (bytes of their own).
    extras: bool,
}

/// The analog chunk an old take with extras has.
fn old_analog_chunk() -> ChunkRow {
    let payload = vec![7u8, 8, 9];
    ChunkRow {
        idx: 0,
        first_frame: 0,
        frames: 5,
        crc32c: crc32c::crc32c(&payload),
        payload,
    }
}

async fn write_at_migration_17(db: &common::Unopened, takes: &[OldTake]) {
    use std::str::FromStr;
    macro_rules! write {
        ($pool:expr, $migrator:expr) => {{
            let pool = $pool;
            let mut before = $migrator;
            let first: Vec<_> = before
                .migrations
                .iter()
                .filter(|m| m.version <= 17)
                .cloned()
                .collect();
            assert_eq!(first.len(), 17);
            before.migrations = first.into();
            before.run(&pool).await.unwrap();
            for OldTake {
                row,
                text,
                chunks,
                errors,
                extras,
            } in takes
            {
                sqlx::query(
                    "INSERT INTO takes (frames, duration_s, raw_bytes, stored_bytes, ratio, \
                     mean_mm, rms_mm, max_mm, kg_percent, id, name, library, fps, points, \
                     metres_per_unit, layout, source_format, codec, max_bound_mm, mean_bound_mm, \
                     header, meta, created_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, \
                     $11, $12, $13, $14, $15, $16, $17, $18, $19, $20, $21, $22, $23)",
                )
                .bind(row.totals.frames)
                .bind(row.totals.duration_s)
                .bind(row.totals.raw_bytes)
                .bind(row.totals.stored_bytes)
                .bind(row.totals.ratio)
                .bind(row.totals.mean_mm)
                .bind(row.totals.rms_mm)
                .bind(row.totals.max_mm)
                .bind(row.totals.kg_percent)
                .bind(&row.id)
                .bind(&row.name)
                .bind(&row.library)
                .bind(row.fps)
                .bind(row.points)
                .bind(row.metres_per_unit)
                .bind(&row.layout)
                .bind(&row.source_format)
                .bind(&row.codec)
                .bind(row.max_bound_mm)
                .bind(row.mean_bound_mm)
                .bind(&row.header)
                .bind(text)
                .bind(row.created_at)
                .execute(&pool)
                .await
                .unwrap();
                if let Some(e) = errors {
                    sqlx::query("INSERT INTO take_errors (take_id, series) VALUES ($1, $2)")
                        .bind(&row.id)
                        .bind(e)
                        .execute(&pool)
                        .await
                        .unwrap();
                }
                for tag in &row.tags {
                    sqlx::query("INSERT INTO take_tags (take_id, tag) VALUES ($1, $2)")
                        .bind(&row.id)
                        .bind(tag)
                        .execute(&pool)
                        .await
                        .unwrap();
                }
                for l in &row.labels {
                    sqlx::query(
                        "INSERT INTO take_labels (take_id, key, value, number) \
                         VALUES ($1, $2, $3, $4)",
                    )
                    .bind(&row.id)
                    .bind(&l.key)
                    .bind(&l.value)
                    .bind(l.number)
                    .execute(&pool)
                    .await
                    .unwrap();
                }
                let analog = if *extras {
                    vec![old_analog_chunk()]
                } else {
                    Vec::new()
                };
                for (table, list) in [("chunks", chunks), ("analog_chunks", &analog)] {
                    for c in list {
                        sqlx::query(&format!(
                            "INSERT INTO {table} (take_id, idx, first_frame, frames, crc32c, \
                             payload) VALUES ($1, $2, $3, $4, $5, $6)"
                        ))
                        .bind(&row.id)
                        .bind(c.idx)
                        .bind(c.first_frame)
                        .bind(c.frames)
                        .bind(i64::from(c.crc32c))
                        .bind(&c.payload)
                        .execute(&pool)
                        .await
                        .unwrap();
                    }
                }
                if *extras {
                    let id = row.id.as_str();
                    // (statement, the take's id bound as $1, the bytes bound after it)
                    let steps: [(&str, bool, Option<Vec<u8>>); 8] = [
                        (
                            "INSERT INTO skeletons (id, layout, joints, payload, created_at) \
                             VALUES ('sk', 'l', 2, $1, 0)",
                            false,
                            Some(vec![1]),
                        ),
                        ("UPDATE takes SET skeleton_id = 'sk' WHERE id = $1", true, None),
                        (
                            "INSERT INTO bases (id, kind, layout, points, dims, payload, \
                             provenance, created_at) VALUES ('b', 'pca', 'l', 2, '[]', $1, '{}', 0)",
                            false,
                            Some(vec![2]),
                        ),
                        (
                            "INSERT INTO take_bases (take_id, basis_id) VALUES ($1, 'b')",
                            true,
                            None,
                        ),
                        (
                            "INSERT INTO take_analog (take_id, header, raw_bytes, stored_bytes) \
                             VALUES ($1, $2, 10, 2)",
                            true,
                            Some(vec![10, 11]),
                        ),
                        (
                            "INSERT INTO take_parameters (take_id, format, payload) \
                             VALUES ($1, 'c3d', $2)",
                            true,
                            Some(vec![12]),
                        ),
                        (
                            "INSERT INTO take_outputs (take_id, payload) VALUES ($1, $2)",
                            true,
                            Some(vec![13]),
                        ),
                        (
                            "INSERT INTO take_features (take_id, codec, stored_bytes, frames, \
                             body_rev, payload, failed) VALUES ($1, 'raw', 1, 2, 0, $2, NULL)",
                            true,
                            Some(vec![14]),
                        ),
                    ];
                    for (sql, with_id, bytes) in steps {
                        let mut q = sqlx::query(sql);
                        if with_id {
                            q = q.bind(id);
                        }
                        if let Some(b) = bytes {
                            q = q.bind(b);
                        }
                        q.execute(&pool).await.unwrap();
                    }
                }
            }
            pool.close().await;
        }};
    }
    match db.name {
        "sqlite" => write!(
            sqlx::sqlite::SqlitePoolOptions::new()
                .connect_with(
                    sqlx::sqlite::SqliteConnectOptions::from_str(&db.url)
                        .unwrap()
                        .create_if_missing(true),
                )
                .await
                .unwrap(),
            sqlx::migrate!("migrations/sqlite")
        ),
        _ => write!(
            sqlx::PgPool::connect(&db.url).await.unwrap(),
            sqlx::migrate!("migrations/postgres")
        ),
    }
}

/// Migration 0018 packs the records of a store written at 0017 in place, 0019 moves each
/// take's error series into its row, 0020 keys chunks by their take's integer key and 0021
/// keys everything else of a take by it: every take reads back as it did (its record, its
/// error series, its tags and labels, its chunks, its frames, its answer through the API,
/// byte for byte), the JSON text column is gone, a new take's
/// chunks and a deleted one's keep apart, and opening the store again finds nothing left
/// to do.
#[tokio::test]
async fn records_written_at_migration_17_are_packed_in_place() {
    use mocapstore::motion::formats::{self, Format};
    use mocapstore::motion::synthetic::walker;

    // A take as today's store writes it, its record as JSON text (what 0017 stored).
    let source = common::sqlite().await;
    let srv = common::start(source.store.clone(), 1 << 24).await;
    let (status, r) = srv
        .post(
            "name=walk&tags=old",
            formats::write(&walker(2400, 6, 120.0, 3, 0.0), Format::Json).unwrap(),
        )
        .await;
    assert_eq!(status, 201, "{r}");
    let id = r["id"].as_str().unwrap().to_string();
    // With a label, as a dataset's sidecar file gives (kept by the take's key since 0021).
    let labels = [mocapstore::store::LabelRow {
        key: "subject".into(),
        value: "07".into(),
        number: true,
    }];
    let edit = mocapstore::store::TakeEdit {
        labels: Some(&labels),
        ..Default::default()
    };
    assert!(source.store.update(&id, &edit).await.unwrap());
    let (_, answer) = srv.get_json(&format!("/v1/takes/{id}")).await;
    let (_, _, frames) = srv.get(&format!("/v1/takes/{id}/frames?format=f32")).await;
    let row = source.store.get(&id).await.unwrap().unwrap();
    assert_eq!(row.labels.len(), 1);
    let text = mocapstore::store::packed::unpack(&row.meta).unwrap();
    assert!(text.starts_with('{') && text.len() > 500, "{text}");
    let chunks = source.store.chunks(&id, 0, i64::MAX).await.unwrap();
    assert!(chunks.len() > 2, "{} chunks", chunks.len());
    let errors = source.store.error_series(&id).await.unwrap();
    assert!(errors.as_ref().is_some_and(|e| !e.is_empty()));
    srv.stop().await;
    source.finish().await;

    // And a row of an empty id (an import takes ids as its manifest gives them).
    let empty = TakeRow {
        id: String::new(),
        tags: Vec::new(),
        ..row.clone()
    };
    let bad = TakeRow {
        id: "bad".into(),
        tags: Vec::new(),
        ..row.clone()
    };
    // And one with a row in every other table of a take's.
    let full = TakeRow {
        id: "full".into(),
        tags: Vec::new(),
        labels: Vec::new(),
        ..row.clone()
    };
    for db in common::all_unopened().await {
        write_at_migration_17(
            &db,
            &[
                OldTake {
                    row: row.clone(),
                    text: text.clone(),
                    chunks: chunks.clone(),
                    errors: errors.clone(),
                    extras: false,
                },
                OldTake {
                    row: empty.clone(),
                    text: text.clone(),
                    chunks: Vec::new(),
                    errors: None,
                    extras: false,
                },
                OldTake {
                    row: bad.clone(),
                    text: text.clone(),
                    chunks: Vec::new(),
                    errors: None,
                    extras: false,
                },
                OldTake {
                    row: full.clone(),
                    text: text.clone(),
                    chunks: Vec::new(),
                    errors: None,
                    extras: true,
                },
            ],
        )
        .await;
        if db.name == "sqlite" {
            // SQLite keeps what a column is given: a record that is not text at all.
            let pool = sqlx::SqlitePool::connect(&db.url).await.unwrap();
            sqlx::query("UPDATE takes SET meta = x'fffe' WHERE id = 'bad'")
                .execute(&pool)
                .await
                .unwrap();
            pool.close().await;
        }
        let t = db.open().await;
        let again = t.store.get(&id).await.unwrap().unwrap();
        assert_eq!(
            again.meta, row.meta,
            "{}: packed as today's store packs",
            t.name
        );
        assert_eq!(again.tags, row.tags, "{}", t.name);
        assert_eq!(again.labels, row.labels, "{}", t.name);
        // 0019 moved the error series into the take's row.
        assert_eq!(
            t.store.error_series(&id).await.unwrap(),
            errors,
            "{}",
            t.name
        );
        assert_eq!(t.store.error_series("").await.unwrap(), None, "{}", t.name);
        assert_eq!(t.store.get("").await.unwrap().unwrap().meta, row.meta);
        // Kept as it was, not packed: that take reads as corrupt (verify names it), and the
        // store opens.
        let kept = t.store.get("bad").await.unwrap().unwrap().meta;
        if t.name == "sqlite" {
            assert_eq!(kept, vec![0xff, 0xfe]);
        } else {
            assert_eq!(kept, row.meta);
        }
        // 0021 re-keyed every other table of a take's: each row reads back as written, and
        // goes with its take.
        let full = t.store.get("full").await.unwrap().unwrap();
        assert_eq!(full.skeleton_id.as_deref(), Some("sk"), "{}", t.name);
        let analog = t.store.analog("full").await.unwrap().unwrap();
        assert_eq!(
            (analog.header, analog.raw_bytes, analog.stored_bytes),
            (vec![10, 11], 10, 2),
            "{}",
            t.name
        );
        assert_eq!(
            t.store.analog_chunks("full", 0, i64::MAX).await.unwrap(),
            vec![old_analog_chunk()],
            "{}",
            t.name
        );
        let p = t.store.parameters("full").await.unwrap().unwrap();
        assert_eq!((p.format.as_str(), p.payload), ("c3d", vec![12]));
        assert_eq!(t.store.outputs("full").await.unwrap(), Some(vec![13]));
        let features = t.store.features_of(&["full".to_string()]).await.unwrap();
        assert_eq!(features.len(), 1, "{}", t.name);
        assert_eq!(features[0].1.payload, vec![14]);
        let used = t
            .store
            .basis_use_within(std::slice::from_ref(&full.library))
            .await
            .unwrap();
        assert_eq!(used.get("b"), Some(&1), "{}", t.name);
        assert!(t.store.delete("full").await.unwrap());
        assert_eq!(t.store.analog("full").await.unwrap(), None);
        assert!(t
            .store
            .analog_chunks("full", 0, i64::MAX)
            .await
            .unwrap()
            .is_empty());
        assert_eq!(t.store.parameters("full").await.unwrap(), None);
        assert_eq!(t.store.outputs("full").await.unwrap(), None);
        assert!(t
            .store
            .features_of(&["full".to_string()])
            .await
            .unwrap()
            .is_empty());
        assert!(t
            .store
            .basis_use_within(std::slice::from_ref(&full.library))
            .await
            .unwrap()
            .is_empty());
        // The JSON text is gone from the table, and what is there is the packed record.
        let (columns, packed): (i64, i64) = match &t.store {
            Store::Sqlite(pool) => (
                sqlx::query_scalar(
                    "SELECT COUNT(*) FROM pragma_table_info('takes') WHERE name = 'meta_text'",
                )
                .fetch_one(pool)
                .await
                .unwrap(),
                sqlx::query_scalar(
                    "SELECT MAX(LENGTH(meta)) FROM takes WHERE typeof(meta) = 'blob'",
                )
                .fetch_one(pool)
                .await
                .unwrap(),
            ),
            Store::Postgres(pool) => (
                sqlx::query_scalar(
                    "SELECT COUNT(*) FROM information_schema.columns WHERE table_schema = \
                     current_schema() AND table_name = 'takes' AND column_name = 'meta_text'",
                )
                .fetch_one(pool)
                .await
                .unwrap(),
                sqlx::query_scalar("SELECT CAST(MAX(LENGTH(meta)) AS BIGINT) FROM takes")
                    .fetch_one(pool)
                    .await
                    .unwrap(),
            ),
        };
        assert_eq!(columns, 0, "{}", t.name);
        assert!(
            packed > 0 && (packed as usize) * 3 < text.len(),
            "{}: {packed} bytes packed for {}",
            t.name,
            text.len()
        );
        // Through the API, the take answers as it did before.
        let srv = common::start(t.store.clone(), 1 << 24).await;
        let (status, now) = srv.get_json(&format!("/v1/takes/{id}")).await;
        assert_eq!(status, 200, "{}: {now}", t.name);
        assert_eq!(now, answer, "{}", t.name);
        let (_, _, now_frames) = srv.get(&format!("/v1/takes/{id}/frames?format=f32")).await;
        assert!(now_frames == frames, "{}: frames differ", t.name);
        // 0020 keyed the chunks by the take's integer key: each reads back as it was; a
        // take stored after it gets a key of its own, and deleting the old take deletes
        // its chunks and no other's.
        assert_eq!(t.store.chunks(&id, 0, i64::MAX).await.unwrap(), chunks);
        assert_eq!(t.store.chunks(&id, 1, 2).await.unwrap(), chunks[1..2]);
        let (status, r) = srv
            .post(
                "name=new",
                formats::write(&walker(240, 6, 120.0, 3, 0.0), Format::Json).unwrap(),
            )
            .await;
        assert_eq!(status, 201, "{}: {r}", t.name);
        let new = r["id"].as_str().unwrap().to_string();
        let new_chunks = t.store.chunks(&new, 0, i64::MAX).await.unwrap();
        assert!(!new_chunks.is_empty());
        let before = t.store.chunk_count().await.unwrap();
        assert_eq!(
            before,
            (chunks.len() + new_chunks.len()) as i64,
            "{}",
            t.name
        );
        assert!(t.store.delete(&id).await.unwrap());
        assert_eq!(
            t.store.chunk_count().await.unwrap(),
            new_chunks.len() as i64,
            "{}",
            t.name
        );
        assert_eq!(t.store.chunks(&new, 0, i64::MAX).await.unwrap(), new_chunks);
        assert!(t.store.chunks(&id, 0, i64::MAX).await.unwrap().is_empty());
        srv.stop().await;
        // Opened again: nothing left to pack, the take as it was.
        let url = t.url.clone();
        t.store.close().await;
        let reopened = Store::open(&url).await.unwrap();
        assert_eq!(reopened.get("").await.unwrap().unwrap().meta, row.meta);
        reopened.close().await;
        t.finish().await;
    }
}
