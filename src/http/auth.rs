//! Who is asking, and whether they may: the bearer token of each request, the scope each
//! route needs, browser safety (cross-origin writes, DNS rebinding), rate limits and the
//! audit entry of every write. Tokens themselves, grants and the log live in
//! [`crate::service::access`]; this module reads headers and answers with statuses.
//!
//! # Order
//! [`front`] runs before routing: it refuses cross-origin writes, authenticates (401), puts
//! the [`Caller`] in the request, and sends the request on either through the rate limiter
//! (any request with a token, anonymous ones on a server open beyond loopback, and every
//! refusal, keyed by address) or straight on (anonymous on loopback). After routing,
//! [`super::routes::require`] checks what the route table declares for the route: its scope
//! (403) and, for a route whose `{id}` names a take, the caller's libraries (404). When the
//! answer is back, [`front`] records writes in the audit log, refusals included.
//!
//! # Routes and scopes
//! Declared once, route by route, in the table in `http/mod.rs` (`declare`); in short:
//!
//! | route | scope |
//! |---|---|
//! | `GET /healthz`, `GET /readyz`, `GET /` and `GET /ui/…` (the viewer's files) | none |
//! | every other `GET` | read |
//! | `POST /v1/takes`, `PATCH /v1/takes/{id}`, `POST /v1/streams…`, `POST /v1/skeletons` | write |
//! | `DELETE /v1/takes/{id}`, `POST`/`DELETE /v1/bases…`, `DELETE /v1/skeletons/{id}`, `/v1/tokens…`, `GET /v1/audit`, `GET /metrics` | admin |
//!
//! A read or write token limited to libraries sees and changes only takes in them, and
//! only the skeletons, bases, jobs and statistics of its libraries (and every uploaded rig,
//! which holds no library's motion); a take of another library answers 404, as one that
//! does not exist. An admin token is over every library.
//! `/metrics` (archive-wide totals) is also served without a token on a separate address
//! when the operator asks for one (`serve --metrics-listen`), for a scraper on an internal
//! network.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, HeaderMap, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::Router;
use tower::ServiceExt;
use tower_governor::key_extractor::KeyExtractor;
use tower_governor::GovernorError;

use super::error::ApiError;
use crate::service::access::{self, Attempt, AuditLog, Authenticator, Caller};
use crate::service::budget::Holder;
use crate::store::Store;

/// How the server treats requests beyond their tokens.
#[derive(Debug, Clone, Default)]
pub struct Policy {
    /// Origins (`https://viewer.example:8443`) whose pages may call the API from a browser:
    /// CORS answers for them, and their writes are not refused as cross-origin.
    pub allowed_origins: Vec<String>,
    /// Serve anonymous requests beyond loopback (`serve --insecure-no-auth`): requests
    /// may name the server by IP address as well as by a loopback name, and anonymous
    /// requests are rate-limited per address.
    pub open_beyond_loopback: bool,
    /// Host names (besides loopback names and, beyond loopback, IP addresses) that requests
    /// to a server without tokens may name (`serve --allow-host`); `*` allows any.
    pub allowed_hosts: Vec<String>,
}

/// What [`front`] needs.
#[derive(Clone)]
pub struct Front {
    pub store: Store,
    pub auth: Arc<Authenticator>,
    pub audit: Arc<AuditLog>,
    pub policy: Arc<Policy>,
    /// The same routes behind the rate limiter; `None` when limits are off.
    pub limited: Option<Router>,
    /// [`refusal`] behind the same limiter: refused requests are limited per address, so
    /// guessing tokens or flooding the audit log with refusals is slowed like anything else.
    pub refuse: Option<Router>,
}

/// Why [`front`] refuses a request, for [`refusal`] to answer.
#[derive(Debug, Clone)]
struct Refused {
    status: StatusCode,
    code: &'static str,
    message: String,
    /// `Retry-After`, for a refusal that is a 503 (the database away while checking the
    /// token).
    retry_after: Option<u64>,
}

/// The answer to a refused request, once it has passed the rate limiter.
pub async fn refusal(req: Request) -> Response {
    match req.extensions().get::<Refused>() {
        Some(r) => ApiError {
            retry_after: r.retry_after,
            ..ApiError::new(r.status, r.code, r.message.clone())
        }
        .into_response(),
        None => ApiError::unauthorized("refused").into_response(),
    }
}

/// The one write route not audited entry by entry (see [`front`]).
const UNAUDITED: &str = "/v1/streams/{id}/frames";

/// The route a request matched, for its audit entry (set by [`super::routes::require`]).
#[derive(Debug, Clone)]
pub(super) struct Route(pub(super) String);

/// Routes anyone may call: liveness, and the viewer's files (which hold no data; the
/// viewer asks for a token when the API answers 401).
fn is_public(path: &str) -> bool {
    path == "/healthz" || path == "/readyz" || path == "/" || path.starts_with("/ui/")
}

/// Whether a method changes state (and so is audited and checked for its origin).
fn changes_state(method: &Method) -> bool {
    !matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS)
}

/// The secret of an `Authorization: Bearer` header; `Err` for any other authorization.
fn bearer(headers: &HeaderMap) -> Result<Option<&str>, ApiError> {
    let Some(v) = headers.get(header::AUTHORIZATION) else {
        return Ok(None);
    };
    let v = v.to_str().map_err(|_| {
        ApiError::unauthorized("the Authorization header is not ASCII: send Bearer <token>")
    })?;
    match v.split_once(' ') {
        Some((scheme, secret))
            if scheme.eq_ignore_ascii_case("bearer") && !secret.trim().is_empty() =>
        {
            Ok(Some(secret.trim()))
        }
        _ => Err(ApiError::unauthorized(
            "the Authorization header must be Bearer <token>",
        )),
    }
}

/// The host of a `Host` header (`name`, `name:port`, `[v6]:port`).
fn host_name(host: &str) -> &str {
    if let Some(rest) = host.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    host.rsplit_once(':').map_or(host, |(h, _)| h)
}

fn is_loopback_host(host: &str) -> bool {
    let h = host_name(host);
    h.eq_ignore_ascii_case("localhost") || h.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// Whether a write's `Origin` (sent by browsers, never by curl or the CLI) is the server's
/// own or one it allows. A page elsewhere can send a "simple" POST (text/plain, no
/// preflight) to a server on the user's machine; this is what stops it.
fn origin_allowed(headers: &HeaderMap, policy: &Policy) -> bool {
    let Some(origin) = headers.get(header::ORIGIN).and_then(|v| v.to_str().ok()) else {
        return true;
    };
    if policy.allowed_origins.iter().any(|o| o == origin) {
        return true;
    }
    let host = headers.get(header::HOST).and_then(|v| v.to_str().ok());
    let own = origin
        .split_once("://")
        .map(|(_, authority)| authority.trim_end_matches('/'));
    matches!((own, host), (Some(o), Some(h)) if o.eq_ignore_ascii_case(h))
}

/// Authenticate, refuse what must be refused, rate-limit, audit. See the module doc.
pub async fn front(State(f): State<Front>, mut req: Request, next: Next) -> Response {
    let method = req.method().clone();
    let path = req.uri().path().to_string();
    if is_public(&path) || method == Method::OPTIONS {
        return next.run(req).await;
    }
    let writes = changes_state(&method);
    let address = peer(&req);
    let caller = match authenticate(&f, req.headers(), writes).await {
        Ok(c) => c,
        Err(e) => {
            let response = match &f.refuse {
                Some(refuse) => {
                    req.extensions_mut().insert(Refused {
                        status: e.status,
                        code: e.code,
                        message: e.message,
                        retry_after: e.retry_after,
                    });
                    match refuse.clone().oneshot(req).await {
                        Ok(r) => r,
                        Err(never) => match never {},
                    }
                }
                None => e.into_response(),
            };
            // Past the limit nothing was tried: not worth an entry each.
            if writes && response.status() != StatusCode::TOO_MANY_REQUESTS {
                let done = Done::of(&response);
                audit(&f, None, address, &method, &path, done).await;
            }
            return response;
        }
    };
    let holder = holder_of(&req, &caller);
    req.extensions_mut().insert(holder);
    req.extensions_mut().insert(caller.clone());
    let response = if caller.token.is_some() || f.policy.open_beyond_loopback {
        match &f.limited {
            Some(limited) => match limited.clone().oneshot(req).await {
                Ok(r) => r,
                Err(never) => match never {},
            },
            None => next.run(req).await,
        }
    } else {
        next.run(req).await
    };
    if writes {
        let done = Done::of(&response);
        // A live stream's appends come many times a second; its open and finish entries
        // stand for them.
        if done.route.as_deref() != Some(UNAUDITED) {
            audit(&f, caller.token.as_ref(), address, &method, &path, done).await;
        }
    }
    response
}

/// The caller, or the answer that refuses it (`writes`: the request changes state).
async fn authenticate(f: &Front, headers: &HeaderMap, writes: bool) -> Result<Caller, ApiError> {
    if writes && !origin_allowed(headers, &f.policy) {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "cross_origin",
            "a page from another origin may not call this server; allow its origin with \
             serve --cors-origin",
        ));
    }
    let caller = f.auth.authenticate(&f.store, bearer(headers)?).await?;
    if caller.token.is_none() {
        // A server without tokens answers only requests that name it by a name no web page
        // can take over: a page whose own name resolves to this server (DNS rebinding)
        // is refused.
        let host = headers.get(header::HOST).and_then(|v| v.to_str().ok());
        if !host.is_some_and(|h| host_allowed(h, &f.policy)) {
            return Err(ApiError::new(
                StatusCode::FORBIDDEN,
                "misdirected",
                "this server has no tokens and answers only requests addressed to localhost \
                 (or, with --insecure-no-auth, to its IP address) or to a name allowed with \
                 serve --allow-host",
            ));
        }
    }
    Ok(caller)
}

/// Whether a server without tokens answers a request naming `host`: a loopback name; beyond
/// loopback, an IP address (a page's name can be made to resolve anywhere, an address
/// literal cannot be rebound); or a name the operator allowed.
fn host_allowed(host: &str, policy: &Policy) -> bool {
    let name = host_name(host);
    is_loopback_host(host)
        || (policy.open_beyond_loopback && name.parse::<IpAddr>().is_ok())
        || policy
            .allowed_hosts
            .iter()
            .any(|a| a == "*" || a.eq_ignore_ascii_case(name))
}

/// What an answer says for the audit log (read before the log is written: a response
/// body cannot be held across an await).
struct Done {
    status: u16,
    route: Option<String>,
    detail: String,
}

impl Done {
    fn of(response: &Response) -> Done {
        Done {
            status: response.status().as_u16(),
            route: response.extensions().get::<Route>().map(|r| r.0.clone()),
            detail: response
                .headers()
                .get(header::LOCATION)
                .and_then(|v| v.to_str().ok())
                .map(|l| format!("created {l}"))
                .unwrap_or_default(),
        }
    }
}

/// Note a write in the audit log ([`AuditLog`]: a row if it changed something, else a
/// count); a failure to write it is logged, not turned into the answer (the change it
/// describes has happened).
async fn audit(
    f: &Front,
    token: Option<&access::TokenRef>,
    address: IpAddr,
    method: &Method,
    path: &str,
    done: Done,
) {
    let attempt = Attempt {
        caller: token,
        address,
        action: format!("{method} {}", done.route.as_deref().unwrap_or(path)),
        path,
        status: done.status,
        detail: done.detail,
    };
    if let Err(e) = f.audit.note(&f.store, attempt).await {
        tracing::error!(error = %e, "could not write the audit log");
    }
}

/// Who a request counts against (rate limits, shares of the server's budgets): its token,
/// or for a request without one, the client's address.
fn holder_of(req: &Request, caller: &Caller) -> Holder {
    match &caller.token {
        Some(t) => Holder::Token(t.id.clone()),
        None => Holder::address(peer(req)),
    }
}

/// The client's address (unspecified when the server was not given it, as in unit tests).
pub(super) fn peer<T>(req: &axum::http::Request<T>) -> IpAddr {
    req.extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::from([0, 0, 0, 0]), |c| c.0.ip())
}

/// Rate-limit key: the request's [`Holder`]; a refused request (no holder yet) by address.
#[derive(Debug, Clone, Copy)]
pub struct RateKey;

impl KeyExtractor for RateKey {
    type Key = Holder;

    fn extract<T>(&self, req: &axum::http::Request<T>) -> Result<Holder, GovernorError> {
        Ok(req
            .extensions()
            .get::<Holder>()
            .cloned()
            .unwrap_or_else(|| Holder::address(peer(req))))
    }
}

/// A rate-limit refusal in the one error shape, with `Retry-After`.
pub fn too_many(e: GovernorError) -> Response {
    match e {
        GovernorError::TooManyRequests { wait_time, .. } => ApiError {
            retry_after: Some(wait_time.max(1)),
            ..ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "rate_limited",
                format!("too many requests for this token or address; retry in {wait_time} s"),
            )
        }
        .into_response(),
        other => {
            tracing::error!(error = %other, "rate limiter");
            ApiError::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                "internal",
                "internal error; see the server log",
            )
            .into_response()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    #[test]
    fn bearer_headers_parse_and_others_are_refused() {
        let mut h = HeaderMap::new();
        assert!(matches!(bearer(&h), Ok(None)));
        h.insert(
            header::AUTHORIZATION,
            HeaderValue::from_static("Bearer mcs_x"),
        );
        assert_eq!(bearer(&h).unwrap(), Some("mcs_x"));
        h.insert(
            header::AUTHORIZATION,
            HeaderValue::from_static("Basic dXNlcg=="),
        );
        assert!(bearer(&h).is_err());
        h.insert(header::AUTHORIZATION, HeaderValue::from_static("Bearer "));
        assert!(bearer(&h).is_err());
    }

    #[test]
    fn origins_other_than_the_servers_own_or_allowed_are_refused() {
        let policy = Policy {
            allowed_origins: vec!["https://viewer.example".into()],
            ..Policy::default()
        };
        let h = |origin: &'static str| {
            let mut h = HeaderMap::new();
            h.insert(header::HOST, HeaderValue::from_static("127.0.0.1:8080"));
            h.insert(header::ORIGIN, HeaderValue::from_static(origin));
            h
        };
        assert!(origin_allowed(&h("http://127.0.0.1:8080"), &policy));
        assert!(origin_allowed(&h("https://viewer.example"), &policy));
        assert!(!origin_allowed(&h("https://evil.example"), &policy));
        assert!(!origin_allowed(&h("null"), &policy));
        assert!(origin_allowed(&HeaderMap::new(), &policy));
    }

    #[test]
    fn without_tokens_only_names_no_page_can_take_are_answered() {
        let loopback = Policy::default();
        let open = Policy {
            open_beyond_loopback: true,
            ..Policy::default()
        };
        let allowed = Policy {
            open_beyond_loopback: true,
            allowed_hosts: vec!["mocap.lab".into()],
            ..Policy::default()
        };
        assert!(host_allowed("localhost:8080", &loopback));
        assert!(!host_allowed("10.0.0.2:8080", &loopback));
        assert!(host_allowed("10.0.0.2:8080", &open));
        assert!(host_allowed("[2001:db8::1]:80", &open));
        // --insecure-no-auth no longer answers any name (DNS rebinding).
        assert!(!host_allowed("evil.example", &open));
        assert!(!host_allowed("mocap.lab:8080", &open));
        assert!(host_allowed("MOCAP.lab:8080", &allowed));
        let any = Policy {
            allowed_hosts: vec!["*".into()],
            ..Policy::default()
        };
        assert!(host_allowed("evil.example", &any));
    }

    #[test]
    fn loopback_hosts_are_told_apart() {
        for h in ["localhost:8080", "127.0.0.1", "[::1]:80", "LOCALHOST"] {
            assert!(is_loopback_host(h), "{h}");
        }
        for h in ["evil.example", "10.0.0.2:8080", "[2001:db8::1]:80"] {
            assert!(!is_loopback_host(h), "{h}");
        }
    }
}
