//! Shared bases over HTTP, on every backend: training as a background job, listing, coding
//! takes with the basis, and the basis kept while takes reference it.

use crate::common;

use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::metrics;
use mocapstore::motion::synthetic::walker;
use serde_json::json;

use common::wait_for_job;

#[tokio::test]
async fn bases_train_in_the_background_code_takes_and_are_kept_while_used() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        for i in 0..4u64 {
            let m = walker(240, 8, 120.0, i + 1, 0.0);
            let (status, r) = srv
                .post(
                    &format!("library=lib&name=t{i}"),
                    formats::write(&m, Format::Json).unwrap(),
                )
                .await;
            assert_eq!(status, 201, "{r}");
        }
        let other = walker(240, 5, 120.0, 9, 0.0);
        let (status, _) = srv
            .post(
                "library=other",
                formats::write(&other, Format::Json).unwrap(),
            )
            .await;
        assert_eq!(status, 201);

        // Refused before any job starts: several layouts, nothing selected, unknown fields.
        for (body, why) in [
            (json!({}), "spans 2:"),
            (json!({"library": "none"}), "no takes"),
            (
                json!({"library": "lib", "kind": "mdtt-set", "k": [0]}),
                "1..=32",
            ),
        ] {
            let (status, _, r) = srv.post_json("/v1/bases", &body).await;
            assert_eq!(status, 400, "{body}: {r}");
            assert!(r["error"]["message"].as_str().unwrap().contains(why), "{r}");
        }
        let (status, _, r) = srv.post_json("/v1/bases", &json!({"colour": "red"})).await;
        assert_eq!(
            (status, r["error"]["code"].as_str()),
            (400, Some("bad_request"))
        );

        // Train on the library: 202, a job to poll, a basis at the end.
        let (status, location, job) = srv
            .post_json(
                "/v1/bases",
                &json!({"library": "lib", "max_iterations": 20}),
            )
            .await;
        assert_eq!(status, 202, "{job}");
        let location = location.expect("Location of the job");
        assert_eq!(
            location,
            format!("/v1/jobs/{}", job["id"].as_str().unwrap())
        );
        let done = wait_for_job(&srv, &location).await;
        assert_eq!(done["state"], "succeeded", "{done}");
        assert_eq!(done["progress"], 1.0);
        let id = done["result"]["id"].as_str().unwrap().to_string();
        assert_eq!(id.len(), 64, "content hash");

        let (status, list) = srv.get_json("/v1/bases").await;
        assert_eq!(status, 200);
        assert_eq!(list["items"].as_array().unwrap().len(), 1, "{list}");
        let (status, b) = srv.get_json(&format!("/v1/bases/{id}")).await;
        assert_eq!(status, 200, "{b}");
        assert_eq!(
            (b["kind"].as_str(), b["dims"].as_str()),
            (Some("lsdt"), Some("3×8×8"))
        );
        assert_eq!(b["provenance"]["takes"].as_array().unwrap().len(), 4);
        let objective: Vec<f64> = b["provenance"]["objective"]["x"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(
            objective.windows(2).all(|w| w[1] <= w[0] * (1.0 + 1e-12)),
            "{objective:?}"
        );
        assert_eq!(
            srv.get_json(&format!("/v1/bases?layout={}", "0".repeat(32)))
                .await
                .1["items"],
            json!([])
        );

        // A new take of the layout, coded with the basis on request; and `auto` now
        // considers the shared-basis codecs.
        let fresh = walker(300, 8, 120.0, 77, 0.0);
        let body = formats::write(&fresh, Format::Json).unwrap();
        let (status, r) = srv
            .post("codec=lsdt-clip&max_error_mm=1", body.clone())
            .await;
        assert_eq!(status, 201, "{r}");
        assert_eq!(r["codec"], "lsdt-clip");
        let clip_id = r["id"].as_str().unwrap().to_string();
        let (status, _, served) = srv
            .get(&format!("/v1/takes/{clip_id}/frames?format=f32"))
            .await;
        assert_eq!(status, 200);
        let served: Vec<f32> = served
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let s = metrics::compare(fresh.positions(), &served, 8, fresh.unit.to_mm()).unwrap();
        assert!(s.max_mm <= 1.0, "{}", s.max_mm);
        let (status, r) = srv.post("latency=frame", body).await;
        assert_eq!(status, 201, "{r}");
        let tried: Vec<&str> = r["decision"]["tried"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t["codec"].as_str().unwrap())
            .collect();
        assert!(tried.contains(&"lsdt-frame"), "{tried:?}");
        let auto_id = r["id"].as_str().unwrap().to_string();

        // MDTT's database mode: K shared bases, K chosen by total size; takes then code
        // with `mdtt-shared`.
        let (status, location, job) = srv
            .post_json(
                "/v1/bases",
                &json!({"library": "lib", "kind": "mdtt-set", "k": [1, 2]}),
            )
            .await;
        assert_eq!(status, 202, "{job}");
        let done = wait_for_job(&srv, &location.unwrap()).await;
        assert_eq!(done["state"], "succeeded", "{done}");
        let set = &done["result"];
        assert_eq!(set["kind"], "mdtt-set");
        assert_eq!(
            set["provenance"]["k_candidates"].as_array().unwrap().len(),
            2
        );
        let k = set["provenance"]["k"].as_u64().unwrap();
        assert_eq!(set["dims"], format!("{k}×24×24"));
        let (status, r) = srv
            .post(
                "codec=mdtt-shared&max_error_mm=0.5",
                formats::write(&fresh, Format::Json).unwrap(),
            )
            .await;
        assert_eq!(status, 201, "{r}");
        assert!(r["max_mm"].as_f64().unwrap() <= 0.5);
        let shared_id = r["id"].as_str().unwrap().to_string();
        let (_, _, served) = srv
            .get(&format!(
                "/v1/takes/{shared_id}/frames?start=17&end=250&format=f32"
            ))
            .await;
        let served: Vec<f32> = served
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let s = metrics::compare(&fresh.positions()[17 * 24..250 * 24], &served, 8, 1.0).unwrap();
        assert!(s.max_mm <= 0.5, "{}", s.max_mm);
        assert_eq!(srv.delete(&format!("/v1/takes/{shared_id}")).await, 204);

        // In use: 409, and nothing deleted. Unused again: 204.
        let (status, b) = srv.get_json(&format!("/v1/bases/{id}")).await;
        assert!(b["used_by"].as_i64().unwrap() >= 1, "{status} {b}");
        assert_eq!(srv.delete(&format!("/v1/bases/{id}")).await, 409);
        assert_eq!(srv.get_json(&format!("/v1/bases/{id}")).await.0, 200);
        assert_eq!(srv.delete(&format!("/v1/takes/{clip_id}")).await, 204);
        assert_eq!(srv.delete(&format!("/v1/takes/{auto_id}")).await, 204);
        assert_eq!(srv.delete(&format!("/v1/bases/{id}")).await, 204);
        assert_eq!(srv.delete(&format!("/v1/bases/{id}")).await, 404);
        assert_eq!(srv.get_json("/v1/jobs/nope").await.0, 404);
        srv.stop().await;
        t.finish().await;
    }
}
