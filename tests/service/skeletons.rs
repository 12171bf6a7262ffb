//! Skeleton takes: the hierarchy stored once and referenced, BVH served for any range, the
//! skeleton protected while referenced, and the same on both backends.

use mocapstore::motion::formats::{self, ReadOptions};
use mocapstore::motion::synthetic::dancer_bvh;

use crate::common::{self, start};

fn motion_rows(text: &str) -> Vec<String> {
    let at = text.find("Frame Time").unwrap();
    text[at..]
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect()
}

#[tokio::test]
async fn a_skeleton_is_stored_once_served_as_bvh_and_kept_while_referenced() {
    for t in common::all().await {
        let srv = start(t.store.clone(), 8 << 20).await;
        let a = dancer_bvh(500, 120.0, 1, 4);
        let b = dancer_bvh(300, 120.0, 2, 4);
        let mut ids = Vec::new();
        for (name, text) in [("a", &a), ("b", &b)] {
            let (status, report) = srv
                .post(
                    &format!("name={name}&codec=bvh-lossless"),
                    text.as_bytes().to_vec(),
                )
                .await;
            assert_eq!(status, 201, "{} {report}", t.name);
            assert_eq!(report["codec"], "bvh-lossless");
            assert_eq!(report["max_mm"], 0.0);
            ids.push(report["id"].as_str().unwrap().to_string());
        }
        // One skeleton, referenced by both takes.
        let (status, list) = srv.get_json("/v1/skeletons").await;
        assert_eq!(status, 200);
        let items = list["items"].as_array().unwrap();
        assert_eq!(items.len(), 1, "{list}");
        assert_eq!(items[0]["used_by"], 2);
        assert_eq!(items[0]["joints"], 24);
        let sk = items[0]["id"].as_str().unwrap().to_string();
        let (status, one) = srv.get_json(&format!("/v1/skeletons/{sk}")).await;
        assert_eq!(status, 200);
        assert_eq!(one["hierarchy"][1]["name"], "LeftUpLeg");
        // Its joints' roles, as its takes show them.
        assert_eq!(one["roles"]["roles"]["pelvis"], serde_json::json!(["Hips"]));
        assert_eq!(
            one["roles"]["roles"]["left_knee"],
            serde_json::json!(["LeftLeg"])
        );
        assert!(items[0].get("roles").is_none(), "a listing row has none");
        let (status, take) = srv.get_json(&format!("/v1/takes/{}", ids[0])).await;
        assert_eq!(status, 200);
        assert_eq!(take["skeleton"], sk.as_str());
        assert_eq!(take["meta"]["point_names"].as_array().unwrap().len(), 24);
        // What the disk pays: the container plus the row, reported beside it.
        let (stored, disk) = (
            take["stored_bytes"].as_u64().unwrap(),
            take["disk_bytes"].as_u64().unwrap(),
        );
        assert!(disk > stored && disk < stored + 2000, "{stored} {disk}");
        let (_, stats) = srv.get_json("/v1/stats").await;
        assert!(
            stats["total"]["disk_bytes"].as_u64().unwrap()
                > stats["total"]["stored_bytes"].as_u64().unwrap()
        );
        assert!(
            stats["total"]["disk_ratio"].as_f64().unwrap()
                < stats["total"]["ratio"].as_f64().unwrap()
        );

        // Any range as BVH: the uploaded rows, character for character; a range equals the
        // same rows of the whole take.
        let rows = motion_rows(&a);
        for (start, end) in [(0, 500), (0, 1), (17, 260), (499, 500)] {
            let (status, _, body) = srv
                .get(&format!(
                    "/v1/takes/{}/frames?start={start}&end={end}&format=bvh",
                    ids[0]
                ))
                .await;
            assert_eq!(status, 200);
            let text = String::from_utf8(body.clone()).unwrap();
            assert_eq!(motion_rows(&text), rows[start..end]);
            let served = formats::read(&body, &ReadOptions::default())
                .unwrap()
                .motion;
            assert_eq!(served.frame_count(), end - start);
        }
        let (status, _, _) = srv
            .get(&format!(
                "/v1/takes/{}/frames?format=bvh&points=Hips",
                ids[0]
            ))
            .await;
        assert_eq!(status, 400);

        // Protected while referenced; deletable once no take uses it.
        assert_eq!(srv.delete(&format!("/v1/skeletons/{sk}")).await, 409);
        for id in &ids {
            assert_eq!(srv.delete(&format!("/v1/takes/{id}")).await, 204);
        }
        assert_eq!(srv.delete(&format!("/v1/skeletons/{sk}")).await, 204);
        assert_eq!(srv.delete(&format!("/v1/skeletons/{sk}")).await, 404);

        // keep=positions lets position codecs compete; such a take says why it has no BVH.
        let (status, report) = srv
            .post("keep=positions&max_error_mm=5", a.as_bytes().to_vec())
            .await;
        assert_eq!(status, 201, "{report}");
        let id = report["id"].as_str().unwrap();
        if report["codec"] != "bvh-lossless" {
            let (status, _, body) = srv.get(&format!("/v1/takes/{id}/frames?format=bvh")).await;
            assert_eq!(status, 409);
            let msg = String::from_utf8_lossy(&body);
            assert!(msg.contains("bvh-lossless"), "{msg}");
        }
        assert_eq!(report["decision"]["keep"], "positions");
        srv.stop().await;
        t.finish().await;
    }
}

/// A take coded by `pga` comes back as BVH of its skeleton within its bound, any range the
/// same rows as the whole; a take without a skeleton is refused with the reason.
#[tokio::test]
async fn a_pga_take_is_served_as_bvh_within_its_bound() {
    for t in common::all().await {
        let srv = start(t.store.clone(), 8 << 20).await;
        let text = dancer_bvh(400, 120.0, 3, 4);
        let original = formats::read(text.as_bytes(), &ReadOptions::default())
            .unwrap()
            .motion;
        let (status, report) = srv
            .post("name=p&codec=pga&max_error_mm=5", text.as_bytes().to_vec())
            .await;
        assert_eq!(status, 201, "{} {report}", t.name);
        assert_eq!(report["codec"], "pga");
        assert!(report["max_mm"].as_f64().unwrap() <= 5.0, "{report}");
        let id = report["id"].as_str().unwrap();
        let (status, _, body) = srv.get(&format!("/v1/takes/{id}/frames?format=bvh")).await;
        assert_eq!(status, 200);
        let served = formats::read(&body, &ReadOptions::default())
            .unwrap()
            .motion;
        assert_eq!(
            served.skeleton.as_ref().unwrap().joints,
            original.skeleton.as_ref().unwrap().joints
        );
        let max = served_max_mm(&original, &served);
        assert!(max <= 5.0, "{}: served BVH max {max} mm", t.name);
        let whole = motion_rows(&String::from_utf8_lossy(&body));
        let (status, _, part) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?format=bvh&start=37&end=211"
            ))
            .await;
        assert_eq!(status, 200);
        assert_eq!(motion_rows(&String::from_utf8_lossy(&part)), whole[37..211]);
        let points = formats::write(
            &mocapstore::motion::synthetic::walker(60, 4, 60.0, 1, 0.0),
            formats::Format::Json,
        )
        .unwrap();
        let (status, report) = srv.post("name=q&codec=pga", points).await;
        assert!((400..500).contains(&status), "{status} {report}");
        assert!(report["error"].to_string().contains("skeleton"), "{report}");
        srv.stop().await;
        t.finish().await;
    }
}

/// The largest distance (mm) between a served take's FK positions and the original's.
fn served_max_mm(
    original: &mocapstore::motion::Motion,
    served: &mocapstore::motion::Motion,
) -> f64 {
    mocapstore::motion::metrics::compare(
        original.positions(),
        served.positions(),
        original.point_count(),
        original.unit.to_mm(),
    )
    .unwrap()
    .max_mm
}

/// The BVH rows of a file, whitespace normalised.
fn rows_of(text: &str) -> Vec<String> {
    motion_rows(text)
        .iter()
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect()
}

/// Every BVH file of the corpus, ingested with defaults, comes back as BVH: the same
/// hierarchy and frame count read by this project's reader and by an independent one
/// (`bvh_anim`), the values as uploaded (`bvh-lossless`, compared by both readers) or FK
/// positions within the bound (`rot`), and a range equal to the same rows of the whole take.
#[tokio::test]
async fn every_corpus_bvh_comes_back_as_bvh() {
    let Some((root, entries)) = mocapstore::corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = start(t.store.clone(), 64 << 20).await;
    let (mut checked, mut faulty, mut codecs) = (
        0,
        std::collections::BTreeSet::new(),
        std::collections::BTreeMap::new(),
    );
    for e in entries.iter().filter(|e| e.path.ends_with(".bvh")) {
        let bytes = std::fs::read(root.join(&e.path)).unwrap();
        let Ok(original) = formats::read(&bytes, &ReadOptions::default()) else {
            continue; // refused files are the manifest test's business
        };
        let original = original.motion;
        // With defaults (the smallest codec that keeps the animation), and lossless.
        for query in ["name=corpus", "name=corpus&codec=bvh-lossless"] {
            let (status, report) = srv.post(query, bytes.clone()).await;
            assert_eq!(status, 201, "{}: {report}", e.path);
            let id = report["id"].as_str().unwrap();
            let codec = report["codec"].as_str().unwrap().to_string();
            let (status, _, body) = srv.get(&format!("/v1/takes/{id}/frames?format=bvh")).await;
            assert_eq!(status, 200, "{}", e.path);
            let served = formats::read(&body, &ReadOptions::default())
                .unwrap_or_else(|err| panic!("{}: served BVH: {err}", e.path))
                .motion;
            let (a, b) = (
                original.skeleton.as_ref().unwrap(),
                served.skeleton.as_ref().unwrap(),
            );
            assert_eq!(a.joints, b.joints, "{}: hierarchy", e.path);
            assert_eq!(original.frame_count(), served.frame_count(), "{}", e.path);
            // The independent reader agrees on the served file's joints and frames.
            let other = bvh_anim::from_bytes(&body)
                .unwrap_or_else(|err| panic!("{}: bvh_anim: {err}", e.path));
            assert_eq!(other.joints().count(), a.joint_count(), "{}", e.path);
            assert_eq!(other.frames().count(), original.frame_count(), "{}", e.path);
            let text = String::from_utf8_lossy(&body).to_string();
            let uploaded = String::from_utf8_lossy(&bytes).to_string();
            match codec.as_str() {
                "bvh-lossless" => {
                    assert_eq!(rows_of(&text), rows_of(&uploaded), "{}", e.path);
                    let values = |b: &bvh_anim::Bvh| -> Vec<f32> {
                        b.frames().flat_map(|f| f.as_slice().to_vec()).collect()
                    };
                    let theirs = match bvh_anim::from_bytes(&bytes) {
                        Ok(b) => values(&b),
                        // bvh_anim refuses only what the manifest's reference parser
                        // refused too (a header that miscounts its frames); the upload's
                        // rows, as numbers, stand in for it there.
                        Err(err) => {
                            assert_eq!(e.reference_ok, Some(false), "{}: bvh_anim: {err}", e.path);
                            faulty.insert(e.path.clone());
                            rows_of(&uploaded)
                                .iter()
                                .flat_map(|r| r.split(' ').map(|t| t.parse::<f32>().unwrap()))
                                .collect()
                        }
                    };
                    assert_eq!(values(&other), theirs, "{}", e.path);
                }
                "rot" | "pga" => {
                    let max = served_max_mm(&original, &served);
                    assert!(max <= 1.0, "{}: max {max} mm", e.path);
                }
                other => panic!("{}: {other} does not keep the animation", e.path),
            }
            // A range: the same rows as the whole.
            let n = original.frame_count();
            let (lo, hi) = (n / 3, (n / 3 + 50).min(n));
            let (status, _, part) = srv
                .get(&format!(
                    "/v1/takes/{id}/frames?format=bvh&start={lo}&end={hi}"
                ))
                .await;
            assert_eq!(status, 200);
            assert_eq!(
                rows_of(&String::from_utf8_lossy(&part)),
                rows_of(&text)[lo..hi],
                "{}",
                e.path
            );
            *codecs.entry(codec).or_insert(0) += 1;
        }
        checked += 1;
    }
    assert!(checked >= 180, "{checked} BVH files checked");
    assert!(faulty.len() <= 1, "bvh_anim could not read {faulty:?}");
    println!(
        "{checked} corpus BVH files served as BVH: {codecs:?}; faulty headers, compared by \
         their rows: {faulty:?}"
    );
    srv.stop().await;
    t.finish().await;
}
