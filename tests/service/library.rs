//! Listings, pagination, filters, statistics and edits over HTTP, on every backend.

use crate::common;

use std::collections::BTreeSet;

use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use serde_json::Value;

async fn json(srv: &common::Server, path: &str) -> (u16, Value) {
    let (status, _, body) = srv.get(path).await;
    (status, serde_json::from_slice(&body).unwrap_or(Value::Null))
}

#[tokio::test]
async fn listings_pages_filters_stats_and_patches() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        // Ten short takes (under a second, so only raw and quant compete): two libraries,
        // tags on some, lengths 40..130 frames.
        let mut ids = Vec::new();
        for i in 0..10u64 {
            let m = walker(40 + 10 * i as usize, 5, 120.0, i + 1, 0.0);
            let body = formats::write(&m, Format::Json).unwrap();
            let library = if i % 2 == 0 { "even" } else { "odd" };
            let tags = if i % 3 == 0 { "&tags=third" } else { "" };
            let (status, r) = srv
                .post(&format!("name=take{i:02}&library={library}{tags}"), body)
                .await;
            assert_eq!(status, 201, "{r}");
            ids.push(r["id"].as_str().unwrap().to_string());
        }

        // Pages of 3, newest first, cover every take exactly once.
        let mut seen = Vec::new();
        let mut path = "/v1/takes?limit=3".to_string();
        loop {
            let (status, page) = json(&srv, &path).await;
            assert_eq!(status, 200, "{page}");
            let items = page["items"].as_array().unwrap();
            assert!(items.len() <= 3);
            seen.extend(items.iter().map(|s| s["id"].as_str().unwrap().to_string()));
            match page["next_cursor"].as_str() {
                Some(c) => path = format!("/v1/takes?limit=3&cursor={c}"),
                None => break,
            }
        }
        let mut newest_first = ids.clone();
        newest_first.reverse();
        assert_eq!(seen, newest_first, "{}", t.name);

        // Filters.
        let count = |v: &Value| v["items"].as_array().unwrap().len();
        assert_eq!(count(&json(&srv, "/v1/takes?library=even").await.1), 5);
        assert_eq!(count(&json(&srv, "/v1/takes?tag=third").await.1), 4);
        assert_eq!(count(&json(&srv, "/v1/takes?min_frames=100").await.1), 4);
        assert_eq!(
            count(&json(&srv, "/v1/takes?name_prefix=take0").await.1),
            10
        );
        assert_eq!(
            count(&json(&srv, "/v1/takes?library=odd&max_frames=70").await.1),
            2
        );
        assert_eq!(count(&json(&srv, "/v1/takes?fps=120&points=5").await.1), 10);
        assert_eq!(count(&json(&srv, "/v1/takes?codec=raw").await.1), 0);
        let (_, by_name) = json(&srv, "/v1/takes?sort=name&limit=500").await;
        let names: Vec<&str> = by_name["items"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["name"].as_str().unwrap())
            .collect();
        let mut sorted = names.clone();
        sorted.sort();
        assert_eq!(names, sorted);

        // Statistics add up to the listing.
        let (status, stats) = json(&srv, "/v1/stats").await;
        assert_eq!(status, 200);
        let items = by_name["items"].as_array().unwrap();
        let sum = |k: &str| items.iter().map(|s| s[k].as_i64().unwrap()).sum::<i64>();
        assert_eq!(stats["total"]["takes"], 10);
        assert_eq!(stats["total"]["frames"].as_i64().unwrap(), sum("frames"));
        assert_eq!(
            stats["total"]["stored_bytes"].as_i64().unwrap(),
            sum("stored_bytes")
        );
        let per_codec: i64 = stats["by_codec"]
            .as_object()
            .unwrap()
            .values()
            .map(|v| v["takes"].as_i64().unwrap())
            .sum();
        assert_eq!(per_codec, 10);
        assert_eq!(stats["by_library"]["even"]["takes"], 5);
        assert_eq!(
            json(&srv, "/v1/stats?library=odd").await.1["total"]["takes"],
            5
        );

        // Edits.
        let r = srv
            .client
            .patch(format!("{}/v1/takes/{}", srv.base, ids[1]))
            .json(&serde_json::json!({"name": "renamed", "tags": ["x", "x", " y "]}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), 200);
        let row: Value = r.json().await.unwrap();
        assert_eq!(
            (row["name"].as_str(), &row["tags"]),
            (Some("renamed"), &serde_json::json!(["x", "y"]))
        );
        assert_eq!(count(&json(&srv, "/v1/takes?tag=x").await.1), 1);

        // Bad requests.
        for path in [
            "/v1/takes?limit=0",
            "/v1/takes?limit=501",
            "/v1/takes?cursor=nothex",
            "/v1/takes?order=sideways",
            "/v1/takes?sort=colour",
            "/v1/takes?min_frames=many",
            // Conditions no take could meet because they are not values of their kind.
            "/v1/takes?codec=zip",
            "/v1/takes?min_duration_s=-1",
            "/v1/takes?fps=0",
            "/v1/takes?min_frames=-3",
            "/v1/stats?codec=zip",
            "/v1/export?codec=zip",
        ] {
            let (status, body) = json(&srv, path).await;
            assert_eq!(status, 400, "{path}: {body}");
            assert!(body["error"]["message"].is_string());
        }
        let (_, first) = json(&srv, "/v1/takes?limit=2").await;
        let c = first["next_cursor"].as_str().unwrap();
        assert_eq!(
            json(&srv, &format!("/v1/takes?sort=name&cursor={c}"))
                .await
                .0,
            400
        );
        for (id, body, want) in [
            ("nope", serde_json::json!({"name": "a"}), 404),
            (ids[0].as_str(), serde_json::json!({"colour": "red"}), 400),
            (ids[0].as_str(), serde_json::json!({"name": "  "}), 400),
        ] {
            let r = srv
                .client
                .patch(format!("{}/v1/takes/{id}", srv.base))
                .json(&body)
                .send()
                .await
                .unwrap();
            assert_eq!(r.status().as_u16(), want, "{body}");
        }
        let unique: BTreeSet<_> = seen.iter().collect();
        assert_eq!(unique.len(), 10);

        // The older name of the routes answers as /v1/takes does, every method.
        for path in [
            "/v1/takes?library=even".to_string(),
            format!("/v1/takes/{}", ids[1]),
            format!("/v1/takes/{}/frames?format=csv&start=0&end=5", ids[1]),
            format!("/v1/takes/{}/errors", ids[1]),
        ] {
            let older = path.replace("/v1/takes", "/v1/sequences");
            let (now, then) = (srv.get(&path).await, srv.get(&older).await);
            assert_eq!((now.0, &now.2), (then.0, &then.2), "{older}");
            assert_eq!(now.0, 200, "{path}");
        }
        let m = walker(50, 5, 120.0, 99, 0.0);
        let body = formats::write(&m, Format::Json).unwrap();
        let r = srv
            .client
            .post(format!("{}/v1/sequences?name=older&library=odd", srv.base))
            .body(body)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), 201);
        let id = r.json::<Value>().await.unwrap()["id"]
            .as_str()
            .unwrap()
            .to_string();
        let r = srv
            .client
            .patch(format!("{}/v1/sequences/{id}", srv.base))
            .json(&serde_json::json!({"tags": ["old"]}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), 200);
        assert_eq!(
            json(&srv, &format!("/v1/takes/{id}")).await.1["tags"][0],
            "old"
        );
        assert_eq!(srv.delete(&format!("/v1/sequences/{id}")).await, 204);
        assert_eq!(json(&srv, &format!("/v1/takes/{id}")).await.0, 404);
        srv.stop().await;
        t.finish().await;
    }
}
