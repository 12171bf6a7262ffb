//! `mocapstore bench --search --copies N`: what search costs through the store. The files
//! are ingested into a fresh SQLite archive by an in-process server (the first copy with
//! the defaults, timed; further copies under other names with `codec=quant`, for speed:
//! their features are the same), until the archive holds the frames asked. Then:
//! - search latency (`GET /v1/takes/{id}/similar`, 2 s ranges and whole takes of random
//!   takes, one at a time): p50, p99, exact (`index=exact`) and approximate
//!   (`index=approximate`, the graph built first and timed);
//! - the approximate search's recall: the share of exact search's k results (take and
//!   range) it answers too, and the takes it scored;
//! - the features' bytes as a share of the database file;
//! - ingest slowdown: the time taking the first copy's features (again, through a motion
//!   index of its own) against its ingest's time without them.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use mocapstore::http::{Application, Config};
use mocapstore::limits::Limits;
use mocapstore::service::budget::Budget;
use mocapstore::service::motion_index::MotionIndex;
use mocapstore::service::prepared::ReadCaches;
use mocapstore::store::Store;

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn bytes_of(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok()?.metadata().ok())
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

pub async fn run(files: &[PathBuf], min_frames: u64, queries: usize) -> Result<(), String> {
    let dir = std::env::temp_dir().join(format!("mocapstore-search-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let url = format!("sqlite://{}", dir.join("search.db").display());
    let store = Store::open(&url).await.map_err(|e| e.to_string())?;
    let limits = Limits {
        requests_per_s: 1_000_000_000,
        request_burst: 1_000_000_000,
        ..Limits::default()
    };
    let app = Application::with_store(
        store.clone(),
        Config {
            listen: "127.0.0.1:0".into(),
            database_url: url.clone(),
            limits,
            ..Config::default()
        },
    )
    .await?;
    let base = format!("http://{}", app.local_addr());
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until(async {
        let _ = stopped.await;
    }));
    let client = reqwest::Client::new();
    let bodies: Vec<(String, Vec<u8>)> = files
        .iter()
        .filter_map(|p| {
            let stem = p.file_stem()?.to_string_lossy().into_owned();
            Some((stem, std::fs::read(p).ok()?))
        })
        .collect();
    let mut frames = 0u64;
    let mut ids: Vec<(String, f64)> = Vec::new();
    let mut first_ingest_s = 0.0;
    let mut first_ids = Vec::new();
    let mut copy = 0;
    while copy == 0 || frames < min_frames {
        let codec = if copy == 0 { "" } else { "&codec=quant" };
        let started = Instant::now();
        for (stem, body) in &bodies {
            let r = client
                .post(format!(
                    "{base}/v1/takes?name=c{copy}/{stem}&library=c{copy}{codec}"
                ))
                .body(body.clone())
                .send()
                .await
                .map_err(|e| e.to_string())?;
            if !r.status().is_success() {
                eprintln!("{stem}: {}; left out", r.status());
                continue;
            }
            let v: serde_json::Value = r.json().await.map_err(|e| e.to_string())?;
            let (n, fps) = (
                v["frames"].as_u64().unwrap_or(0),
                v["fps"].as_f64().unwrap_or(30.0),
            );
            frames += n;
            let id = v["id"].as_str().unwrap_or_default().to_string();
            if copy == 0 {
                first_ids.push(id.clone());
            }
            ids.push((id, n as f64 / fps));
        }
        if copy == 0 {
            first_ingest_s = started.elapsed().as_secs_f64();
        }
        copy += 1;
        if ids.is_empty() {
            return Err("no file could be ingested".into());
        }
    }
    // The first copy's features taken again, timed apart from its ingest.
    let index = MotionIndex::new(
        store.clone(),
        Arc::new(ReadCaches::new(64 << 20)),
        Arc::new(Budget::new(limits.answer_bytes, limits.answer_share_bytes)),
        limits,
    );
    let started = Instant::now();
    for id in &first_ids {
        index.index(id).await.map_err(|e| e.to_string())?;
    }
    let features_s = started.elapsed().as_secs_f64();
    let (feature_bytes, indexed) = store.features_bytes().await.map_err(|e| e.to_string())?;

    let mut rng = mocapstore::rng::Rng::new(7);
    let mut exact_ms = Vec::with_capacity(queries);
    let mut approximate_ms = Vec::with_capacity(queries);
    let (mut found, mut missed, mut scored) = (0usize, 0usize, 0usize);
    let mut windows_searched = 0u64;
    let search = |url: String| {
        let client = client.clone();
        async move {
            let started = Instant::now();
            let r = client.get(url).send().await.map_err(|e| e.to_string())?;
            let status = r.status();
            let v: serde_json::Value = r.json().await.map_err(|e| e.to_string())?;
            Ok::<_, String>((status, v, started.elapsed().as_secs_f64() * 1e3))
        }
    };
    // One search first: the server reads every take's features into memory once.
    let (_, _, first_search_ms) = search(format!(
        "{base}/v1/takes/{}/similar?k=10&index=exact",
        ids[0].0
    ))
    .await?;
    // The graph: the first approximate search starts its build and is refused until it is in.
    let built = Instant::now();
    loop {
        let (status, v, _) = search(format!(
            "{base}/v1/takes/{}/similar?k=10&index=approximate",
            ids[0].0
        ))
        .await?;
        if status.is_success() {
            break;
        }
        if status != reqwest::StatusCode::SERVICE_UNAVAILABLE {
            return Err(format!("approximate search: {status}: {v}"));
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let build_s = built.elapsed().as_secs_f64();
    for q in 0..queries {
        let (id, seconds) = &ids[rng.below(ids.len())];
        let range = if q % 2 == 0 && *seconds > 2.5 {
            let t0 = rng.unit() * (seconds - 2.0);
            format!("&t0={t0:.3}&t1={:.3}", t0 + 2.0)
        } else {
            String::new()
        };
        let mut answers = Vec::new();
        for (index, times) in [
            ("exact", &mut exact_ms),
            ("approximate", &mut approximate_ms),
        ] {
            let (status, v, ms) = search(format!(
                "{base}/v1/takes/{id}/similar?k=10&index={index}{range}"
            ))
            .await?;
            if !status.is_success() {
                return Err(format!("search of take {id} ({index}): {status}: {v}"));
            }
            times.push(ms);
            answers.push(v);
        }
        let results = |v: &serde_json::Value| -> Vec<(String, String)> {
            v["results"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|r| (r["take"].to_string(), r["t0"].to_string()))
                .collect()
        };
        let (exact, approximate) = (results(&answers[0]), results(&answers[1]));
        found += exact.iter().filter(|r| approximate.contains(r)).count();
        missed += exact.iter().filter(|r| !approximate.contains(r)).count();
        scored += answers[1]["searched"]["scored"].as_u64().unwrap_or(0) as usize;
        windows_searched = answers[0]["searched"]["windows"].as_u64().unwrap_or(0);
    }
    let _ = stop.send(());
    let _ = server.await;
    store.close().await;
    let db_bytes = bytes_of(&dir);
    let _ = std::fs::remove_dir_all(&dir);
    exact_ms.sort_by(f64::total_cmp);
    approximate_ms.sort_by(f64::total_cmp);
    println!();
    println!(
        "Search through the store: {} takes ({copy} copies of {} files), {frames} frames, \
         {windows_searched} windows; {queries} searches (2 s ranges and whole takes of random \
         takes, k = 10, one at a time, over HTTP), each exact and approximate",
        ids.len(),
        bodies.len()
    );
    println!();
    println!("| | value |");
    println!("|---|---:|");
    println!(
        "| search p50, exact / approximate | {:.1} / {:.1} ms |",
        percentile(&exact_ms, 0.5),
        percentile(&approximate_ms, 0.5)
    );
    println!(
        "| search p99, exact / approximate | {:.1} / {:.1} ms |",
        percentile(&exact_ms, 0.99),
        percentile(&approximate_ms, 0.99)
    );
    println!(
        "| approximate recall@10 (exact's results it answers too) | {:.3} ({found} of {}) |",
        found as f64 / (found + missed).max(1) as f64,
        found + missed
    );
    println!(
        "| takes scored, approximate (exact: all {}) | {:.0} a search |",
        ids.len(),
        scored as f64 / queries.max(1) as f64
    );
    println!("| graph built (first approximate search to its answer) | {build_s:.1} s |");
    println!("| first search (reads every take's features) | {first_search_ms:.0} ms |");
    println!(
        "| features stored | {} takes, {:.2} MB ({:.1} bytes a frame) |",
        indexed,
        feature_bytes as f64 / 1e6,
        feature_bytes as f64 / frames.max(1) as f64
    );
    println!(
        "| database file | {:.2} MB; features {:.1} % of it |",
        db_bytes as f64 / 1e6,
        100.0 * feature_bytes as f64 / db_bytes.max(1) as f64
    );
    println!(
        "| ingest of the first copy (defaults) | {first_ingest_s:.1} s, of which taking \
         features {features_s:.1} s: {:.1} % slower than without |",
        100.0 * features_s / (first_ingest_s - features_s).max(1e-9)
    );
    Ok(())
}
