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

/// Labels on every backend: given at ingest (a query, a header, a JSON take's own, the
/// query over the file's), changed by PATCH (set, removed, the rest kept), found by
/// `label.<key>=` in listings, statistics and exports (numbers by value), written in the
/// export's manifest; what cannot be a label is a 400 that changes nothing.
#[tokio::test]
async fn labels_are_given_changed_and_found() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        let take = |seed: u64| {
            let m = walker(40, 4, 120.0, seed, 0.0);
            formats::write(&m, Format::Json).unwrap()
        };
        let (status, a) = srv
            .post(
                "name=a&library=lab&labels=content:walk,style:happy,n:1",
                take(1),
            )
            .await;
        assert_eq!(status, 201, "{a}");
        let a = a["id"].as_str().unwrap().to_string();
        // A JSON take's own labels, and the query's over them.
        let mut doc: Value = serde_json::from_slice(&take(2)).unwrap();
        doc["labels"] = serde_json::json!({"content": "run", "subject": {"id": 7}});
        let (status, b) = srv
            .post(
                "name=b&library=lab&labels=%7B%22content%22%3A%22jog%22%7D",
                doc.to_string().into_bytes(),
            )
            .await;
        assert_eq!(status, 201, "{b}");
        let b = b["id"].as_str().unwrap().to_string();
        // A header.
        let r = srv
            .client
            .post(format!("{}/v1/takes?name=c&library=lab", srv.base))
            .header("x-mocap-labels", "content:walk,style:sad")
            .body(take(3))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), 201);
        let (_, got) = json(&srv, &format!("/v1/takes/{a}")).await;
        assert_eq!(
            got["labels"],
            serde_json::json!({"content": "walk", "style": "happy", "n": 1}),
            "{got}"
        );
        let (_, got) = json(&srv, &format!("/v1/takes/{b}")).await;
        assert_eq!(
            got["labels"],
            serde_json::json!({"content": "jog", "subject.id": 7}),
            "{got}"
        );

        let names = |page: &Value| -> BTreeSet<String> {
            page["items"]
                .as_array()
                .unwrap()
                .iter()
                .map(|t| t["name"].as_str().unwrap().to_string())
                .collect()
        };
        let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
        let (_, page) = json(&srv, "/v1/takes?label.content=walk").await;
        assert_eq!(names(&page), set(&["a", "c"]));
        let (_, page) = json(&srv, "/v1/takes?label.content=walk&label.style=sad").await;
        assert_eq!(names(&page), set(&["c"]));
        let (_, page) = json(&srv, "/v1/takes?label.n=1.0&library=lab").await;
        assert_eq!(names(&page), set(&["a"]), "numbers by value");
        let (_, page) = json(&srv, "/v1/takes?label.subject.id=7").await;
        assert_eq!(names(&page), set(&["b"]));
        let (_, stats) = json(&srv, "/v1/stats?label.content=walk").await;
        assert_eq!(stats["total"]["takes"], 2, "{stats}");

        // PATCH: set, remove, keep.
        let patch = |id: String, body: Value| {
            let (client, base) = (srv.client.clone(), srv.base.clone());
            async move {
                let r = client
                    .patch(format!("{base}/v1/takes/{id}"))
                    .json(&body)
                    .send()
                    .await
                    .unwrap();
                (r.status().as_u16(), r.json::<Value>().await.unwrap())
            }
        };
        let (status, got) = patch(
            a.clone(),
            serde_json::json!({"labels": {"style": null, "take": 3}}),
        )
        .await;
        assert_eq!(status, 200, "{got}");
        assert_eq!(
            got["labels"],
            serde_json::json!({"content": "walk", "n": 1, "take": 3})
        );
        // Refused, naming why; nothing changed, the rest of the PATCH included.
        for (bad, why) in [
            (serde_json::json!({"labels": {"a b": 1}}), "a b"),
            (serde_json::json!({"labels": {"k": [1]}}), "list"),
            (serde_json::json!({"labels": {"k": ""}}), "1 to"),
            (serde_json::json!({"labels": ["k"]}), "object"),
            (
                serde_json::json!({"name": "renamed", "labels": {"k": "x".repeat(300)}}),
                "256",
            ),
        ] {
            let (status, err) = patch(a.clone(), bad.clone()).await;
            assert_eq!(status, 400, "{bad}: {err}");
            assert!(err.to_string().contains(why), "{bad}: {err}");
        }
        let too_many: serde_json::Map<String, Value> =
            (0..70).map(|i| (format!("k{i}"), Value::from(i))).collect();
        let (status, err) = patch(a.clone(), serde_json::json!({ "labels": too_many })).await;
        assert_eq!(status, 400, "{err}");
        let (_, got) = json(&srv, &format!("/v1/takes/{a}")).await;
        assert_eq!(got["name"], "a");
        assert_eq!(got["labels"]["take"], 3);
        for bad in ["labels=content", "labels=a%20b:1", "labels=%5B1%5D"] {
            let (status, err) = srv.post(&format!("name=x&{bad}"), take(4)).await;
            assert_eq!(status, 400, "{bad}: {err}");
        }
        let (status, err) = json(&srv, "/v1/takes?label.a%20b=1").await;
        assert_eq!(status, 400, "{err}");

        // The export's manifest carries them; its label filter picks the takes.
        let (status, _, zip) = srv
            .get("/v1/export?library=lab&label.content=walk&format=json")
            .await;
        assert_eq!(status, 200);
        let mut archive = zip::ZipArchive::new(std::io::Cursor::new(zip)).unwrap();
        let mut manifest = String::new();
        std::io::Read::read_to_string(&mut archive.by_name("manifest.csv").unwrap(), &mut manifest)
            .unwrap();
        let lines: Vec<&str> = manifest.lines().collect();
        assert!(
            lines[0].starts_with("file,id,name,library,tags,labels,"),
            "{manifest}"
        );
        assert_eq!(lines.len(), 3, "{manifest}");
        assert!(
            manifest.contains(r#""{""content"":""walk"",""n"":1,""take"":3}""#),
            "{manifest}"
        );
        srv.stop().await;
        t.finish().await;
    }
}

/// `GET /v1/stats` says where the database's bytes go: every table and index by what it
/// holds, adding up to the database's size, with the chunk payloads among the motion.
// Multi-threaded: the CLI's process asks the server while this test waits for it.
#[tokio::test(flavor = "multi_thread")]
async fn the_databases_bytes_are_split_by_what_they_hold() {
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 8 << 20).await;
        for i in 0..3u64 {
            let m = walker(300, 8, 120.0, i + 1, 0.0);
            let body = formats::write(&m, Format::Json).unwrap();
            let (status, r) = srv.post(&format!("name=bytes{i}"), body).await;
            assert_eq!(status, 201, "{r}");
        }
        let (status, stats) = json(&srv, "/v1/stats").await;
        assert_eq!(status, 200, "{stats}");
        let s = &stats["storage"];
        let objects = s["objects"].as_array().unwrap();
        let find = |name: &str| objects.iter().find(|o| o["name"] == name).cloned();
        let chunks = find("chunks").unwrap_or_else(|| panic!("{}: {s}", t.name));
        assert_eq!(chunks["holds"], "motion");
        assert_eq!(find("takes").unwrap()["holds"], "records");
        // The chunk table's pages hold at least the payloads (SQLite does not compress).
        let payload: i64 = stats["total"]["stored_bytes"].as_i64().unwrap();
        let sum = |holds: &str| -> i64 {
            objects
                .iter()
                .filter(|o| o["holds"] == holds)
                .map(|o| o["bytes"].as_i64().unwrap())
                .sum()
        };
        assert_eq!(s["motion_bytes"].as_i64().unwrap(), sum("motion"));
        assert_eq!(s["record_bytes"].as_i64().unwrap(), sum("records"));
        assert_eq!(s["index_bytes"].as_i64().unwrap(), sum("indexes"));
        let indexes = objects.iter().filter(|o| o["holds"] == "indexes");
        assert!(
            indexes.clone().any(|o| o["table"] == "takes"),
            "{}: the takes' indexes are named with their table: {s}",
            t.name
        );
        let total = s["total_bytes"].as_i64().unwrap();
        let all = sum("motion") + sum("records") + sum("indexes");
        if t.name == "sqlite" {
            assert!(chunks["bytes"].as_i64().unwrap() >= payload / 2, "{s}");
            assert!(chunks["unused_bytes"].as_i64().unwrap() >= 0);
            // Every page is a table's, an index's or free.
            assert_eq!(all + s["free_bytes"].as_i64().unwrap(), total, "{s}");
        } else {
            assert!(s["free_bytes"].is_null(), "{s}");
            assert_eq!(all, total, "{s}");
        }
        // The CLI prints the same split.
        let (ok, out, err) = common::mocapstore(&["stats", "--server", &srv.base]);
        assert!(ok, "{err}");
        let motion = format!("| motion | {} |", s["motion_bytes"]);
        assert!(
            out.contains(&motion) && out.contains("| chunks | motion |"),
            "{out}"
        );
        srv.stop().await;
        t.finish().await;
    }
}
