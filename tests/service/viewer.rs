//! The web viewer in a real browser: Debian's Chromium, headless, driven over WebDriver
//! (chromedriver) against the real server on port 0 with real corpus takes. Screenshots of
//! each page at 1280×720 go to `target/viewer-screenshots/`.
//!
//! The WebDriver client is the few JSON calls below over reqwest (already a test
//! dependency): a client crate would add a dependency tree to every build for six endpoints.
//!
//! Chromium and chromedriver come from Debian's `chromium` and `chromium-driver`; `.ci/run`
//! installs them and sets `MOCAP_TEST_BROWSER=1`, under which a missing browser fails the
//! test. Without that variable and without a browser, the test says so and passes.

use crate::common;

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use mocapstore::corpus;
use serde_json::{json, Value};

/// A chromedriver process and one headless Chromium session on it.
struct Browser {
    driver: Child,
    base: String,
    session: String,
    http: reqwest::Client,
}

impl Browser {
    async fn start() -> Option<Browser> {
        let required = std::env::var("MOCAP_TEST_BROWSER").is_ok_and(|v| v == "1");
        let found = |name: &str| {
            Command::new("sh")
                .args(["-c", &format!("command -v {name}")])
                .output()
                .is_ok_and(|o| o.status.success())
        };
        if !found("chromedriver") || !found("chromium") {
            assert!(
                !required,
                "MOCAP_TEST_BROWSER=1 but chromium/chromedriver are missing (apt-get install chromium chromium-driver)"
            );
            eprintln!("chromium or chromedriver missing: skipping the browser test");
            return None;
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let driver = Command::new("chromedriver")
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts");
        let base = format!("http://127.0.0.1:{port}");
        let http = reqwest::Client::new();
        for _ in 0..200 {
            if http.get(format!("{base}/status")).send().await.is_ok() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {
                "binary": "/usr/bin/chromium",
                "args": ["--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                         "--window-size=1280,720", "--use-angle=swiftshader",
                         "--enable-unsafe-swiftshader", "--disable-gpu-sandbox"]
            },
            "goog:loggingPrefs": {"browser": "ALL"}
        }}});
        let r: Value = http
            .post(format!("{base}/session"))
            .json(&caps)
            .send()
            .await
            .expect("chromedriver answers")
            .json()
            .await
            .unwrap();
        let session = r["value"]["sessionId"]
            .as_str()
            .unwrap_or_else(|| panic!("no session: {r}"))
            .to_string();
        let b = Browser {
            driver,
            base,
            session,
            http,
        };
        b.viewport(1280, 720).await;
        Some(b)
    }

    async fn cmd(&self, method: reqwest::Method, path: &str, body: Option<Value>) -> Value {
        let url = format!("{}/session/{}{path}", self.base, self.session);
        let mut rb = self.http.request(method, url);
        if let Some(b) = body {
            rb = rb.json(&b);
        }
        let v: Value = rb.send().await.unwrap().json().await.unwrap();
        if v["value"]["error"].is_string() {
            panic!("WebDriver {path}: {v}");
        }
        v["value"].clone()
    }

    /// Make the page's viewport `width × height` CSS pixels (the window is larger by its
    /// frame).
    async fn viewport(&self, width: i64, height: i64) {
        let frame = self
            .js(
                "return [window.outerWidth - window.innerWidth, window.outerHeight - window.innerHeight];",
                json!([]),
            )
            .await;
        let (fw, fh) = (
            frame[0].as_i64().unwrap_or(0),
            frame[1].as_i64().unwrap_or(0),
        );
        self.cmd(
            reqwest::Method::POST,
            "/window/rect",
            Some(json!({"width": width + fw, "height": height + fh})),
        )
        .await;
    }

    async fn goto(&self, url: &str) {
        self.cmd(reqwest::Method::POST, "/url", Some(json!({"url": url})))
            .await;
    }

    /// Run `script` (a function body; `arguments` as in WebDriver) in the page.
    async fn js(&self, script: &str, args: Value) -> Value {
        self.cmd(
            reqwest::Method::POST,
            "/execute/sync",
            Some(json!({"script": script, "args": args})),
        )
        .await
    }

    /// Go to `url` and wait until `script` holds there; its value.
    async fn visit(&self, url: &str, what: &str, script: &str) -> Value {
        self.goto(url).await;
        self.until(what, script).await
    }

    /// Wait until `script` returns something truthy; its value.
    async fn until(&self, what: &str, script: &str) -> Value {
        for _ in 0..300 {
            let v = self.js(script, json!([])).await;
            if !(v.is_null() || v == false || v == 0 || v == "") {
                return v;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        panic!("timed out waiting for {what}");
    }

    async fn screenshot(&self, name: &str) {
        use base64::Engine;
        let v = self.cmd(reqwest::Method::GET, "/screenshot", None).await;
        let png = base64::engine::general_purpose::STANDARD
            .decode(v.as_str().unwrap())
            .unwrap();
        let dir = screenshots();
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(format!("{name}.png")), png).unwrap();
    }

    /// Console messages at level SEVERE since the last call.
    async fn console_errors(&self) -> Vec<String> {
        let v = self
            .cmd(
                reqwest::Method::POST,
                "/se/log",
                Some(json!({"type": "browser"})),
            )
            .await;
        v.as_array()
            .into_iter()
            .flatten()
            .filter(|e| e["level"] == "SEVERE")
            .map(|e| e["message"].as_str().unwrap_or("").to_string())
            .collect()
    }

    async fn quit(mut self) {
        let _ = self
            .http
            .delete(format!("{}/session/{}", self.base, self.session))
            .send()
            .await;
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

fn screenshots() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/viewer-screenshots")
}

fn corpus_bytes(rel: &str) -> Vec<u8> {
    std::fs::read(corpus::root().join(rel)).unwrap()
}

/// Upload corpus file `rel` with `query`; the stored take's report.
async fn stored(srv: &common::Server, query: &str, rel: &str) -> Value {
    let (status, take) = srv.post(query, corpus_bytes(rel)).await;
    assert_eq!(status, 201, "{rel}: {take}");
    take
}

#[tokio::test]
async fn the_viewer_lists_plays_and_uploads_in_a_real_browser() {
    if corpus::for_tests().is_none() {
        return;
    }
    let Some(browser) = Browser::start().await else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let bvh = stored(
        &srv,
        "name=131_02&library=cmu&tags=run&max_error_mm=1",
        "bvh/cmu/131_02.bvh",
    )
    .await;
    stored(
        &srv,
        "name=gait&library=lab&max_error_mm=1",
        "c3d/btkdata__others__Gait.c3d",
    )
    .await;
    let bvh_id = bvh["id"].as_str().unwrap().to_string();

    // Library: both takes, then a filter leaves one.
    let rows = browser
        .visit(&format!("{}/#/", srv.base), "the listing", "const r = document.querySelectorAll('table.takes tbody tr'); return r.length >= 2 && r.length;")
        .await;
    assert_eq!(rows, 2);
    browser.screenshot("library").await;
    let names = browser
        .visit(&format!("{}/#/?library=lab", srv.base), "the filtered listing", "const r = [...document.querySelectorAll('table.takes tbody tr td:first-child')].map(e => e.textContent); return r.length === 1 && r;")
        .await;
    assert_eq!(names, json!(["gait"]));
    assert!(browser.console_errors().await.is_empty());

    // A take: the figure is drawn (pixels, not only DOM), play advances the playhead.
    browser
        .visit(
            &format!("{}/#/take/{bvh_id}", srv.base),
            "the first frame",
            "return document.querySelector('canvas.view')?.dataset.frame === '0';",
        )
        .await;
    let drawn = browser
        .js(
            "const c = document.querySelector('canvas.view');
             const gl = c.getContext('webgl2') || c.getContext('webgl');
             const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
             const px = new Uint8Array(w * h * 4);
             gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
             let dark = 0;
             for (let i = 0; i < px.length; i += 4) if (px[i] + px[i+1] + px[i+2] < 300) dark++;
             return dark;",
            json!([]),
        )
        .await;
    assert!(
        drawn.as_u64().unwrap() > 200,
        "the figure's points and bones are drawn: {drawn} dark pixels"
    );
    browser.screenshot("take").await;
    browser
        .js(
            "document.querySelector('button.play').click(); return true;",
            json!([]),
        )
        .await;
    browser
        .until(
            "playback",
            "const f = document.querySelector('canvas.view').dataset.frame; return Number(f) > 30 && Number.isInteger(Number(f));",
        )
        .await;
    browser
        .js(
            "document.querySelector('button.play').click(); return true;",
            json!([]),
        )
        .await;

    // Scrubbing to second 8 fetches that second's range (the page's own request log).
    browser
        .js(
            "const s = document.querySelector('input[type=range]');
             s.value = String(Math.round(8 * 120.0005)); s.dispatchEvent(new Event('input'));
             return true;",
            json!([]),
        )
        .await;
    let fetched = browser
        .until(
            "the range of second 8",
            "return performance.getEntriesByType('resource').map(e => e.name).find(n => /frames\\?start=960&end=1080&format=f32/.test(n)) || '';",
        )
        .await;
    assert!(fetched.as_str().unwrap().contains("start=960"), "{fetched}");
    let url = browser
        .until(
            "a shareable URL",
            "return location.hash.includes('t=8') && location.hash;",
        )
        .await;
    assert!(url.as_str().unwrap().contains(&bvh_id), "{url}");

    // The decision table is the take's decision record.
    let (_, take) = srv.get_json(&format!("/v1/sequences/{bvh_id}")).await;
    let table = browser
        .js(
            "return [...document.querySelectorAll('table.decision tbody tr:not(.skipped)')].map(r => [r.cells[0].textContent, Number(r.cells[1].textContent)]);",
            json!([]),
        )
        .await;
    let tried: Vec<Value> = take["meta"]["decision"]["tried"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| json!([c["codec"], c["stored_bytes"]]))
        .collect();
    assert_eq!(table, Value::Array(tried));
    let winner = browser
        .js(
            "return document.querySelector('table.decision tr.winner td').textContent;",
            json!([]),
        )
        .await;
    assert_eq!(winner, take["meta"]["decision"]["winner"]);
    // What compression did: the error per second charted against the bound.
    let chart = browser
        .until(
            "the error chart",
            "const s = document.querySelector('svg.errors'); return s && [s.querySelector('polyline.max').getAttribute('points').split(' ').length, !!s.querySelector('line.bound')];",
        )
        .await;
    assert_eq!(
        chart,
        json!([11, true]),
        "1,247 frames at 120 fps: 11 seconds"
    );
    assert!(browser.console_errors().await.is_empty());

    // Drag and drop: a TRC file dropped on the library page is stored; a file the server
    // refuses shows its error.
    browser
        .visit(
            &format!("{}/#/?library=dropped", srv.base),
            "the library page",
            "return document.querySelector('.drop') !== null;",
        )
        .await;
    let trc = String::from_utf8(corpus_bytes("trc/TRCSamples__Gait.trc")).unwrap();
    browser
        .js(
            "const drop = document.querySelector('.drop');
             const dt = new DataTransfer();
             dt.items.add(new File([arguments[0]], 'gait.trc', {type: 'text/plain'}));
             dt.items.add(new File(['not a take'], 'junk.bvh'));
             drop.dispatchEvent(new DragEvent('drop', {dataTransfer: dt, bubbles: true, cancelable: true}));
             return true;",
            json!([trc]),
        )
        .await;
    let outcome = browser
        .until(
            "both uploads",
            "const li = [...document.querySelectorAll('.uploads li')]; return li.length === 2 && li.every(l => /stored|refused/.test(l.textContent)) && li.map(l => l.textContent);",
        )
        .await;
    let outcome: Vec<String> = serde_json::from_value(outcome).unwrap();
    assert!(outcome[0].contains("stored as"), "{outcome:?}");
    assert!(outcome[1].contains("refused"), "{outcome:?}");
    let (_, list) = srv.get_json("/v1/sequences?library=dropped").await;
    assert_eq!(list["items"][0]["name"], "gait", "{list}");
    browser.screenshot("upload").await;
    // The refused upload's 4xx is the page's message, not a console error of ours.
    let errors: Vec<String> = browser
        .console_errors()
        .await
        .into_iter()
        .filter(|e| !e.contains("the server responded with a status of 4"))
        .collect();
    assert!(errors.is_empty(), "{errors:?}");

    // Statistics: /v1/stats as charts, and one dot per take.
    let drawn = browser
        .visit(&format!("{}/#/stats", srv.base), "the statistics charts", "const f = document.querySelectorAll('figure'); return f.length === 4 && [document.querySelectorAll('svg.bars')[1].querySelectorAll('rect.stored_bytes').length, document.querySelectorAll('svg.scatter circle.take').length];")
        .await;
    let (_, stats) = srv.get_json("/v1/stats").await;
    let codecs = stats["by_codec"].as_object().unwrap().len();
    let takes = stats["total"]["takes"].as_u64().unwrap();
    assert_eq!(drawn, json!([codecs, takes]), "{stats}");
    browser.screenshot("stats").await;
    assert!(browser.console_errors().await.is_empty());

    // Phone-sized: the take page still fits.
    browser.viewport(390, 844).await;
    browser
        .visit(
            &format!("{}/#/take/{bvh_id}?t=2", srv.base),
            "the phone layout",
            "return document.querySelector('canvas.view')?.dataset.frame === '240';",
        )
        .await;
    let overflow = browser
        .js(
            "return document.documentElement.scrollWidth - document.documentElement.clientWidth;",
            json!([]),
        )
        .await;
    assert!(
        overflow.as_i64().unwrap() <= 0,
        "horizontal overflow {overflow}"
    );
    browser.screenshot("take-phone").await;
    assert!(browser.console_errors().await.is_empty());

    browser.quit().await;
    srv.stop().await;
    t.finish().await;
}

/// The series the viewer charts: one bin a second, its worst bin the take's max error, no
/// bin over the bound; a live take has none and says so.
#[tokio::test]
async fn error_series_are_measured_at_ingest_and_served() {
    if corpus::for_tests().is_none() {
        return;
    }
    for t in common::all().await {
        let srv = common::start(t.store.clone(), 64 << 20).await;
        let take = stored(&srv, "name=131_02&max_error_mm=1", "bvh/cmu/131_02.bvh").await;
        let id = take["id"].as_str().unwrap();
        let (status, e) = srv.get_json(&format!("/v1/sequences/{id}/errors")).await;
        assert_eq!(status, 200, "{e}");
        let per = e["frames_per_bin"].as_u64().unwrap();
        assert_eq!(per, 120);
        let max: Vec<f64> = serde_json::from_value(e["max_mm"].clone()).unwrap();
        let mean: Vec<f64> = serde_json::from_value(e["mean_mm"].clone()).unwrap();
        assert_eq!(max.len() as u64, 1247u64.div_ceil(per));
        assert_eq!(mean.len(), max.len());
        let worst = max.iter().cloned().fold(0.0, f64::max);
        assert!(
            (worst - take["max_mm"].as_f64().unwrap()).abs() < 1e-4,
            "{worst} vs {take}"
        );
        assert!(max.iter().all(|m| *m <= 1.0 + 1e-6));
        assert!(mean.iter().zip(&max).all(|(a, b)| a <= b));
        assert_eq!(e["max_bound_mm"], 1.0);

        let (_, _, stream) = srv
            .post_json("/v1/streams", &json!({"fps": 60.0, "points": 2}))
            .await;
        let sid = stream["id"].as_str().unwrap();
        let (status, e) = srv.get_json(&format!("/v1/sequences/{sid}/errors")).await;
        assert_eq!(status, 409, "{e}");
        let (status, _) = srv.get_json("/v1/sequences/nope/errors").await;
        assert_eq!(status, 404);
        srv.stop().await;
        t.finish().await;
    }
}
