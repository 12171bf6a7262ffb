//! Concurrency and interrupted uploads, over HTTP, on every backend.

use crate::common;

use std::io::Write;
use std::net::TcpStream;

use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use serde_json::Value;

fn take_json(seed: u64, frames: usize) -> Vec<u8> {
    formats::write(&walker(frames, 6, 120.0, seed, 0.1), Format::Json).unwrap()
}

#[tokio::test]
async fn sixteen_clients_ingest_and_read_at_once() {
    for t in common::all().await {
        let srv = std::sync::Arc::new(common::start(t.store.clone(), 8 << 20).await);
        let mut tasks = Vec::new();
        for c in 0..16u64 {
            let srv = srv.clone();
            tasks.push(tokio::spawn(async move {
                let mut ids = Vec::new();
                for k in 0..2 {
                    // 150 frames at 120 fps: long enough for mdtt to compete too.
                    let (status, r) = srv
                        .post(
                            &format!("name=c{c}-{k}&library=load"),
                            take_json(c * 10 + k + 1, 150),
                        )
                        .await;
                    assert_eq!(status, 201, "{r}");
                    let id = r["id"].as_str().unwrap().to_string();
                    let (status, _, body) = srv
                        .get(&format!("/v1/takes/{id}/frames?start=10&end=90"))
                        .await;
                    assert_eq!(status, 200);
                    let v: Value = serde_json::from_slice(&body).unwrap();
                    assert_eq!(v["frames"].as_array().unwrap().len(), 80);
                    ids.push(id);
                }
                ids
            }));
        }
        let mut all = Vec::new();
        for task in tasks {
            all.extend(task.await.unwrap());
        }
        all.sort();
        all.dedup();
        assert_eq!(all.len(), 32, "{}", t.name);
        assert_eq!(
            t.store.count().await.unwrap(),
            32,
            "{}: no lost takes",
            t.name
        );
        let srv = std::sync::Arc::try_unwrap(srv)
            .ok()
            .expect("all clients done");
        srv.stop().await;
        t.finish().await;
    }
}

/// A client that dies half-way through its upload, or right after sending it, leaves
/// nothing behind.
#[tokio::test]
async fn interrupted_uploads_leave_nothing() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let addr = srv.base.trim_start_matches("http://").to_string();
        let body = take_json(7, 600);
        for send in [body.len() / 2, body.len()] {
            let addr = addr.clone();
            let body = body.clone();
            tokio::task::spawn_blocking(move || {
                let mut s = TcpStream::connect(&addr).unwrap();
                write!(
                    s,
                    "POST /v1/takes?name=cut HTTP/1.1\r\nHost: localhost\r\nContent-Length: {}\r\n\r\n",
                    body.len()
                )
                .unwrap();
                s.write_all(&body[..send]).unwrap();
                s.flush().unwrap();
                drop(s); // hang up without reading a response
            })
            .await
            .unwrap();
        }
        // Wait, by what the server reports, until it has seen both requests and finished (or
        // dropped) them and holds none of their bytes: from then on nothing more is stored.
        common::settled(&srv, 2).await;
        let (full_upload_kept, chunks) = t.store.counts().await.unwrap();
        // The half upload never stores; the complete one may have been committed before the
        // hang-up was noticed, but never in part.
        assert!(full_upload_kept <= 1, "{}", t.name);
        if full_upload_kept == 0 {
            assert_eq!(chunks, 0, "{}: chunks without a take", t.name);
        } else {
            let (_, list) = {
                let (s, _, b) = srv.get("/v1/takes").await;
                (s, serde_json::from_slice::<Value>(&b).unwrap())
            };
            let id = list["items"][0]["id"].as_str().unwrap().to_string();
            let (status, h, _) = srv.get(&format!("/v1/takes/{id}/frames?format=f32")).await;
            assert_eq!(
                (status, h["x-frames"].to_str().unwrap()),
                (200, "600"),
                "{}: a whole take",
                t.name
            );
        }
        srv.stop().await;
        t.finish().await;
    }
}

/// Two servers share one database: a take deleted through one is gone from the other at
/// once, although the other had its decoded chunks cached.
#[tokio::test]
async fn deletes_through_another_server_are_seen_despite_caches() {
    for t in common::all().await {
        let a = common::start(t.store.clone(), 8 << 20).await;
        let b = common::start(t.store.clone(), 8 << 20).await;
        let (status, r) = a.post("name=shared", take_json(3, 300)).await;
        assert_eq!(status, 201, "{r}");
        let id = r["id"].as_str().unwrap().to_string();
        let frames = format!("/v1/takes/{id}/frames?start=0&end=100&format=f32");
        let (s1, _, first) = a.get(&frames).await;
        let (s2, _, again) = a.get(&frames).await; // served from the caches
        assert_eq!((s1, s2), (200, 200));
        assert!(first == again);
        assert_eq!(b.delete(&format!("/v1/takes/{id}")).await, 204);
        let (status, _, _) = a.get(&frames).await;
        assert_eq!(status, 404, "{}", t.name);
        a.stop().await;
        b.stop().await;
        t.finish().await;
    }
}

/// A long read whose middle chunks are in the decoded-chunk cache (a short read put them
/// there) gives the same bytes as before: payloads read ahead for chunks that then come
/// from the cache are skipped, not taken for the next chunk's.
#[tokio::test]
async fn long_reads_over_cached_chunks_are_whole() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let (status, r) = srv.post("name=long&codec=quant", take_json(9, 2400)).await;
    assert_eq!(status, 201, "{r}");
    let id = r["id"].as_str().unwrap().to_string();
    let whole = format!("/v1/takes/{id}/frames?format=f32");
    let (status, _, before) = srv.get(&whole).await;
    assert_eq!(status, 200);
    let (status, _, _) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?start=700&end=900&format=f32"
        ))
        .await;
    assert_eq!(status, 200);
    let (status, _, after) = srv.get(&whole).await;
    assert_eq!(status, 200);
    assert!(before == after);
    srv.stop().await;
    t.finish().await;
}
