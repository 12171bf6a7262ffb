//! Request bodies read under the server's budget for them ([`Budget`]: a total and a share
//! per caller), before their handler runs:
//! - a body over its route's size limit is refused (413): at once when its
//!   `Content-Length` says so, else when it passes the limit;
//! - the budget counts what has arrived, not what was declared: a client that declares
//!   512 MiB and sends nothing holds nothing. A body that would take the server past its
//!   budget, or its caller past its share, is refused at once (503, `Retry-After`);
//! - a body from which nothing arrives for [`crate::limits::Limits::body_idle`] is dropped
//!   (408) and what it held is freed.
//!
//! The reservation travels with the bytes: the body reaches its handler as [`Bytes`] that own
//! their reservation, so it is returned when the last copy of the upload is dropped (the
//! parser on the blocking pool may hold it after the response has gone), not when the
//! response is written. What the budget counts is therefore what the server really holds.

use std::sync::Arc;
use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{header, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http_body_util::BodyExt;

use super::error::ApiError;
use crate::limits::RETRY_AFTER_S;
use crate::service::budget::{Budget, Holder, Refused, Reservation};

/// A body's buffer grows in steps of at least this many bytes.
const STEP: usize = 64 << 10;

/// What one route's bodies are read under.
#[derive(Clone)]
pub struct BodyGate {
    pub budget: Arc<Budget>,
    /// Largest body this route takes, bytes.
    pub limit: u64,
    /// How long a body may send nothing.
    pub idle: Duration,
}

/// A body and the reservation it holds while any copy of it lives.
struct HeldBody {
    data: Vec<u8>,
    _reserved: Reservation,
}

impl AsRef<[u8]> for HeldBody {
    fn as_ref(&self) -> &[u8] {
        &self.data
    }
}

fn too_large(limit: u64, what: String) -> Response {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "too_large",
        format!("{what}; this route takes bodies of at most {limit} bytes"),
    )
    .into_response()
}

fn busy(refused: Refused) -> Response {
    ApiError::busy(format!(
        "{}; retry in {RETRY_AFTER_S} s",
        refused.reason("request bodies")
    ))
    .into_response()
}

/// Middleware: read the body under the route's limit and the server's budget, then call the
/// handler with it.
pub async fn hold_body(State(gate): State<BodyGate>, req: Request, next: Next) -> Response {
    let declared = match req.headers().get(header::CONTENT_LENGTH) {
        None => None,
        Some(v) => match v.to_str().ok().and_then(|s| s.trim().parse::<u64>().ok()) {
            Some(n) => Some(n),
            None => return ApiError::bad_request("Content-Length is not a number").into_response(),
        },
    };
    if let Some(n) = declared.filter(|&n| n > gate.limit) {
        return too_large(gate.limit, format!("Content-Length is {n} bytes"));
    }
    // The front door puts the caller's holder in every request it lets through.
    let holder = req
        .extensions()
        .get::<Holder>()
        .cloned()
        .unwrap_or_else(|| Holder::address(super::auth::peer(&req)));
    let mut reserved = gate.budget.reservation(holder);
    // The buffer never grows past what the body may be: declared, or the route's limit.
    let most = declared.unwrap_or(gate.limit) as usize;
    let (parts, mut body) = req.into_parts();
    let mut data: Vec<u8> = Vec::new();
    loop {
        let frame = match tokio::time::timeout(gate.idle, body.frame()).await {
            Err(_) => {
                return ApiError::new(
                    StatusCode::REQUEST_TIMEOUT,
                    "body_timeout",
                    format!(
                        "no part of the request body arrived for {} s; send it again",
                        gate.idle.as_secs()
                    ),
                )
                .into_response()
            }
            Ok(None) => break,
            Ok(Some(Err(e))) => {
                return ApiError::bad_request(format!("could not read the request body: {e}"))
                    .into_response()
            }
            Ok(Some(Ok(f))) => f,
        };
        let Ok(chunk) = frame.into_data() else {
            continue; // trailers
        };
        let len = data.len() + chunk.len();
        if len as u64 > gate.limit {
            return too_large(gate.limit, format!("the body passed {} bytes", gate.limit));
        }
        if len > data.capacity() {
            // Room is reserved before it is allocated, and counted as allocated: capacity,
            // not length.
            let want = len.max(data.capacity() * 2).max(STEP).min(most.max(len));
            if let Err(r) = reserved.grow_to(want as u64) {
                return busy(r);
            }
            data.reserve_exact(want - data.len());
        }
        data.extend_from_slice(&chunk);
    }
    let body = Bytes::from_owner(HeldBody {
        data,
        _reserved: reserved,
    });
    next.run(Request::from_parts(parts, Body::from(body))).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reservations_come_back_when_their_bytes_are_dropped() {
        let b = Arc::new(Budget::new(10 << 10, 10 << 10));
        let mut r = b.reservation(Holder::Address([10, 0, 0, 1].into()));
        r.grow_to((4 << 10) + 1).unwrap(); // rounds up to 5 KiB
        assert_eq!(b.reserved_bytes(), 5 << 10);
        let bytes = Bytes::from_owner(HeldBody {
            data: vec![1, 2, 3],
            _reserved: r,
        });
        let copy = bytes.clone();
        drop(bytes);
        assert_eq!(b.reserved_bytes(), 5 << 10, "a copy still holds it");
        drop(copy);
        assert_eq!(b.reserved_bytes(), 0);
    }
}
