//! Automatic choice learns from a layout's takes (`service::history`): after the first
//! takes, in which every candidate is encoded, the candidates that lost every one of them are
//! left out, and the decision record says so, with an estimate of their size.

use mocapstore::motion::synthetic::dancer_bvh;

use crate::common::{self, start};

#[tokio::test]
async fn candidates_that_always_lost_on_a_layout_are_left_out_and_recorded() {
    let t = common::sqlite().await;
    let srv = start(t.store.clone(), 8 << 20).await;
    let explored = mocapstore::service::history::MIN_EXPLORED;
    let mut last = serde_json::Value::Null;
    for seed in 0..=explored as u64 {
        let text = dancer_bvh(240, 120.0, seed, 4);
        let (status, report) = srv
            .post(&format!("name=d{seed}&max_error_mm=1"), text.into_bytes())
            .await;
        assert_eq!(status, 201, "{report}");
        let d = &report["decision"];
        if (seed as usize) < explored {
            assert!(d.get("pruned").is_none(), "take {seed} explores: {d}");
        }
        last = report;
    }
    let d = &last["decision"];
    let pruned = d["pruned"]
        .as_array()
        .expect("pruned candidates after the exploration");
    assert!(!pruned.is_empty());
    let tried: Vec<&str> = d["tried"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["codec"].as_str().unwrap())
        .collect();
    for p in pruned {
        let codec = p["codec"].as_str().unwrap();
        assert!(!tried.contains(&codec), "{codec} was pruned and tried");
        assert_eq!(p["beat_kept"], 0, "{p}");
        assert!(p["median_ratio"].as_f64().unwrap() > 1.0);
        assert!(p["estimated_bytes"].as_u64().unwrap() > last["stored_bytes"].as_u64().unwrap());
    }
    assert!(d["reason"].as_str().unwrap().contains("not encoded"));
    assert!(last["max_mm"].as_f64().unwrap() <= 1.0);
    srv.stop().await;
    t.finish().await;
}

/// A history says what usually loses, not what can be done without: where every candidate
/// it kept fails on a take, the ones it left out run after all, and the take is stored.
#[tokio::test]
async fn the_candidates_left_out_run_when_every_kept_one_fails() {
    use mocapstore::motion::formats::{self, Format};
    use mocapstore::motion::synthetic::walker;
    use mocapstore::motion::Motion;

    let t = common::sqlite().await;
    let srv = start(t.store.clone(), 8 << 20).await;
    // Three points 9 km from the origin, where f32 coordinates are 1 mm apart, held to 0.3 mm
    // (so each must come back exactly): spca codes them smallest every time (measured: 1,080–1,177 bytes against quant's 1,276–1,364, mdtt's 1,389–2,624
    // and raw's 1,431–1,644), so the history keeps spca alone.
    let take = |seed: u64| {
        let w = walker(240, 3, 120.0, seed, 0.0);
        let far: Vec<f32> = w.positions().iter().map(|v| v + 9e6).collect();
        let m = Motion::new(w.fps, w.unit, w.point_names.clone(), far, None).unwrap();
        (formats::write(&m, Format::Json).unwrap(), w.point_names)
    };
    use mocapstore::service::history::{EXPLORE_EVERY, MIN_EXPLORED as explored};
    // The two takes after the exploration are not explored again (every candidate would run).
    assert!((explored as u64..explored as u64 + 2).all(|seen| seen % EXPLORE_EVERY != 0));
    for seed in 0..explored as u64 {
        let (body, _) = take(seed);
        let (status, report) = srv
            .post(&format!("name=e{seed}&max_error_mm=0.3"), body)
            .await;
        assert_eq!(status, 201, "{report}");
        assert_eq!(report["codec"], "spca", "{report}");
    }
    let (body, _) = take(100);
    let (status, report) = srv.post("name=kept&max_error_mm=0.3", body).await;
    assert_eq!(status, 201, "{report}");
    let pruned: Vec<&str> = report["decision"]["pruned"]
        .as_array()
        .expect("candidates left out")
        .iter()
        .map(|p| p["codec"].as_str().unwrap())
        .collect();
    assert!(
        pruned.contains(&"quant") && pruned.contains(&"raw"),
        "{report}"
    );
    // Naming all three points as the torso leaves spca nothing to code: it fails.
    let (body, names) = take(101);
    let torso = names.join(",");
    let (status, report) = srv
        .post(
            &format!("name=fallback&max_error_mm=0.3&torso={torso}"),
            body,
        )
        .await;
    assert_eq!(status, 201, "{report}");
    let d = &report["decision"];
    let tried: Vec<(&str, bool)> = d["tried"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["codec"].as_str().unwrap(),
                t.get("error").is_some_and(|e| !e.is_null()),
            )
        })
        .collect();
    assert!(tried.contains(&("spca", true)), "{d}");
    for codec in pruned {
        assert!(
            tried.contains(&(codec, false)),
            "{codec} did not run after spca failed: {d}"
        );
    }
    assert_ne!(report["codec"], "spca");
    assert!(report["max_mm"].as_f64().unwrap() <= 0.3);
    // Stored whole, and readable.
    let id = report["id"].as_str().unwrap();
    let (status, _, _) = srv.get(&format!("/v1/takes/{id}/frames?format=json")).await;
    assert_eq!(status, 200);
    srv.stop().await;
    t.finish().await;
}
