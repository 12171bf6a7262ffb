//! `openapi.yaml` is the contract: every route answers as it says, and live responses match
//! the schemas it gives (a small validator for the JSON Schema subset the file uses).

use crate::common;

use mocapstore::motion::formats::{self, Format};
use mocapstore::motion::synthetic::walker;
use serde_json::Value;

fn spec() -> Value {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml")).unwrap();
    serde_yaml_ng::from_str(&text).expect("openapi.yaml parses")
}

fn resolve<'a>(spec: &'a Value, v: &'a Value) -> &'a Value {
    match v.get("$ref").and_then(Value::as_str) {
        Some(r) => {
            let mut node = spec;
            for part in r.trim_start_matches("#/").split('/') {
                node = &node[part];
            }
            resolve(spec, node)
        }
        None => v,
    }
}

/// Check `value` against `schema`; errors name the JSON path.
fn check(spec: &Value, schema: &Value, value: &Value, path: &str, errors: &mut Vec<String>) {
    let schema = resolve(spec, schema);
    let types: Vec<&str> = match &schema["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    };
    if !types.is_empty() {
        let ok = types.iter().any(|t| match *t {
            "object" => value.is_object(),
            "array" => value.is_array(),
            "string" => value.is_string(),
            "integer" => value.is_i64() || value.is_u64(),
            "number" => value.is_number(),
            "boolean" => value.is_boolean(),
            "null" => value.is_null(),
            _ => false,
        });
        if !ok {
            errors.push(format!("{path}: {value} is not {types:?}"));
            return;
        }
    }
    if let Some(options) = schema["enum"].as_array() {
        if !options.contains(value) {
            errors.push(format!("{path}: {value} not in {options:?}"));
        }
    }
    if let Value::Object(obj) = value {
        for req in schema["required"].as_array().into_iter().flatten() {
            let k = req.as_str().unwrap();
            if !obj.contains_key(k) {
                errors.push(format!("{path}: missing {k}"));
            }
        }
        for (k, v) in obj {
            let sub = schema["properties"]
                .get(k)
                .or_else(|| schema.get("additionalProperties").filter(|a| a.is_object()));
            if let Some(sub) = sub {
                check(spec, sub, v, &format!("{path}.{k}"), errors);
            }
        }
    }
    if let (Value::Array(items), Some(item_schema)) = (value, schema.get("items")) {
        for (i, v) in items.iter().enumerate().take(50) {
            check(spec, item_schema, v, &format!("{path}[{i}]"), errors);
        }
    }
}

/// The operation's response schema for `status` (JSON bodies only).
fn response_schema<'a>(spec: &'a Value, path: &str, method: &str, status: u16) -> &'a Value {
    let op = &spec["paths"][path][method];
    assert!(op.is_object(), "{method} {path} is not in openapi.yaml");
    let resp = resolve(spec, &op["responses"][status.to_string()]);
    assert!(
        resp.is_object(),
        "{method} {path} → {status} is not in openapi.yaml"
    );
    &resp["content"]["application/json"]["schema"]
}

/// The answer has the status the test expects, and that status and its body are what the
/// contract says for the operation.
fn conforms(spec: &Value, path: &str, method: &str, (status, want): (u16, u16), body: &Value) {
    assert_eq!(status, want, "{method} {path}: {body}");
    let schema = response_schema(spec, path, method, status);
    let mut errors = Vec::new();
    check(spec, schema, body, "$", &mut errors);
    assert!(
        errors.is_empty(),
        "{method} {path} {status}: {}",
        errors.join("; ")
    );
}

#[tokio::test]
async fn live_responses_match_the_contract() {
    let spec = spec();
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let take = formats::write(&walker(300, 6, 120.0, 3, 0.2), Format::Json).unwrap();
    let (status, report) = srv.post("name=a&tags=x,y&max_error_mm=1", take).await;
    conforms(&spec, "/v1/takes", "post", (status, 201), &report);
    let id = report["id"].as_str().unwrap().to_string();
    for ((status, body), want) in [
        (srv.post("codec=zip", vec![1]).await, 400),
        (srv.post("", b"junk".to_vec()).await, 422),
    ] {
        conforms(&spec, "/v1/takes", "post", (status, want), &body);
    }
    let get = |p: String| {
        let srv = &srv;
        async move {
            let (s, _, b) = srv.get(&p).await;
            (
                s,
                serde_json::from_slice::<Value>(&b).unwrap_or(Value::Null),
            )
        }
    };
    for (route, path, want) in [
        ("/v1/takes", "/v1/takes?limit=1".to_string(), 200),
        ("/v1/takes", "/v1/takes?limit=0".to_string(), 400),
        ("/v1/takes/{id}", format!("/v1/takes/{id}"), 200),
        ("/v1/takes/{id}", "/v1/takes/nope".to_string(), 404),
        (
            "/v1/takes/{id}/frames",
            format!("/v1/takes/{id}/frames?start=3&end=9"),
            200,
        ),
        (
            "/v1/takes/{id}/frames",
            format!("/v1/takes/{id}/frames?end=9999"),
            416,
        ),
        (
            "/v1/takes/{id}/frames",
            format!("/v1/takes/{id}/frames?format=bvh"),
            409,
        ),
        ("/v1/stats", "/v1/stats".to_string(), 200),
    ] {
        let (status, body) = get(path).await;
        conforms(&spec, route, "get", (status, want), &body);
    }
    let r = srv
        .client
        .patch(format!("{}/v1/takes/{id}", srv.base))
        .json(&serde_json::json!({"library": "moved"}))
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    conforms(
        &spec,
        "/v1/takes/{id}",
        "patch",
        (status, 200),
        &r.json().await.unwrap(),
    );
    // Bases and jobs.
    let (status, _, job) = srv
        .post_json("/v1/bases", &serde_json::json!({"max_iterations": 5}))
        .await;
    conforms(&spec, "/v1/bases", "post", (status, 202), &job);
    let (status, _, bad) = srv
        .post_json("/v1/bases", &serde_json::json!({"library": "none"}))
        .await;
    conforms(&spec, "/v1/bases", "post", (status, 400), &bad);
    let job_path = format!("/v1/jobs/{}", job["id"].as_str().unwrap());
    let (status, j) = get(job_path.clone()).await;
    conforms(&spec, "/v1/jobs/{id}", "get", (status, 200), &j);
    let j = common::wait_for_job(&srv, &job_path).await;
    conforms(&spec, "/v1/jobs/{id}", "get", (200, 200), &j);
    let basis = j["result"]["id"].as_str().unwrap().to_string();
    for (route, path, want) in [
        ("/v1/bases", "/v1/bases".to_string(), 200),
        ("/v1/bases", "/v1/bases?kind=nope".to_string(), 400),
        ("/v1/bases/{id}", format!("/v1/bases/{basis}"), 200),
        ("/v1/bases/{id}", "/v1/bases/nope".to_string(), 404),
        ("/v1/jobs/{id}", "/v1/jobs/nope".to_string(), 404),
        ("/v1/jobs/{id}", format!("{job_path}?wait_s=601"), 400),
    ] {
        let (status, body) = get(path).await;
        conforms(&spec, route, "get", (status, want), &body);
    }
    // Streams.
    let (status, _, stream) = srv
        .post_json(
            "/v1/streams",
            &serde_json::json!({"fps": 60.0, "points": ["a", "b"], "chunk_seconds": 0.1}),
        )
        .await;
    conforms(&spec, "/v1/streams", "post", (status, 201), &stream);
    let (status, _, bad) = srv
        .post_json(
            "/v1/streams",
            &serde_json::json!({"fps": -1.0, "points": 2}),
        )
        .await;
    conforms(&spec, "/v1/streams", "post", (status, 400), &bad);
    let sid = stream["id"].as_str().unwrap().to_string();
    let frames = serde_json::json!({"frames": vec![[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]; 8]});
    for (body, want) in [(frames, 200), (serde_json::json!({"frames": [[1.0]]}), 400)] {
        let (status, _, r) = srv
            .post_json(&format!("/v1/streams/{sid}/frames"), &body)
            .await;
        conforms(&spec, "/v1/streams/{id}/frames", "post", (status, want), &r);
    }
    let (status, s) = get(format!("/v1/streams/{sid}")).await;
    conforms(&spec, "/v1/streams/{id}", "get", (status, 200), &s);
    for want in [200, 409] {
        let (status, _, r) = srv
            .post_json(&format!("/v1/streams/{sid}/finish"), &serde_json::json!({}))
            .await;
        conforms(&spec, "/v1/streams/{id}/finish", "post", (status, want), &r);
    }
    let documented = |path: &str, method: &str, status: u16| {
        spec["paths"][path][method]["responses"][status.to_string()].is_object()
    };
    // The basis codes no take (the stream, of another layout, codes with the DCT).
    let status = srv.delete(&format!("/v1/bases/{basis}")).await;
    assert!(status == 204 && documented("/v1/bases/{id}", "delete", status));
    let status = srv.delete(&format!("/v1/takes/{id}")).await;
    assert!(status == 204 && documented("/v1/takes/{id}", "delete", status));
    for p in ["/healthz", "/metrics"] {
        let (status, _, _) = srv.get(p).await;
        assert!(status == 200 && documented(p, "get", status), "{p}");
    }
    srv.stop().await;
    t.finish().await;
}

/// The contract names every codec a take can be coded with, and no other.
#[test]
fn the_codec_ids_are_the_registry() {
    let spec = spec();
    let listed: Vec<String> = spec["components"]["schemas"]["CodecId"]["enum"]
        .as_array()
        .expect("CodecId lists its values")
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    let registry: Vec<String> = mocapstore::codec::CodecId::ALL
        .iter()
        .map(|c| c.to_string())
        .collect();
    assert_eq!(listed, registry);
}
