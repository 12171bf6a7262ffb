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

use std::os::unix::process::CommandExt;
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
    /// Whether `screenshot` saves (one backend's tour is enough).
    shots: std::cell::Cell<bool>,
}

impl Browser {
    /// A browser for a test on corpus takes; None (the test passes, saying why) without the
    /// corpus, or without a browser when none is required.
    async fn with_corpus() -> Option<Browser> {
        corpus::for_tests()?;
        Browser::start().await
    }

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
        // Port 0: chromedriver binds a free port itself and says which (no port found free
        // here and bound again by the child, which another process could take between).
        let mut driver = Command::new("chromedriver")
            .arg("--port=0")
            .process_group(0)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts");
        let mut lines = std::io::BufRead::lines(std::io::BufReader::new(
            driver.stdout.take().expect("chromedriver's output"),
        ));
        let port: u16 = loop {
            let line = lines
                .next()
                .expect("chromedriver says its port")
                .expect("chromedriver's output");
            if let Some(rest) = line.split("started successfully on port ").nth(1) {
                break rest.trim_end_matches('.').trim().parse().expect("a port");
            }
        };
        // Keep reading what it prints, or a full pipe would stop it.
        std::thread::spawn(move || lines.for_each(drop));
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
            shots: std::cell::Cell::new(true),
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

    /// Press keys as a user would (WebDriver key actions): each entry is pressed and
    /// released in turn, with `modifier` (e.g. Shift, "\u{E008}") held if given.
    async fn keys(&self, modifier: Option<&str>, keys: &[&str]) {
        let mut actions = Vec::new();
        if let Some(m) = modifier {
            actions.push(json!({"type": "keyDown", "value": m}));
        }
        for k in keys {
            actions.push(json!({"type": "keyDown", "value": k}));
            actions.push(json!({"type": "keyUp", "value": k}));
        }
        if let Some(m) = modifier {
            actions.push(json!({"type": "keyUp", "value": m}));
        }
        self.cmd(
            reqwest::Method::POST,
            "/actions",
            Some(json!({"actions": [{"type": "key", "id": "keyboard", "actions": actions}]})),
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

    fn shots(&self, on: bool) {
        self.shots.set(on);
    }

    async fn screenshot(&self, name: &str) {
        if !self.shots.get() {
            return;
        }
        use base64::Engine;
        let v = self.cmd(reqwest::Method::GET, "/screenshot", None).await;
        let png = base64::engine::general_purpose::STANDARD
            .decode(v.as_str().unwrap())
            .unwrap();
        let dir = screenshots();
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(format!("{name}.png")), png).unwrap();
    }

    /// Click the first element `selector` finds.
    async fn click(&self, selector: &str) {
        self.js(
            "document.querySelector(arguments[0]).click(); return true;",
            json!([selector]),
        )
        .await;
    }

    /// How far the page is wider than the viewport, CSS pixels (≤ 0: it fits).
    async fn overflow(&self) -> i64 {
        self.js(
            "return document.documentElement.scrollWidth - document.documentElement.clientWidth;",
            json!([]),
        )
        .await
        .as_i64()
        .unwrap()
    }

    /// Console errors since the last call, but for the browser's own line about an HTTP
    /// status starting with `status` (an error answer the page was meant to get and show).
    async fn console_errors_but_status(&self, status: &str) -> Vec<String> {
        let expected = format!("the server responded with a status of {status}");
        self.console_errors()
            .await
            .into_iter()
            .filter(|e| !e.contains(&expected))
            .collect()
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

    /// End the session politely; `Drop` then stops chromedriver.
    async fn quit(self) {
        let _ = self
            .http
            .delete(format!("{}/session/{}", self.base, self.session))
            .send()
            .await;
    }
}

/// chromedriver and every browser it started, also when a test fails half-way: a headless
/// Chromium left behind keeps drawing its page and takes a core from every later test.
impl Drop for Browser {
    fn drop(&mut self) {
        let group = format!("-{}", self.driver.id());
        let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
        let _ = self.driver.wait();
    }
}

/// Pixels of the `index`th 3-D view of the page whose colour `test` (a JS expression over
/// r, g, b) accepts.
async fn pixels(browser: &Browser, index: usize, test: &str) -> u64 {
    browser
        .js(
            "const c = document.querySelectorAll('canvas.view')[arguments[0]];
             const test = new Function('r', 'g', 'b', 'return ' + arguments[1]);
             const gl = c.getContext('webgl2') || c.getContext('webgl');
             const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
             const px = new Uint8Array(w * h * 4);
             gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
             let n = 0;
             for (let i = 0; i < px.length; i += 4) if (test(px[i], px[i+1], px[i+2])) n++;
             return n;",
            json!([index, test]),
        )
        .await
        .as_u64()
        .unwrap()
}

/// Dark pixels (points and bones) on the `index`th 3-D view of the page.
async fn drawn(browser: &Browser, index: usize) -> u64 {
    pixels(browser, index, "r + g + b < 300").await
}

/// Controls a screen reader could not name: buttons, fields, links and focusable views with
/// neither text, a label nor an aria-label.
async fn unnamed_controls(browser: &Browser) -> Value {
    browser
        .js(
            "return [...document.querySelectorAll('button, input, select, a, [tabindex]')]
               .filter(e => !e.hidden && e.type !== 'hidden' && e.id !== 'main')
               .filter(e => !(e.getAttribute('aria-label') || e.textContent.trim() || e.labels?.length || e.closest('label')))
               .map(e => e.outerHTML.slice(0, 80));",
            json!([]),
        )
        .await
}

fn screenshots() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/viewer-screenshots")
}

fn corpus_bytes(rel: &str) -> Vec<u8> {
    std::fs::read(corpus::root().join(rel)).unwrap()
}

/// Upload corpus file `rel` with `query`; the stored take's report.
/// The frame of take `id`'s first event, as the page rounds it.
async fn fp_events(srv: &common::Server, id: &str) -> i64 {
    let (_, take) = srv.get_json(&format!("/v1/takes/{id}")).await;
    let f = take["meta"]["events"][0]["frame"].as_i64().unwrap();
    f.clamp(0, take["frames"].as_i64().unwrap() - 1)
}

async fn stored(srv: &common::Server, query: &str, rel: &str) -> Value {
    let (status, take) = srv.post(query, corpus_bytes(rel)).await;
    assert_eq!(status, 201, "{rel}: {take}");
    take
}

#[tokio::test]
async fn the_viewer_lists_plays_and_uploads_in_a_real_browser() {
    let Some(browser) = Browser::with_corpus().await else {
        return;
    };
    // The same tour on every backend; screenshots of the SQLite one (the default).
    for t in common::all().await {
        browser.viewport(1280, 720).await;
        browser.shots(t.name == "sqlite");
        let srv = common::start(t.store.clone(), 64 << 20).await;
        let bvh = stored(
            &srv,
            "name=131_02&library=cmu&tags=run&max_error_mm=1",
            "bvh/cmu/131_02.bvh",
        )
        .await;
        let gait = stored(
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
        assert_eq!(unnamed_controls(&browser).await, json!([]));
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
        browser.click("button.play").await;
        browser
            .until(
                "playback",
                "const f = document.querySelector('canvas.view').dataset.frame; return Number(f) > 30 && Number.isInteger(Number(f));",
            )
            .await;
        browser.click("button.play").await;

        // The keyboard: → one frame, shift+→ one second, Home the start.
        let frame = || async {
            browser
                .js(
                    "return Number(document.querySelector('canvas.view').dataset.frame);",
                    json!([]),
                )
                .await
                .as_i64()
                .unwrap()
        };
        browser
            .js(
                "document.querySelector('canvas.view').focus(); return true;",
                json!([]),
            )
            .await;
        browser.keys(None, &["\u{E011}"]).await; // Home
        browser
            .until(
                "Home",
                "return document.querySelector('canvas.view').dataset.frame === '0';",
            )
            .await;
        browser.keys(None, &["\u{E014}", "\u{E014}"]).await; // → →
        browser
            .until(
                "→ →",
                "return document.querySelector('canvas.view').dataset.frame === '2';",
            )
            .await;
        browser.keys(Some("\u{E008}"), &["\u{E014}"]).await; // shift+→
        browser
            .until(
                "shift+→",
                "return document.querySelector('canvas.view').dataset.frame === '122';",
            )
            .await;
        assert_eq!(frame().await, 122);
        assert_eq!(unnamed_controls(&browser).await, json!([]));

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
        let (_, take) = srv.get_json(&format!("/v1/takes/{bvh_id}")).await;
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
        let (_, list) = srv.get_json("/v1/takes?library=dropped").await;
        assert_eq!(list["items"][0]["name"], "gait", "{list}");
        browser.screenshot("upload").await;
        // The refused upload's 4xx is the page's message, not a console error of ours.
        let errors = browser.console_errors_but_status("4").await;
        assert!(errors.is_empty(), "{errors:?}");

        // Statistics: /v1/stats as charts, and one dot per take.
        let drawn = browser
            .visit(&format!("{}/#/stats", srv.base), "the statistics charts", "const f = document.querySelectorAll('figure'); return f.length === 4 && [document.querySelectorAll('svg.bars')[1].querySelectorAll('rect.stored_bytes').length, document.querySelectorAll('svg.scatter circle.take').length];")
            .await;
        let (_, stats) = srv.get_json("/v1/stats").await;
        let codecs = stats["by_codec"].as_object().unwrap().len();
        let takes = stats["total"]["takes"].as_u64().unwrap();
        assert_eq!(drawn, json!([codecs, takes]), "{stats}");
        // Points and analog channels apart (the gait take has 28 channels).
        let split = browser
            .js(
                "return document.querySelector('p.split')?.textContent || '';",
                json!([]),
            )
            .await;
        assert!(
            split.as_str().unwrap().contains("Analog channels")
                && !split.as_str().unwrap().contains("Analog channels: 0 B"),
            "{split}"
        );
        browser.screenshot("stats").await;
        assert_eq!(unnamed_controls(&browser).await, json!([]));
        assert!(browser.console_errors().await.is_empty());

        // An error answer is the page's message, in the server's words.
        let message = browser
            .visit(
                &format!("{}/#/take/no-such-take", srv.base),
                "the error message",
                "const m = document.getElementById('message'); return !m.hidden && m.getAttribute('role') === 'alert' && m.textContent;",
            )
            .await;
        assert!(
            message.as_str().unwrap().contains("(not_found)"),
            "{message}"
        );
        let errors = browser.console_errors_but_status("404").await;
        assert!(errors.is_empty(), "{errors:?}");

        // A marker take with its markers named on screen, at their points.
        let gait_id = gait["id"].as_str().unwrap();
        let (_, gait) = srv.get_json(&format!("/v1/takes/{gait_id}")).await;
        browser
            .visit(
                // Second 2: the subject is in the capture volume (most markers are missing
                // before second 1.5 and after 3.7).
                &format!("{}/#/take/{gait_id}?t=2", srv.base),
                "the marker take",
                "return document.querySelector('canvas.view')?.dataset.frame;",
            )
            .await;
        let labels = browser
            .js(
                "document.querySelector('input.labels-toggle').click();
                 const c = document.querySelector('canvas.view').getBoundingClientRect();
                 return [...document.querySelectorAll('.labels span')].map(s => {
                   const r = s.getBoundingClientRect();
                   return [s.textContent, !s.hidden && r.left >= c.left && r.top >= c.top - 16 && r.left <= c.right && r.top <= c.bottom];
                 });",
                json!([]),
            )
            .await;
        let labels = labels.as_array().unwrap();
        let names: Vec<&Value> = labels.iter().map(|l| &l[0]).collect();
        let want: Vec<&Value> = gait["meta"]["point_names"]
            .as_array()
            .unwrap()
            .iter()
            .collect();
        assert_eq!(names, want);
        let on_view = labels.iter().filter(|l| l[1] == true).count();
        assert!(
            on_view * 2 > labels.len(),
            "{on_view} of {} labels over the view",
            labels.len()
        );
        browser.screenshot("take-labels").await;
        assert!(browser.console_errors().await.is_empty());

        // A C3D's events on the timeline (12 foot strikes and foot offs), its analog
        // channels among the facts; a click on an event seeks to it.
        let fp = stored(
            &srv,
            "name=flatfoot&codec=quant&labels=subject:s1,trial:3",
            "c3d/btkdata__PiG__PiG_Motion-FlatFoot-Full.c3d",
        )
        .await;
        let fp_id = fp["id"].as_str().unwrap();
        let events = browser
            .visit(
                &format!("{}/#/take/{fp_id}", srv.base),
                "the events strip",
                "const e = document.querySelectorAll('svg.events g.event'); return e.length > 0 && e.length;",
            )
            .await;
        assert_eq!(events, 12);
        let facts = browser
            .js(
                "return document.querySelector('table.facts').textContent;",
                json!([]),
            )
            .await;
        assert!(
            facts.as_str().unwrap().contains("analog channels")
                && facts.as_str().unwrap().contains("analog-lossless")
                && facts.as_str().unwrap().contains("subject: s1, trial: 3"),
            "{facts}"
        );
        // The library filtered by a label: that take alone, its labels in their column.
        let rows = browser
            .visit(
                &format!("{}/#/?labels=subject:%20s1", srv.base),
                "the library filtered by a label",
                "const r = document.querySelectorAll('table.takes tbody tr'); return r.length > 0 && [...r].map(t => t.textContent);",
            )
            .await;
        let rows = rows.as_array().unwrap();
        assert_eq!(rows.len(), 1, "{rows:?}");
        assert!(rows[0].as_str().unwrap().contains("flatfoot"), "{rows:?}");
        browser
            .visit(
                &format!("{}/#/take/{fp_id}", srv.base),
                "the events strip again",
                "const e = document.querySelectorAll('svg.events g.event'); return e.length > 0 && e.length;",
            )
            .await;
        let first = &fp_events(&srv, fp_id).await;
        browser
            .js(
                "document.querySelectorAll('svg.events g.event')[0].dispatchEvent(new MouseEvent('click', { bubbles: true })); return true;",
                json!([]),
            )
            .await;
        browser
            .until(
                "the event's frame",
                &format!(
                    "return document.querySelector('canvas.view').dataset.frame === '{first}';"
                ),
            )
            .await;
        browser.screenshot("take-events").await;
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
        let overflow = browser.overflow().await;
        assert!(overflow <= 0, "horizontal overflow {overflow}");
        browser.screenshot("take-phone").await;
        assert!(browser.console_errors().await.is_empty());

        srv.stop().await;
        t.finish().await;
    }
    browser.quit().await;
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
        let (status, e) = srv.get_json(&format!("/v1/takes/{id}/errors")).await;
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
        let (status, e) = srv.get_json(&format!("/v1/takes/{sid}/errors")).await;
        assert_eq!(status, 409, "{e}");
        let (status, _) = srv.get_json("/v1/takes/nope/errors").await;
        assert_eq!(status, 404);
        srv.stop().await;
        t.finish().await;
    }
}

/// The live page follows an open stream as a producer sends it in real time: the figure is
/// drawn and moves, the delays from capture and from the server to the screen are shown,
/// and the page says when the stream ends.
#[tokio::test]
async fn the_live_page_shows_a_stream_as_it_arrives() {
    let Some(browser) = Browser::with_corpus().await else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    // A real take's positions, sent again as a live capture would send them.
    let src = stored(&srv, "name=131_02&max_error_mm=1", "bvh/cmu/131_02.bvh").await;
    let src_id = src["id"].as_str().unwrap();
    let (_, _, bytes) = srv
        .get(&format!("/v1/takes/{src_id}/frames?format=f32"))
        .await;
    let points = src["points"].as_u64().unwrap() as usize;
    let (_, src) = srv.get_json(&format!("/v1/takes/{src_id}")).await;
    let (status, _, stream) = srv
        .post_json(
            "/v1/streams",
            &json!({"name": "stage-live", "library": "stage", "fps": 120.0, "points": points,
                    "unit": src["metres_per_unit"].to_string(), "max_error_mm": 1.0}),
        )
        .await;
    assert_eq!(status, 201, "{stream}");
    let sid = stream["id"].as_str().unwrap().to_string();

    let status = browser
        .visit(
            &format!("{}/#/live/{sid}", srv.base),
            "the live page",
            "const s = document.querySelector('.status'); return s && s.textContent.startsWith('live') && s.textContent;",
        )
        .await;
    assert!(status.as_str().unwrap().contains("as they arrive"));

    // 12 frames every 100 ms, each append saying when its last frame was captured, until
    // the page has been seen to do what it should (not a fixed window of frames, which a
    // slow machine could miss).
    let (client, base, id) = (srv.client.clone(), srv.base.clone(), sid.clone());
    let frame_bytes = points * 12;
    let src_frames = bytes.clone();
    let (stop, stopped) = tokio::sync::watch::channel(false);
    let producer = tokio::spawn(async move {
        let start = tokio::time::Instant::now();
        for (i, batch) in bytes.chunks(12 * frame_bytes).enumerate() {
            tokio::time::sleep_until(start + Duration::from_millis(100 * (i as u64 + 1))).await;
            if *stopped.borrow() {
                break;
            }
            let r = client
                .post(format!(
                    "{base}/v1/streams/{id}/frames?captured_ms={}",
                    mocapstore::service::now_ms()
                ))
                .header("content-type", "application/octet-stream")
                .body(batch.to_vec())
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 200);
        }
    });
    let first = browser
        .until(
            "frames shown",
            "const f = Number(document.querySelector('canvas.view').dataset.frame); return f > 60 && f;",
        )
        .await;
    // A stream has no skeleton: its points, in blue.
    let points_drawn = pixels(&browser, 0, "b > 150 && r < 100").await;
    assert!(
        points_drawn > 100,
        "the figure is drawn: {points_drawn} pixels"
    );
    let later = browser
        .until(
            "the figure moving",
            &format!("const f = Number(document.querySelector('canvas.view').dataset.frame); return f > {first} + 60 && f;"),
        )
        .await;
    assert!(later.as_u64() > first.as_u64());
    let delays = browser
        .until(
            "the delays",
            "const d = [...document.querySelectorAll('.live-stats dd')]; return d[2].dataset.median && d[3].dataset.median && [Number(d[2].dataset.median), Number(d[3].dataset.median), d[2].textContent, d[3].textContent];",
        )
        .await;
    let (capture, server) = (delays[0].as_f64().unwrap(), delays[1].as_f64().unwrap());
    println!(
        "live page: capture → visible {}, server → visible {} (median / p95)",
        delays[2], delays[3]
    );
    // Frames are captured before the server takes them, and shown after.
    assert!(server >= -20.0, "{delays}");
    assert!(capture >= server - 20.0, "{delays}");
    assert_eq!(unnamed_controls(&browser).await, json!([]));
    browser.screenshot("live").await;
    stop.send_replace(true);
    producer.await.unwrap();

    let (status, _, _) = srv
        .post_json(&format!("/v1/streams/{sid}/finish"), &json!({}))
        .await;
    assert_eq!(status, 200);
    let ended = browser
        .until(
            "the end of the stream",
            "const s = document.querySelector('.status'); return s.textContent.includes('has ended') && s.querySelector('a').getAttribute('href');",
        )
        .await;
    assert_eq!(ended, json!(format!("#/take/{sid}")));
    let skipped = browser
        .js(
            "return document.querySelectorAll('.live-stats dd')[4].textContent;",
            json!([]),
        )
        .await;
    assert_eq!(skipped, "0");
    let errors = browser.console_errors().await;
    assert!(errors.is_empty(), "{errors:?}");

    // Another server on the same database forwards the events of a stream coded here:
    // its live page shows the stream as it arrives, and sees it end.
    let other = common::start(t.store.clone(), 64 << 20).await;
    let (_, _, stream) = srv
        .post_json(
            "/v1/streams",
            &json!({"name": "elsewhere", "fps": 120.0, "points": points,
                    "unit": src["metres_per_unit"].to_string(), "max_error_mm": 1.0}),
        )
        .await;
    let sid = stream["id"].as_str().unwrap().to_string();
    let send = |from: usize, to: usize| {
        srv.client
            .post(format!("{}/v1/streams/{sid}/frames?flush=true", srv.base))
            .header("content-type", "application/octet-stream")
            .body(src_frames[from * frame_bytes..to * frame_bytes].to_vec())
            .send()
    };
    assert_eq!(send(0, 240).await.unwrap().status(), 200);
    let status = browser
        .visit(
            &format!("{}/#/live/{sid}", other.base),
            "a stream coded by another server, through this one",
            "const c = document.querySelector('canvas.view'); return c?.dataset.frame === '239' && document.querySelector('.status').textContent;",
        )
        .await;
    assert!(
        !status.as_str().unwrap().contains("newest stored frame"),
        "live, not the stored frames: {status}"
    );
    assert_eq!(send(240, 300).await.unwrap().status(), 200);
    browser
        .until(
            "frames appended on the coding server, through the other",
            "return document.querySelector('canvas.view')?.dataset.frame === '299';",
        )
        .await;
    let (status, _, _) = srv
        .post_json(&format!("/v1/streams/{sid}/finish"), &json!({}))
        .await;
    assert_eq!(status, 200);
    browser
        .until(
            "the end of the stream coded elsewhere",
            "return document.querySelector('.status').textContent.includes('has ended');",
        )
        .await;
    let errors = browser.console_errors().await;
    assert!(errors.is_empty(), "{errors:?}");
    browser.quit().await;
    other.stop().await;
    srv.stop().await;
    t.finish().await;
}

/// One take stored at two bounds, compared: overlaid and side by side, in step, from a
/// shareable URL; the frame-by-frame distance between them within the sum of the bounds.
#[tokio::test]
async fn the_compare_page_keeps_takes_in_step() {
    let Some(browser) = Browser::with_corpus().await else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let fine = stored(&srv, "name=fine&max_error_mm=1", "bvh/cmu/131_02.bvh").await;
    let coarse = stored(&srv, "name=coarse&max_error_mm=20", "bvh/cmu/131_02.bvh").await;
    let (a, b) = (fine["id"].as_str().unwrap(), coarse["id"].as_str().unwrap());

    // Ticking both takes in the library opens them on the compare page.
    browser
        .visit(
            &format!("{}/#/", srv.base),
            "the listing",
            "return document.querySelectorAll('table.takes tbody tr').length === 2;",
        )
        .await;
    let hash = browser
        .js(
            "document.querySelectorAll('table.takes tbody input[type=checkbox]').forEach(c => c.click());
             document.querySelector('button.compare').click();
             return location.hash;",
            json!([]),
        )
        .await;
    let hash = hash.as_str().unwrap();
    assert!(
        hash.starts_with("#/compare?ids=") && hash.contains(a) && hash.contains(b),
        "{hash}"
    );

    // Overlaid at second 3: both figures drawn, in their own colours.
    let url = format!("{}/#/compare?ids={a},{b}&t=3", srv.base);
    browser
        .visit(
            &url,
            "both takes at second 3",
            "return document.querySelector('canvas.view')?.dataset.frames === '360,360';",
        )
        .await;
    let blue = pixels(&browser, 0, "b > 150 && r < 100").await;
    let red = pixels(&browser, 0, "r > 150 && g < 100 && b < 100").await;
    assert!(blue > 30 && red > 30, "blue and red figures: {blue}, {red}");
    // Each take is within its bound of the original, so within 21 mm of the other.
    let now = browser
        .js(
            "return [...document.querySelectorAll('table.legend td.now')].map(e => e.textContent);",
            json!([]),
        )
        .await;
    let second = now[1].as_str().unwrap();
    let max: f64 = second
        .split("max ")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{now}"));
    assert!(max > 0.0 && max <= 21.0, "{now}");
    browser.screenshot("compare-overlay").await;

    // Playing moves both in step; pausing writes the view into the URL.
    browser.click("button.play").await;
    let frames = browser
        .until(
            "both takes playing",
            "const f = document.querySelector('canvas.view').dataset.frames.split(',').map(Number); return f[0] > 400 && f;",
        )
        .await;
    assert_eq!(frames[0], frames[1], "in step: {frames}");
    browser.click("button.play").await;
    let shared = browser
        .until(
            "the shared URL",
            "return /[?&]t=([0-9.]+)/.test(location.hash) && Number(location.hash.match(/[?&]t=([0-9.]+)/)[1]) > 3 && location.hash;",
        )
        .await;
    let shared = shared.as_str().unwrap().to_string();
    assert!(
        shared.contains(&format!("ids={a}%2C{b}")) && shared.contains("mode=overlay"),
        "{shared}"
    );
    let paused = browser
        .js(
            "return document.querySelector('canvas.view').dataset.frames;",
            json!([]),
        )
        .await;

    // Side by side, from the URL: one view per take, both drawn, at the same frames.
    browser.click("input[value=side]").await;
    browser
        .until(
            "side by side",
            "return location.hash.includes('mode=side') && document.querySelectorAll('canvas.view').length === 2 && document.querySelector('canvas.view').dataset.frames;",
        )
        .await;
    assert!(drawn(&browser, 0).await > 100 && drawn(&browser, 1).await > 100);
    browser.screenshot("compare-side").await;
    // The shared URL opens the same view at the same playhead.
    browser.goto(&format!("{}/", srv.base)).await;
    let again = browser
        .visit(
            &format!("{}/{shared}", srv.base),
            "the shared view",
            "return document.querySelector('canvas.view')?.dataset.frames;",
        )
        .await;
    assert_eq!(again, paused);
    assert_eq!(unnamed_controls(&browser).await, json!([]));
    assert!(browser.console_errors().await.is_empty());

    // Phone-sized: the side-by-side views stack and nothing overflows.
    browser.viewport(390, 844).await;
    browser.goto(&format!("{}/", srv.base)).await;
    browser
        .visit(
            &format!("{}/{}", srv.base, shared.replace("mode=overlay", "mode=side")),
            "the phone layout",
            "return document.querySelectorAll('canvas.view').length === 2 && document.querySelector('canvas.view').dataset.frames;",
        )
        .await;
    let overflow = browser.overflow().await;
    assert!(overflow <= 0, "horizontal overflow {overflow}");
    browser.screenshot("compare-phone").await;
    browser.quit().await;
    srv.stop().await;
    t.finish().await;
}

/// The take page opens the GLB it would download (three.js's GLTFLoader, as Blender and
/// web players read it) beside the figure, without console errors; at t = 1 s a joint of
/// the loaded glTF stands where the service's own positions put it.
#[tokio::test]
async fn the_take_page_opens_the_glb_it_would_download() {
    let Some(browser) = Browser::with_corpus().await else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let bvh = stored(&srv, "name=131_02&max_error_mm=1", "bvh/cmu/131_02.bvh").await;
    let id = bvh["id"].as_str().unwrap().to_string();
    browser
        .visit(
            &format!("{}/#/take/{id}", srv.base),
            "the first frame",
            "return document.querySelector('canvas.view')?.dataset.frame === '0';",
        )
        .await;
    browser.click("button.open-glb").await;
    browser
        .until("the GLB loaded", "return !!window.mocapstoreGlb;")
        .await;
    // The service's own positions of the first frame at or after 1 s, and its time.
    let (status, _, body) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?unit=m&up=y&t0=1&t1=1.02&points=LeftWrist"
        ))
        .await;
    assert_eq!(status, 200);
    let v: Value = serde_json::from_slice(&body).unwrap();
    // Its time as the GLB keys it, at the take's printed rate (120.00048 fps: frame 120,
    // the first of the second from 1 s at 120 fps, is at 0.999996 s).
    let t1 = v["start"].as_f64().unwrap() / v["fps"].as_f64().unwrap();
    assert!((0.9999..1.01).contains(&t1), "{t1}");
    let at = browser
        .js(
            "window.mocapstoreGlb.at(arguments[0]); return window.mocapstoreGlb.position('LeftWrist');",
            json!([t1]),
        )
        .await;
    let at: Vec<f64> = at
        .as_array()
        .unwrap_or_else(|| panic!("no LeftWrist node: {at}"))
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let want: Vec<f64> = v["frames"][0][0]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let d =
        ((at[0] - want[0]).powi(2) + (at[1] - want[1]).powi(2) + (at[2] - want[2]).powi(2)).sqrt();
    // The same frame: glTF's f32 keys composed down the chain against the decoded
    // positions, well within the bound (1 mm).
    assert!(
        d < 1e-3,
        "LeftWrist at 1 s: glTF {at:?}, service {want:?}: {d} m apart"
    );
    assert!(browser.console_errors().await.is_empty());
    browser.quit().await;
    srv.stop().await;
    t.finish().await;
}

/// Issue 48: takes stand up in the browser, whatever axis they were captured along. The
/// take page turns each by its body's up (never by its extent): a Bandai walk and a CMU
/// walk (Y-up, long walks that once lay on their side) and a Plug-in Gait C3D (Z-up) show
/// the head above the feet in three.js's world at frame 0, and the GLB three.js's
/// GLTFLoader opens does too.
#[tokio::test(flavor = "multi_thread")]
async fn takes_stand_up_in_the_viewer() {
    let Some(browser) = Browser::with_corpus().await else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    // (file, its up, the second looked at and its frame (where the markers are seen), the
    // head and ankle nodes of its GLB).
    let bandai = "bvh/bandai/dataset-1_walk_normal_001.bvh";
    for (rel, up, (t, frame), head, ankle) in [
        (bandai, "y", (0.0, 0), Some("Head"), "Foot_L"),
        ("bvh/cmu/01_01.bvh", "y", (0.0, 0), Some("Head"), "LeftFoot"),
        ("c3d/btkdata__others__Gait.c3d", "z", (2.0, 200), None, ""),
    ] {
        let take = stored(&srv, "max_error_mm=1", rel).await;
        let id = take["id"].as_str().unwrap().to_string();
        let seen = browser
            .visit(
                &format!("{}/#/take/{id}?t={t}", srv.base),
                "the frame",
                &format!("const c = document.querySelector('canvas.view'); return c?.dataset.frame === '{frame}' && [c.dataset.up, c.dataset.head, c.dataset.feet];"),
            )
            .await;
        assert_eq!(seen[0], up, "{rel}: {seen}");
        let y = |v: &Value| -> f64 {
            v.as_str()
                .and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("{rel}: {seen}"))
        };
        let (h, f) = (y(&seen[1]), y(&seen[2]));
        assert!(
            h - f > 1.0,
            "{rel}: head at {h} m, feet at {f} m in the view"
        );
        if let Some(head) = head {
            // The last page's GLB is not this one's.
            browser.js("window.mocapstoreGlb = null;", json!([])).await;
            browser.click("button.open-glb").await;
            browser
                .until("the GLB loaded", "return !!window.mocapstoreGlb;")
                .await;
            let ys = browser
                .js(
                    "const g = window.mocapstoreGlb; g.at(0); return [g.position(arguments[0])[1], g.position(arguments[1])[1]];",
                    json!([head, ankle]),
                )
                .await;
            let (h, a) = (ys[0].as_f64().unwrap(), ys[1].as_f64().unwrap());
            assert!(
                h - a > 1.0,
                "{rel}: in the GLB the head is at {h} m, the ankle at {a} m"
            );
        }
    }
    assert!(browser.console_errors().await.is_empty());
    browser.quit().await;
    srv.stop().await;
    t.finish().await;
}

/// Issue 52: the take page puts a take on a chosen rig beside the original. A CMU walk
/// (131_02) on the Mixamo Y Bot uploaded as a skeleton opens, as the GLB the server writes,
/// in three.js's GLTFLoader with the Y Bot's skinned meshes, upright (its head above its
/// feet, as three.js evaluates the file's node tree) and walking (its hips cover ground)
/// at several times; a screenshot shows it beside the take's own figure.
#[tokio::test]
async fn a_take_plays_on_an_uploaded_character_beside_the_original() {
    let Some(browser) = Browser::with_corpus().await else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let r = srv
        .client
        .post(format!("{}/v1/skeletons", srv.base))
        .body(corpus_bytes("gltf/mixamo_ybot_character.glb"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let rig: Value = r.json().await.unwrap();
    let ybot = rig["id"].as_str().unwrap().to_string();
    let take = stored(&srv, "name=131_02&max_error_mm=1", "bvh/cmu/131_02.bvh").await;
    let id = take["id"].as_str().unwrap().to_string();
    browser
        .visit(
            &format!("{}/#/take/{id}?t=1", srv.base),
            "the frame at 1 s",
            "return document.querySelector('canvas.view')?.dataset.frame === '120';",
        )
        .await;
    // The uploaded rigs join the choice once listed.
    browser
        .until(
            "the Y Bot among the rigs",
            &format!(
                "const s = document.querySelector('select.out-rig'); \
                 if (!s?.querySelector('option[value=\"{ybot}\"]')) return false; \
                 s.value = '{ybot}'; return true;"
            ),
        )
        .await;
    browser.click("button.open-glb").await;
    browser
        .until("the GLB loaded", "return !!window.mocapstoreGlb;")
        .await;
    let skinned = browser
        .js(
            "let n = 0; window.mocapstoreGlb.gltf.scene.traverse((o) => { if (o.isSkinnedMesh) n++; }); return n;",
            json!([]),
        )
        .await;
    assert_eq!(skinned, 2, "the Y Bot's two skinned meshes");
    let mut hips = Vec::new();
    for at in [0.5, 2.0, 4.0, 6.0, 8.0, 10.0] {
        let v = browser
            .js(
                "const g = window.mocapstoreGlb; g.at(arguments[0]); \
                 return ['mixamorig:Head', 'mixamorig:LeftFoot', 'mixamorig:RightFoot', 'mixamorig:Hips'].map((n) => g.position(n));",
                json!([at]),
            )
            .await;
        let p = |i: usize| -> Vec<f64> {
            v[i].as_array()
                .unwrap_or_else(|| panic!("at {at} s: {v}"))
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let (head, left, right) = (p(0), p(1), p(2));
        assert!(
            head[1] - left[1].max(right[1]) > 1.0,
            "at {at} s the head is at {head:?}, the feet at {left:?} and {right:?}"
        );
        hips.push(p(3));
    }
    let (a, b) = (&hips[0], &hips[hips.len() - 1]);
    let ground = ((b[0] - a[0]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
    assert!(
        ground > 1.0,
        "the hips moved {ground} m across the floor: {hips:?}"
    );
    // Both at 1 s, the take's own figure and the Y Bot beside it.
    browser
        .js("window.mocapstoreGlb.at(1.0); return true;", json!([]))
        .await;
    browser.screenshot("take-on-ybot").await;
    assert!(browser.console_errors().await.is_empty());
    browser.quit().await;
    srv.stop().await;
    t.finish().await;
}

/// Issue 51: on a take page, the loop range is searched with "Find similar"; the ranges
/// found are listed with their scores, nearest first (a copy of the take, at the very range,
/// scores 0), and "play beside" plays the first one side by side with the query, each from
/// its own start, in step.
#[tokio::test]
async fn the_take_page_finds_similar_motion_and_plays_it_beside() {
    let Some(browser) = Browser::with_corpus().await else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let walk = "bvh/bandai/dataset-1_walk_normal_001.bvh";
    let query = stored(&srv, "name=walk&library=a&max_error_mm=1", walk).await;
    let copy = stored(&srv, "name=copy&library=b&max_error_mm=1", walk).await;
    for (name, rel) in [
        ("other-walk", "bvh/bandai/dataset-1_walk_happy_001.bvh"),
        ("bow", "bvh/bandai/dataset-1_bow_normal_001.bvh"),
        ("bye", "bvh/bandai/dataset-1_bye_normal_001.bvh"),
    ] {
        stored(&srv, &format!("name={name}&library=b&max_error_mm=1"), rel).await;
    }
    let (q, c) = (query["id"].as_str().unwrap(), copy["id"].as_str().unwrap());

    // Seconds 1 to 3 of the walk, chosen as the loop range, searched.
    browser
        .visit(
            &format!("{}/#/take/{q}?t=1&loop=1&from=1&to=3", srv.base),
            "the take page",
            "return document.querySelector('canvas.view')?.dataset.frame && document.querySelector('button.find-similar');",
        )
        .await;
    browser.click("button.find-similar").await;
    let rows = browser
        .until(
            "the results",
            "const rows = [...document.querySelectorAll('table.similar tbody tr')];
             return rows.length && rows.map(r => [...r.querySelectorAll('td')].map(d => d.textContent));",
        )
        .await;
    let rows = rows.as_array().unwrap();
    // The query's own range never comes back (its take does, at a range apart from it);
    // every take is found, nearest first.
    assert_eq!(rows.len(), 5, "{rows:?}");
    let cell = |r: usize, c: usize| rows[r][c].as_str().unwrap().to_string();
    assert_eq!(cell(0, 1), "copy", "{rows:?}");
    assert_eq!(cell(0, 3), "1.00–3.00", "{rows:?}");
    let scores: Vec<f64> = (0..rows.len())
        .map(|r| cell(r, 5).parse().unwrap())
        .collect();
    assert_eq!(scores[0], 0.0, "{rows:?}");
    assert!(scores.windows(2).all(|w| w[0] <= w[1]), "{scores:?}");
    assert_eq!(cell(1, 1), "walk", "{rows:?}");
    let own: Vec<f64> = cell(1, 3).split('–').map(|x| x.parse().unwrap()).collect();
    assert!(
        own[0] >= 3.0 || own[1] <= 1.0,
        "apart from the query: {rows:?}"
    );
    assert_eq!(cell(2, 1), "other-walk", "the other walk next: {rows:?}");
    let status = browser
        .js(
            "return document.querySelector('.similar-status').textContent;",
            json!([]),
        )
        .await;
    assert!(
        status.as_str().unwrap().contains("among 5 takes"),
        "{status}"
    );
    browser
        .js(
            "document.querySelector('.similar-panel').scrollIntoView(); return true;",
            json!([]),
        )
        .await;
    browser.screenshot("similar-results").await;
    assert_eq!(unnamed_controls(&browser).await, json!([]));

    // The copy's range beside the query's: both from second 1 (frame 30 at 30 fps).
    browser.click("table.similar a.play-beside").await;
    let frames = browser
        .until(
            "the pair side by side",
            "const c = document.querySelectorAll('canvas.view');
             return location.hash.startsWith('#/compare') && c.length === 2 && c[0].dataset.frames;",
        )
        .await;
    assert_eq!(frames, "30,30", "each from its own start");
    let hash = browser.js("return location.hash;", json!([])).await;
    let hash = hash.as_str().unwrap();
    assert!(
        hash.contains(&format!("ids={q}%2C{c}")) && hash.contains("mode=side"),
        "{hash}"
    );
    assert!(drawn(&browser, 0).await > 100 && drawn(&browser, 1).await > 100);
    // Playing moves both on; the loop keeps them within the query's two seconds.
    browser.click("button.play").await;
    let moved = browser
        .until(
            "both playing",
            "const f = document.querySelector('canvas.view').dataset.frames.split(',').map(Number); return f[0] > 40 && f;",
        )
        .await;
    assert_eq!(moved[0], moved[1], "in step: {moved}");
    assert!(moved[0].as_i64().unwrap() <= 90, "{moved}");
    browser.click("button.play").await;
    browser.screenshot("similar-beside").await;

    // The query's own take, at another range, plays from that range's start beside it.
    browser.goto(&format!("{}/", srv.base)).await;
    browser
        .visit(
            &format!("{}/#/take/{q}?t=1&loop=1&from=1&to=3", srv.base),
            "the take page again",
            "return document.querySelector('canvas.view')?.dataset.frame && document.querySelector('button.find-similar');",
        )
        .await;
    browser.click("button.find-similar").await;
    let second = browser
        .until(
            "the results again",
            "const a = document.querySelectorAll('table.similar a.play-beside')[1]; return a && a.getAttribute('href');",
        )
        .await;
    let second = second.as_str().unwrap().to_string();
    let start: f64 = second
        .split("starts=")
        .nth(1)
        .and_then(|s| s.split('&').next())
        .map(|s| s.replace("%2C", ","))
        .and_then(|s| s.split(',').nth(1).and_then(|x| x.parse().ok()))
        .unwrap_or_else(|| panic!("{second}"));
    browser.goto(&format!("{}/{second}", srv.base)).await;
    let frames = browser
        .until(
            "the other walk beside",
            "const c = document.querySelectorAll('canvas.view'); return c.length === 2 && c[0].dataset.frames;",
        )
        .await;
    let want = format!("30,{}", (start * 30.0 + 1e-6).floor() as i64);
    assert_eq!(frames, want.as_str(), "{second}");
    assert!(browser.console_errors().await.is_empty());
    browser.quit().await;
    srv.stop().await;
    t.finish().await;
}
