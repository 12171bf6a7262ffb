//! The web viewer: its files (`ui/`, with three.js vendored under `ui/vendor/three/`) built
//! into the binary, served at `/` and `/ui/…`. No build step and no CDN: the machine running
//! the service may be offline. The pages call the same `/v1` API as every other client,
//! with the token the user gives them; the files themselves hold no data and need none.
//!
//! Served with a strict [`CONTENT_SECURITY_POLICY`]. For it, the vendored
//! `OrbitControls.js` imports `./three.module.js` instead of the bare `three` (one line
//! changed from upstream), so the page needs no inline import map.

use axum::extract::Path;
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};

use super::error::ApiError;

/// One file of the viewer.
struct Asset {
    path: &'static str,
    content_type: &'static str,
    bytes: &'static [u8],
}

macro_rules! asset {
    ($path:literal, $type:expr) => {
        Asset {
            path: $path,
            content_type: $type,
            bytes: include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/ui/", $path)),
        }
    };
}

const JS: &str = "text/javascript; charset=utf-8";

static ASSETS: &[Asset] = &[
    asset!("index.html", "text/html; charset=utf-8"),
    asset!("style.css", "text/css; charset=utf-8"),
    asset!("app.js", JS),
    asset!("api.js", JS),
    asset!("dom.js", JS),
    asset!("library.js", JS),
    asset!("take.js", JS),
    asset!("stats.js", JS),
    asset!("player.js", JS),
    asset!("frames.js", JS),
    asset!("transport.js", JS),
    asset!("live.js", JS),
    asset!("compare.js", JS),
    asset!("similar.js", JS),
    asset!("vendor/three/three.module.js", JS),
    asset!("vendor/three/three.core.js", JS),
    asset!("vendor/three/OrbitControls.js", JS),
    asset!("vendor/three/GLTFLoader.js", JS),
    asset!("vendor/three/BufferGeometryUtils.js", JS),
    asset!("vendor/three/SkeletonUtils.js", JS),
    asset!("vendor/three/LICENSE", "text/plain; charset=utf-8"),
];

/// A build's files never change while it runs: their ETags (a hash of the bytes) are
/// computed once.
fn etag(i: usize) -> &'static str {
    static TAGS: std::sync::OnceLock<Vec<String>> = std::sync::OnceLock::new();
    &TAGS.get_or_init(|| {
        ASSETS
            .iter()
            .map(|a| format!("\"{}\"", &blake3::hash(a.bytes).to_hex()[..20]))
            .collect()
    })[i]
}

fn serve(i: usize, headers: &HeaderMap) -> Response {
    let (a, tag) = (&ASSETS[i], etag(i));
    let fresh = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == tag));
    let mut out = if fresh {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        a.bytes.into_response()
    };
    let h = out.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(a.content_type),
    );
    h.insert(
        header::ETAG,
        HeaderValue::from_str(tag).expect("hex is a valid header value"),
    );
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CONTENT_SECURITY_POLICY),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    out
}

/// The viewer's pages run only their own files: no inline script or style attribute (so
/// an injected one does nothing), no other origin, and no framing by another site
/// (clickjacking). Its styles are set from script through the CSSOM, which this allows;
/// three.js is imported by path rather than through an inline import map.
pub const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; script-src 'self'; \
    style-src 'self'; img-src 'self' data: blob:; connect-src 'self'; font-src 'self'; \
    object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'";

/// `GET /`: the viewer's page.
pub async fn index(headers: HeaderMap) -> Response {
    serve(0, &headers)
}

/// `GET /ui/{*path}`: one of the viewer's files.
pub async fn file(Path(path): Path<String>, headers: HeaderMap) -> Response {
    match ASSETS.iter().position(|a| a.path == path) {
        Some(i) => serve(i, &headers),
        None => ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!("the viewer has no file {path:?}"),
        )
        .into_response(),
    }
}
