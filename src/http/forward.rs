//! Forwarding a live stream's request to the server that codes it
//! ([`crate::service::streams::Route::Owner`]): the request as it came (its token, its
//! body, its query), marked as forwarded so that it is never sent on again, and the
//! owner's answer passed back as it comes — a watcher's event stream included.

use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::http::{header, HeaderMap, HeaderName, Method, Request, Uri};
use axum::response::Response;
use http_body_util::Full;
use hyper_util::client::legacy::connect::HttpConnector;
use hyper_util::client::legacy::Client;
use hyper_util::rt::TokioExecutor;

use crate::service::budget::Holder;

/// Marks a request one server forwarded to another (its value: the sender's id).
pub const FORWARDED: HeaderName = HeaderName::from_static("x-mocapstore-forwarded");

/// How long a server waits for the owner to take the connection: past it the owner is
/// taken for stopped (its lease then decides).
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);

/// How long a server waits for the head of the owner's answer: long, since a finish may
/// re-encode the whole take, and a slow success answered 503 would be sent again (an append
/// codes a chunk or two; a watch answers at once). Only a connection that cannot be made
/// ([`CONNECT_TIMEOUT`]) says the owner stopped; its lease then decides.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(600);

/// The request headers passed on: who the caller is, what the body is, and the name and
/// origin the caller used (the owner checks a browser's write against them as this server
/// would have).
const PASSED: [HeaderName; 5] = [
    header::AUTHORIZATION,
    header::CONTENT_TYPE,
    header::ACCEPT,
    header::HOST,
    header::ORIGIN,
];

/// Answer headers not passed back: they describe the hop, not the answer (RFC 9110
/// §7.6.1), with any the answer's `Connection` names.
const HOP: [HeaderName; 6] = [
    header::CONNECTION,
    header::TRANSFER_ENCODING,
    header::UPGRADE,
    header::TE,
    header::TRAILER,
    HeaderName::from_static("keep-alive"),
];

/// A pooled HTTP/1.1 client to the other servers.
pub struct Forwarder {
    client: Client<HttpConnector, Full<Bytes>>,
    /// This server's id, sent with each forwarded request.
    from: String,
}

impl Forwarder {
    pub fn new(from: &str) -> Forwarder {
        let mut connector = HttpConnector::new();
        connector.set_connect_timeout(Some(CONNECT_TIMEOUT));
        connector.set_nodelay(true);
        let client = Client::builder(TokioExecutor::new())
            .pool_idle_timeout(Duration::from_secs(30))
            .build(connector);
        Forwarder {
            client,
            from: from.to_string(),
        }
    }

    /// Send the request to the server at `base` (`http://host:port`) and hand back its
    /// answer; `Err` (why) if it could not be reached or did not answer in time.
    pub async fn send(
        &self,
        base: &str,
        method: Method,
        uri: &Uri,
        headers: &HeaderMap,
        body: Bytes,
        holder: &Holder,
    ) -> Result<Response, String> {
        let path = uri.path_and_query().map_or("/", |p| p.as_str());
        let target: Uri = format!("{}{path}", base.trim_end_matches('/'))
            .parse()
            .map_err(|e| format!("the owner's address {base:?}: {e}"))?;
        let mut request = Request::builder().method(method).uri(target);
        for name in PASSED {
            for v in headers.get_all(&name) {
                request = request.header(&name, v);
            }
        }
        request = request.header(FORWARDED, self.from.as_str());
        // The owner counts an anonymous caller by its address if it trusts this server as
        // a proxy (`--trusted-proxy`).
        if let Holder::Address(ip) = holder {
            request = request.header("x-forwarded-for", ip.to_string());
        }
        let request = request
            .body(Full::new(body))
            .map_err(|e| format!("building the forwarded request: {e}"))?;
        let answer = tokio::time::timeout(ANSWER_TIMEOUT, self.client.request(request))
            .await
            .map_err(|_| format!("no answer from {base} within {ANSWER_TIMEOUT:?}"))?
            .map_err(|e| format!("{base}: {e}"))?;
        let (mut parts, body) = answer.into_parts();
        let named: Vec<HeaderName> = parts
            .headers
            .get_all(header::CONNECTION)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .filter_map(|n| HeaderName::from_bytes(n.trim().as_bytes()).ok())
            .collect();
        for name in HOP.into_iter().chain(named) {
            parts.headers.remove(name);
        }
        Ok(Response::from_parts(parts, Body::new(body)))
    }
}
