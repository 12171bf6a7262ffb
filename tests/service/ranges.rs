//! `GET /v1/ranges`: a batch of ranges of several takes in one multipart answer, each part
//! the bytes and headers its own frames request gives; a batch that cannot be answered
//! whole is refused before any of it is written.

use crate::common;

use serde_json::{json, Value};

/// A take of `points` points and `frames` frames at 100 fps, wandering, with a gap (point
/// 1 missing over frames 20..30).
fn take_json(points: usize, frames: usize, seed: f64) -> Vec<u8> {
    let names: Vec<String> = (0..points).map(|p| format!("P{p}")).collect();
    let frames: Vec<Value> = (0..frames)
        .map(|f| {
            let t = f as f64 / 100.0;
            Value::Array(
                (0..points)
                    .map(|p| {
                        if p == 1 && (20..30).contains(&f) {
                            Value::Null
                        } else {
                            let a = seed + p as f64;
                            json!([
                                100.0 * (t + a).sin(),
                                50.0 * (2.0 * t + a).cos() + 900.0,
                                10.0 * p as f64 + t * 30.0
                            ])
                        }
                    })
                    .collect(),
            )
        })
        .collect();
    serde_json::to_vec(&json!({"fps": 100.0, "points": names, "frames": frames})).unwrap()
}

/// The parts of a multipart answer, split at its boundary lines (not by their lengths, as
/// the Python client reads them): each part's headers (lower-case names) and body.
/// A part's headers (lower-case names, in order) and its body.
type Part = (Vec<(String, String)>, Vec<u8>);

fn parts(content_type: &str, body: &[u8]) -> Vec<Part> {
    let boundary = content_type
        .strip_prefix("multipart/mixed; boundary=")
        .unwrap_or_else(|| panic!("not multipart/mixed: {content_type}"));
    let delim = format!("\r\n--{boundary}").into_bytes();
    let find = |from: usize, what: &[u8]| {
        body[from..]
            .windows(what.len())
            .position(|w| w == what)
            .map(|p| p + from)
    };
    let mut at = find(0, &delim).expect("a first boundary");
    assert_eq!(at, 0, "nothing before the first boundary");
    let mut out = Vec::new();
    loop {
        at += delim.len();
        if body[at..].starts_with(b"--\r\n") {
            assert_eq!(at + 4, body.len(), "nothing after the closing boundary");
            return out;
        }
        assert!(body[at..].starts_with(b"\r\n"));
        let head_end = find(at, b"\r\n\r\n").expect("a part's headers end");
        let headers = std::str::from_utf8(&body[at + 2..head_end])
            .unwrap()
            .split("\r\n")
            .map(|l| {
                let (k, v) = l.split_once(": ").unwrap();
                (k.to_ascii_lowercase(), v.to_string())
            })
            .collect();
        let next = find(head_end + 4, &delim).expect("a boundary after each part");
        out.push((headers, body[head_end + 4..next].to_vec()));
        at = next;
    }
}

fn header<'a>(headers: &'a [(String, String)], name: &str) -> &'a str {
    headers
        .iter()
        .find(|(k, _)| k == name)
        .map(|(_, v)| v.as_str())
        .unwrap_or_else(|| panic!("no {name} in {headers:?}"))
}

#[tokio::test(flavor = "multi_thread")]
async fn a_batch_is_each_range_as_its_own_request_gives_it() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let mut ids = Vec::new();
    for (points, frames, seed) in [(4, 300, 0.0), (6, 250, 1.0)] {
        // Points no convention names: their up is given, as a user would.
        let (status, report) = srv
            .post(
                "codec=quant&max_error_mm=0.5&unit=mm&up=y",
                take_json(points, frames, seed),
            )
            .await;
        assert_eq!(status, 201, "{report}");
        ids.push(report["id"].as_str().unwrap().to_string());
    }
    let (a, b) = (&ids[0], &ids[1]);
    // Across takes and chunks, overlapping, repeated, one over the gap; every transform.
    let ranges = [
        (a, 0, 40),
        (b, 10, 50),
        (a, 15, 35),
        (a, 150, 290),
        (b, 0, 40),
    ];
    let spec: Vec<String> = ranges
        .iter()
        .map(|(id, s, e)| format!("{id}:{s}-{e}"))
        .collect();
    for shared in [
        "format=f32",
        "format=npy&fps=30&unit=m&up=z",
        "points=P3,P1&fps=60",
    ] {
        let (status, h, body) = srv
            .get(&format!("/v1/ranges?ranges={}&{shared}", spec.join(",")))
            .await;
        assert_eq!(status, 200, "{shared}: {}", String::from_utf8_lossy(&body));
        let ct = h["content-type"].to_str().unwrap();
        let got = parts(ct, &body);
        assert_eq!(got.len(), ranges.len(), "{shared}");
        for ((id, s, e), (headers, part)) in ranges.iter().zip(&got) {
            let path = format!("/v1/takes/{id}/frames?start={s}&end={e}&{shared}");
            let path = if shared.contains("format=") {
                path
            } else {
                format!("{path}&format=f32")
            };
            let (status, one_h, one) = srv.get(&path).await;
            assert_eq!(status, 200);
            assert_eq!(part, &one, "{path}: the part's bytes are the range's");
            assert_eq!(header(headers, "x-take"), id.as_str());
            assert_eq!(header(headers, "x-sequence"), id.as_str(), "the older name");
            for name in [
                "content-type",
                "content-length",
                "x-frames",
                "x-start-frame",
                "x-fps",
                "x-source-fps",
                "x-points",
                "x-metres-per-unit",
            ] {
                assert_eq!(
                    header(headers, name),
                    one_h[name].to_str().unwrap(),
                    "{path}: {name}"
                );
            }
        }
    }
    // The gap comes back as NaN in the part, where the frames route has it.
    let (_, h, body) = srv
        .get(&format!("/v1/ranges?ranges={a}:18-32&points=P1"))
        .await;
    let got = parts(h["content-type"].to_str().unwrap(), &body);
    let values: Vec<f32> = got[0]
        .1
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(values.len(), 14 * 3);
    for (f, xyz) in values.chunks(3).enumerate() {
        assert_eq!(xyz[0].is_nan(), (2..12).contains(&f), "frame {}", 18 + f);
    }
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread")]
async fn a_batch_that_cannot_be_answered_whole_is_refused_before_it_starts() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (status, report) = srv
        .post(
            "codec=quant&max_error_mm=0.5&unit=mm",
            take_json(3, 100, 0.0),
        )
        .await;
    assert_eq!(status, 201, "{report}");
    let id = report["id"].as_str().unwrap().to_string();
    let too_many = format!(
        "ranges={}",
        vec![format!("{id}:0-10"); ranges_limit() + 1].join(",")
    );
    for (query, status, says) in [
        (format!("ranges={id}:0-10&format=json"), 400, "f32 or npy"),
        ("ranges=".to_string(), 400, "names no range"),
        (format!("ranges={id}"), 400, "ID:START-END"),
        (format!("ranges={id}:10-10"), 400, "holds no frames"),
        (format!("ranges={id}:a-10"), 400, "ID:START-END"),
        (too_many, 400, "over the limit"),
        // The bad part is the last: refused before the first is written.
        (format!("ranges={id}:0-10,nosuch:0-10"), 404, "nosuch"),
        (format!("ranges={id}:0-10,{id}:90-120"), 416, ""),
        (format!("ranges={id}:0-10&points=P0,P9"), 400, "P9"),
        (
            format!("ranges={id}:0-10&points=P0,P0"),
            400,
            "more than once",
        ),
        (format!("ranges={id}:0-10&unit=furlong"), 400, ""),
    ] {
        let (got, h, body) = srv.get(&format!("/v1/ranges?{query}")).await;
        let text = String::from_utf8_lossy(&body);
        let query: String = query.chars().take(120).collect();
        assert_eq!(got, status, "{query}: {text}");
        assert_eq!(h["content-type"], "application/json", "{query}");
        let v: Value = serde_json::from_slice(&body).unwrap();
        assert!(
            v["error"]["message"].as_str().unwrap().contains(says),
            "{query}: {text}"
        );
    }
    srv.stop().await;
}

fn ranges_limit() -> usize {
    mocapstore::limits::MAX_RANGES
}

/// A skeleton take of two joints (an End Site under the second), 30 frames at 30 fps.
fn skeleton_bvh() -> Vec<u8> {
    let mut s = String::from(
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition \
         Zrotation Xrotation Yrotation\n  JOINT Chest\n  {\n    OFFSET 0 20 0\n    CHANNELS \
         3 Zrotation Xrotation Yrotation\n    End Site\n    {\n      OFFSET 0 20 0\n    }\n  \
         }\n}\nMOTION\nFrames: 30\nFrame Time: 0.0333333\n",
    );
    for f in 0..30 {
        let t = f as f64 / 30.0;
        s += &format!(
            "{:.4} 90 0 {:.3} 0 0 {:.3} 0 0\n",
            t * 100.0,
            10.0 * t,
            20.0 * (2.0 * t).sin()
        );
    }
    s.into_bytes()
}

#[tokio::test(flavor = "multi_thread")]
async fn every_part_is_checked_as_its_own_request_would_be() {
    let t = common::sqlite().await;
    let srv = common::start_with(
        t.store.clone(),
        mocapstore::http::Config {
            limits: mocapstore::limits::Limits {
                answer_samples: 1_000,
                ..Default::default()
            },
            ..Default::default()
        },
    )
    .await;
    let (status, markers) = srv
        .post(
            "codec=quant&max_error_mm=0.5&unit=mm",
            take_json(3, 100, 0.0),
        )
        .await;
    assert_eq!(status, 201, "{markers}");
    let (status, skeleton) = srv.post("unit=cm", skeleton_bvh()).await;
    assert_eq!(status, 201, "{skeleton}");
    let (m, k) = (
        markers["id"].as_str().unwrap(),
        skeleton["id"].as_str().unwrap(),
    );
    // Root motion follows a body's pelvis: a take whose body names none (nor its up), after a
    // skeleton take, is refused before the skeleton's part is written, as its own request
    // would be.
    let (status, _, body) = srv
        .get(&format!("/v1/takes/{m}/frames?root=in-place"))
        .await;
    assert_eq!(status, 409, "{}", String::from_utf8_lossy(&body));
    let (status, h, body) = srv
        .get(&format!(
            "/v1/ranges?ranges={k}:0-30,{m}:0-10&root=in-place"
        ))
        .await;
    assert_eq!(status, 409, "{}", String::from_utf8_lossy(&body));
    assert_eq!(h["content-type"], "application/json");
    let (status, _, _) = srv
        .get(&format!("/v1/ranges?ranges={k}:0-30,{k}:5-10&root=extract"))
        .await;
    assert_eq!(status, 200);
    // Each part fits one answer (3 × 100 = 300 samples of 1,000); four do not together.
    let part = format!("{m}:0-100");
    let (status, _, _) = srv
        .get(&format!(
            "/v1/ranges?ranges={}",
            [part.as_str(); 3].join(",")
        ))
        .await;
    assert_eq!(status, 200);
    let (status, body) = srv
        .get_json(&format!(
            "/v1/ranges?ranges={}",
            [part.as_str(); 4].join(",")
        ))
        .await;
    assert_eq!(status, 400, "{body}");
    assert!(
        body["error"]["message"]
            .as_str()
            .unwrap()
            .contains("batch's samples"),
        "{body}"
    );
    srv.stop().await;
}

/// A token limited to one library: a batch naming a take of another is 404 whole, wherever
/// that take comes in the batch.
#[tokio::test(flavor = "multi_thread")]
async fn a_take_the_token_does_not_reach_is_not_there_in_any_part() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let admin = common::token(&t.store, "admin", "admin", None).await;
    let reader = common::token(&t.store, "lab-reader", "read", Some(&["lab"])).await;
    let mut ids = Vec::new();
    for library in ["lab", "other"] {
        let r = srv
            .client
            .post(format!(
                "{}/v1/takes?library={library}&codec=quant&max_error_mm=1&unit=mm",
                srv.base
            ))
            .bearer_auth(&admin)
            .body(take_json(3, 60, 0.0))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
        let v: Value = r.json().await.unwrap();
        ids.push(v["id"].as_str().unwrap().to_string());
    }
    let (lab, other) = (&ids[0], &ids[1]);
    for (ranges, want) in [
        (format!("{lab}:0-10"), 200),
        (format!("{lab}:0-10,{other}:0-10"), 404),
        (format!("{other}:0-10,{lab}:0-10"), 404),
        (format!("{lab}:0-10,{lab}:5-20,{other}:0-10"), 404),
    ] {
        let r = srv
            .client
            .get(format!("{}/v1/ranges?ranges={ranges}", srv.base))
            .bearer_auth(&reader)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), want, "{ranges}");
    }
    srv.stop().await;
}

/// Issue 52: a batch put on one skeleton (`skeleton=smpl`) is, part for part, what each
/// range's own request with `skeleton=smpl` gives: the SMPL joints' places of takes of
/// other rigs, a training batch on one body.
#[tokio::test(flavor = "multi_thread")]
async fn a_batch_on_one_skeleton_is_each_range_on_it() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let (status, take) = srv
        .post(
            "name=walker&codec=bvh-lossless",
            mocapstore::motion::synthetic::dancer_bvh(240, 60.0, 1, 4).into_bytes(),
        )
        .await;
    assert_eq!(status, 201, "{take}");
    let id = take["id"].as_str().unwrap();
    let (status, headers, body) = srv
        .get(&format!(
            "/v1/ranges?ranges={id}:0-60,{id}:100-160&format=npy&skeleton=smpl"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let got = parts(headers["content-type"].to_str().unwrap(), &body);
    assert_eq!(got.len(), 2);
    for ((h, b), (start, end)) in got.iter().zip([(0, 60), (100, 160)]) {
        let (status, _, own) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?start={start}&end={end}&format=npy&skeleton=smpl"
            ))
            .await;
        assert_eq!(status, 200);
        assert_eq!(b, &own, "{start}-{end}");
        assert_eq!(header(h, "x-frames"), "60");
    }
    // feet=lock without a skeleton is refused, as on a range.
    let (status, _, _) = srv
        .get(&format!("/v1/ranges?ranges={id}:0-60&feet=lock"))
        .await;
    assert_eq!(status, 400);
    srv.stop().await;
    t.finish().await;
}
