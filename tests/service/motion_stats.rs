//! Normalisation statistics of a library's motion (issue 50): `/v1/motion-stats` gives, per
//! layout (or per body role), the mean and spread of positions and velocities of exactly
//! the frames the range answers give with the same transforms, reads each take once and
//! keeps it (read again when the take changes), answers the same on two servers of one
//! database, and sees only the token's libraries.

use crate::common;

use serde_json::{json, Value};

use mocapstore::corpus;
use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;

/// The transforms every request here asks: what a model is trained on.
const SHAPE: &str = "fps=30&unit=m&up=y&root=in-place";

/// A take's frames as the range answer gives them with [`SHAPE`]: (frames, points × 3).
async fn frames(srv: &common::Server, id: &str, extra: &str) -> Vec<Vec<f64>> {
    let (status, headers, body) = srv
        .get(&format!("/v1/takes/{id}/frames?format=f32&{SHAPE}{extra}"))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let points: usize = headers["x-points"].to_str().unwrap().parse().unwrap();
    let values: Vec<f64> = body
        .chunks_exact(4)
        .map(|b| f64::from(f32::from_le_bytes(b.try_into().unwrap())))
        .collect();
    values.chunks(points * 3).map(<[f64]>::to_vec).collect()
}

/// Mean and population std of each column over frames, two passes, NaN left out; and of
/// the column's differences between consecutive frames times `fps`.
fn direct(takes: &[Vec<Vec<f64>>], fps: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let width = takes[0][0].len();
    let moments = |values: &dyn Fn(usize) -> Vec<f64>| -> (Vec<f64>, Vec<f64>) {
        (0..width)
            .map(|c| {
                let v = values(c);
                let n = v.len() as f64;
                let mean = v.iter().sum::<f64>() / n;
                let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
                (mean, var.sqrt())
            })
            .unzip()
    };
    let (mean, std) = moments(&|c| {
        takes
            .iter()
            .flatten()
            .map(|f| f[c])
            .filter(|v| !v.is_nan())
            .collect()
    });
    let (vmean, vstd) = moments(&|c| {
        takes
            .iter()
            .flat_map(|t| t.windows(2).map(|w| (w[1][c] - w[0][c]) * fps))
            .filter(|v| !v.is_nan())
            .collect()
    });
    (mean, std, vmean, vstd)
}

fn column(v: &Value, key: &str) -> Vec<f64> {
    v[key]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|p| p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        .collect()
}

fn close(ours: &[f64], theirs: &[f64], what: &str) {
    assert_eq!(ours.len(), theirs.len(), "{what}");
    for (i, (a, b)) in ours.iter().zip(theirs).enumerate() {
        assert!(
            (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
            "{what}[{i}]: {a} against {b} from the frames"
        );
    }
}

async fn ingest(srv: &common::Server, query: &str, body: Vec<u8>) -> String {
    let (status, v) = srv.post(query, body).await;
    assert_eq!(status, 201, "{query}: {v}");
    v["id"].as_str().unwrap().to_string()
}

/// Two layouts (two Bandai takes of one rig, a CMU take of another) and a take in another
/// library: per-layout statistics equal to those of the frames the range answers give,
/// kept and read again only for what changed, the same from a second server of the same
/// database; roles give every rig one layout, equal to the centroids of the roles' points.
#[tokio::test(flavor = "multi_thread")]
async fn motion_stats_are_those_of_the_frames_a_client_reads() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    for t in common::all().await {
        let one = common::start(t.store.clone(), 64 << 20).await;
        let two = common::start(t.store.clone(), 64 << 20).await;
        let bvh = |rel: &str| std::fs::read(root.join("bvh").join(rel)).unwrap();
        let walk = "bandai/dataset-1_walk_active_001.bvh";
        let bow = "bandai/dataset-1_bow_active_001.bvh";
        let a = ingest(&one, "name=walk&library=lab&codec=rot", bvh(walk)).await;
        let b = ingest(&one, "name=bow&library=lab&codec=rot", bvh(bow)).await;
        let c = ingest(&one, "name=cmu&library=lab&codec=rot", bvh("cmu/01_01.bvh")).await;
        ingest(&one, "name=elsewhere&library=other&codec=rot", bvh(bow)).await;

        let path = format!("/v1/motion-stats?library=lab&{SHAPE}");
        let (status, first) = one.get_json(&path).await;
        assert_eq!(status, 200, "{first}");
        assert_eq!(first["takes"], 3, "{first}");
        assert_eq!(first["read"], 3);
        let groups = first["groups"].as_array().unwrap();
        assert_eq!(groups.len(), 2, "two rigs, two layouts");
        let bandai = groups
            .iter()
            .find(|g| g["takes"] == 2)
            .expect("the Bandai rig");
        let cmu = groups
            .iter()
            .find(|g| g["takes"] == 1)
            .expect("the CMU rig");
        for (g, ids) in [(bandai, vec![&a, &b]), (cmu, vec![&c])] {
            let mut takes = Vec::new();
            for id in ids {
                takes.push(frames(&one, id, "").await);
            }
            let frames_in: usize = takes.iter().map(Vec::len).sum();
            assert_eq!(g["frames"], frames_in);
            assert_eq!(g["metres_per_unit"], 1.0);
            let (mean, std, vmean, vstd) = direct(&takes, 30.0);
            close(&column(g, "mean"), &mean, "mean");
            close(&column(g, "std"), &std, "std");
            close(&column(g, "velocity_mean"), &vmean, "velocity_mean");
            close(&column(g, "velocity_std"), &vstd, "velocity_std");
            // Heights in metres of a standing person, up y: the transforms were applied.
            let heights: Vec<f64> = column(g, "mean")
                .iter()
                .skip(1)
                .step_by(3)
                .copied()
                .collect();
            assert!(
                heights.iter().all(|h| (-0.1..2.2).contains(h)),
                "{heights:?}"
            );
        }

        // Kept: asked again, nothing is read, and the numbers are the same.
        let (_, again) = one.get_json(&path).await;
        assert_eq!(again["read"], 0);
        assert_eq!(again["groups"], first["groups"]);
        // Another server of the same database: the same numbers, to the bit.
        let (_, other) = two.get_json(&path).await;
        assert_eq!(other["read"], 3);
        assert_eq!(other["groups"], first["groups"]);

        // A take added is read alone; a take deleted (through the other server) is left out.
        let d = ingest(&one, "name=walk2&library=lab&codec=raw", bvh(walk)).await;
        let (_, grown) = one.get_json(&path).await;
        assert_eq!(
            (grown["read"].as_u64(), grown["takes"].as_u64()),
            (Some(1), Some(4))
        );
        assert_eq!(two.delete(&format!("/v1/takes/{d}")).await, 204);
        assert_eq!(two.delete(&format!("/v1/takes/{c}")).await, 204);
        let (_, shrunk) = one.get_json(&path).await;
        assert_eq!(shrunk["takes"], 2);
        assert_eq!(shrunk["read"], 0);
        assert_eq!(&shrunk["groups"][0], bandai);

        // By roles: one layout of the 20 roles, each the centroid of the points the take's
        // body places in it.
        let cmu_again = ingest(&one, "name=cmu&library=lab&codec=rot", bvh("cmu/01_01.bvh")).await;
        let (status, roles) = one.get_json(&format!("{path}&by=roles")).await;
        assert_eq!(status, 200, "{roles}");
        assert_eq!(roles["groups"].as_array().unwrap().len(), 1, "{roles}");
        let g = &roles["groups"][0];
        assert_eq!(g["takes"], 3);
        let names: Vec<&str> = common::strings(&g["points"]);
        assert_eq!(names.len(), 20);
        assert_eq!(names[0], "pelvis");
        let mut takes = Vec::new();
        for id in [&a, &b, &cmu_again] {
            let (_, record) = one.get_json(&format!("/v1/takes/{id}")).await;
            let points = common::strings(&record["meta"]["point_names"]);
            let placed = &record["body"]["roles"];
            let by_role: Vec<Vec<usize>> = names
                .iter()
                .map(|r| {
                    placed[*r]
                        .as_array()
                        .map(|ns| {
                            ns.iter()
                                .map(|n| points.iter().position(|p| p == &n.as_str().unwrap()))
                                .map(Option::unwrap)
                                .collect()
                        })
                        .unwrap_or_default()
                })
                .collect();
            let centroids: Vec<Vec<f64>> = frames(&one, id, "")
                .await
                .iter()
                .map(|f| {
                    by_role
                        .iter()
                        .flat_map(|idx| {
                            (0..3).map(move |k| {
                                if idx.is_empty() {
                                    f64::NAN
                                } else {
                                    idx.iter().map(|p| f[p * 3 + k]).sum::<f64>() / idx.len() as f64
                                }
                            })
                        })
                        .collect()
                })
                .collect();
            takes.push(centroids);
        }
        let (mean, std, vmean, vstd) = direct(&takes, 30.0);
        let present: Vec<u64> = g["present"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        for (r, n) in present.iter().enumerate() {
            if *n == 0 {
                continue; // a role no take places: its numbers are 0, the direct ones NaN
            }
            let at = r * 3..r * 3 + 3;
            close(&column(g, "mean")[at.clone()], &mean[at.clone()], names[r]);
            close(&column(g, "std")[at.clone()], &std[at.clone()], names[r]);
            close(
                &column(g, "velocity_mean")[at.clone()],
                &vmean[at.clone()],
                names[r],
            );
            close(&column(g, "velocity_std")[at.clone()], &vstd[at], names[r]);
        }
        assert!(present[0] > 0, "every take places its pelvis");

        one.stop().await;
        two.stop().await;
        t.finish().await;
    }
}

/// Takes named by id (a training split), points named, what cannot be answered refused
/// with why, takes that lack what is asked listed as skipped, and a library-limited token's
/// answer unchanged by what other libraries hold.
#[tokio::test(flavor = "multi_thread")]
async fn motion_stats_of_named_takes_points_and_libraries() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 16 << 20).await;
    let json_take = |frames, points, seed| {
        formats::write(&walker(frames, points, 60.0, seed, 0.0), Format::Json).unwrap()
    };
    let a = ingest(&srv, "name=a&library=lab&unit=mm", json_take(120, 6, 1)).await;
    let b = ingest(&srv, "name=b&library=lab&unit=mm", json_take(90, 6, 2)).await;
    let c = ingest(&srv, "name=c&library=lab&unit=mm", json_take(90, 4, 3)).await;

    // By id: the takes named, as one layout; the same as the listing's filter on one take.
    let (status, _, by_ids) = srv
        .post_json("/v1/motion-stats", &json!({"ids": [a, b], "unit": "m"}))
        .await;
    assert_eq!(status, 200, "{by_ids}");
    assert_eq!(by_ids["takes"], 2);
    assert_eq!(by_ids["groups"].as_array().unwrap().len(), 1);
    assert_eq!(by_ids["groups"][0]["frames"], 210);
    let (_, _, one) = srv
        .post_json("/v1/motion-stats", &json!({"ids": [c]}))
        .await;
    let (_, listed) = srv.get_json("/v1/motion-stats?name_prefix=c").await;
    assert_eq!(one["groups"], listed["groups"]);
    assert_eq!(
        one["groups"][0]["metres_per_unit"], 0.001,
        "the take's own unit"
    );

    // The same points of every take: one group; a take without them is skipped, and says
    // which points it has.
    let (_, named) = srv
        .get_json("/v1/motion-stats?library=lab&points=M5,M0")
        .await;
    assert_eq!(named["takes"], 2, "{named}");
    assert_eq!(common::strings(&named["groups"][0]["points"]), ["M5", "M0"]);
    assert_eq!(named["skipped_count"], 1);
    assert_eq!(named["skipped"][0]["id"], c.as_str());
    let why = named["skipped"][0]["reason"].as_str().unwrap();
    assert!(
        why.contains("M5") && why.contains("M3"),
        "the reason lists the take's points: {why}"
    );
    // What each take gave is kept, a skip too: asked again, nothing is read.
    let (_, again) = srv
        .get_json("/v1/motion-stats?library=lab&points=M5,M0")
        .await;
    assert_eq!(
        (again["read"].as_u64(), again["skipped_count"].as_u64()),
        (Some(0), Some(1))
    );

    // A take still being streamed is left out, and says why; once finished, it counts.
    let (status, _, live) = srv
        .post_json(
            "/v1/streams",
            &json!({"name": "live", "library": "lab", "fps": 60.0, "points": 6, "unit": "mm"}),
        )
        .await;
    assert_eq!(status, 201, "{live}");
    let live = live["id"].as_str().unwrap().to_string();
    let frames: Vec<u8> = walker(60, 6, 60.0, 4, 0.0)
        .positions()
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let r = srv
        .client
        .post(format!("{}/v1/streams/{live}/frames?flush=true", srv.base))
        .header("content-type", "application/octet-stream")
        .body(frames)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let (_, streaming) = srv.get_json("/v1/motion-stats?library=lab").await;
    assert_eq!(streaming["takes"], 3, "{streaming}");
    let skipped = &streaming["skipped"][0];
    assert_eq!(skipped["id"], live.as_str());
    assert!(
        skipped["reason"].as_str().unwrap().contains("streamed"),
        "{skipped}"
    );
    let (status, _, _) = srv
        .post_json(&format!("/v1/streams/{live}/finish"), &json!({}))
        .await;
    assert_eq!(status, 200);
    let (_, finished) = srv.get_json("/v1/motion-stats?library=lab").await;
    assert_eq!(
        (finished["takes"].as_u64(), finished["read"].as_u64()),
        (Some(4), Some(1))
    );
    assert_eq!(srv.delete(&format!("/v1/takes/{live}")).await, 204);

    // Refused, with why.
    for (query, says) in [
        ("by=roles&points=M0", "leave out points"),
        ("by=roles&root=extract", "root=in-place"),
        ("by=joints", "points or roles"),
        ("fps=0", "fps"),
        ("points=M0,M0", "named twice"),
        ("points=M0,,M1", "empty name"),
        ("ids=a,b", "POST"),
    ] {
        let (status, v) = srv.get_json(&format!("/v1/motion-stats?{query}")).await;
        assert_eq!(status, 400, "{query}: {v}");
        assert!(v.to_string().contains(says), "{query}: {v}");
    }
    let (status, _, v) = srv
        .post_json("/v1/motion-stats", &json!({"ids": [a], "library": "lab"}))
        .await;
    assert_eq!(status, 400, "{v}");
    let (status, _, v) = srv
        .post_json("/v1/motion-stats", &json!({"ids": ["no-such-take"]}))
        .await;
    assert_eq!(status, 404, "{v}");
    let (status, _, v) = srv
        .post_json("/v1/motion-stats", &json!({"ids": [a], "colour": "red"}))
        .await;
    assert_eq!(status, 400, "an unknown field: {v}");
    srv.stop().await;
    t.finish().await;

    // A token of library "lab" only: the same answer whatever the other libraries hold; a
    // take of another library named by id is not found.
    let t = common::sqlite().await;
    let reader = common::token(&t.store, "reader", "read", Some(&["lab"])).await;
    let writer = common::token(&t.store, "writer", "write", None).await;
    let srv = common::start(t.store.clone(), 16 << 20).await;
    let put = |name: &'static str, library: &'static str, seed| {
        let (srv, writer) = (&srv, writer.clone());
        async move {
            let r = srv
                .client
                .post(format!(
                    "{}/v1/takes?name={name}&library={library}&unit=mm",
                    srv.base
                ))
                .bearer_auth(&writer)
                .body(json_take(60, 6, seed))
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 201);
            r.json::<Value>().await.unwrap()["id"]
                .as_str()
                .unwrap()
                .to_string()
        }
    };
    for (name, seed) in [("a", 1), ("b", 2), ("c", 3)] {
        put(name, "lab", seed).await;
    }
    let ask = |q: &'static str| {
        let (srv, reader) = (&srv, reader.clone());
        async move {
            let r = srv
                .client
                .get(format!("{}/v1/motion-stats{q}", srv.base))
                .bearer_auth(&reader)
                .send()
                .await
                .unwrap();
            (r.status().as_u16(), r.json::<Value>().await.unwrap())
        }
    };
    let (status, before) = ask("").await;
    assert_eq!(status, 200, "{before}");
    assert_eq!(before["takes"], 3);
    let hidden = put("hidden", "secret", 9).await;
    let (_, after) = ask("").await;
    assert_eq!(after["takes"], before["takes"]);
    assert_eq!(after["groups"], before["groups"]);
    let (_, other) = ask("?library=secret").await;
    assert_eq!(other["takes"], 0, "{other}");
    let r = srv
        .client
        .post(format!("{}/v1/motion-stats", srv.base))
        .bearer_auth(&reader)
        .json(&json!({"ids": [hidden]}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
    srv.stop().await;
    t.finish().await;
}
