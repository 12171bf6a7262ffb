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
