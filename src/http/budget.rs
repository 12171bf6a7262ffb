//! Request bodies under one server-wide memory budget.
//!
//! A limit per request does not bound a server: three 500 MB uploads at once held 2.7 GB.
//! So every body is read here, before its handler runs, against two bounds:
//! - its route's size limit: a `Content-Length` over it is refused (413) before a byte of
//!   the body is read, and a body without one is cut off (413) once it passes the limit;
//! - the server's budget for bodies held at once ([`crate::limits::Limits::inflight_bytes`]):
//!   a body that would go over is refused at once with 503 and `Retry-After`, never queued
//!   in memory.
//!
//! The reservation travels with the bytes: the body reaches its handler as [`Bytes`] that own
//! their reservation, so it is returned when the last copy of the upload is dropped (the
//! parser on the blocking pool may hold it after the response has gone), not when the
//! response is written. What the budget counts is therefore what the server really holds.

use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{header, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http_body_util::BodyExt;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::error::ApiError;
use crate::limits::RETRY_AFTER_S;

/// The budget counts in KiB so that one `u32` reservation covers any body.
const UNIT: u64 = 1024;

/// Bytes of request bodies the server may hold at once.
pub struct BodyBudget {
    permits: Arc<Semaphore>,
    total_units: u64,
}

impl BodyBudget {
    pub fn new(bytes: u64) -> Self {
        let units = (bytes / UNIT).clamp(1, Semaphore::MAX_PERMITS as u64);
        BodyBudget {
            permits: Arc::new(Semaphore::new(units as usize)),
            total_units: units,
        }
    }

    /// Bytes reserved by bodies held now (rounded up to KiB per reservation).
    pub fn held_bytes(&self) -> u64 {
        (self.total_units - self.permits.available_permits() as u64) * UNIT
    }

    /// The budget, bytes.
    pub fn total_bytes(&self) -> u64 {
        self.total_units * UNIT
    }

    /// Reserve room for `bytes` more, or `None` if the budget has not got it now.
    fn reserve(&self, bytes: u64) -> Option<OwnedSemaphorePermit> {
        let units = u32::try_from(bytes.div_ceil(UNIT)).ok()?;
        self.permits.clone().try_acquire_many_owned(units).ok()
    }
}

/// What one route's bodies are read under.
#[derive(Clone)]
pub struct BodyGate {
    pub budget: Arc<BodyBudget>,
    /// Largest body this route takes, bytes.
    pub limit: u64,
}

/// A body and the reservation it holds while any copy of it lives.
struct Held {
    data: Vec<u8>,
    _reserved: Vec<OwnedSemaphorePermit>,
}

impl AsRef<[u8]> for Held {
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

fn busy(budget: &BodyBudget) -> Response {
    ApiError::busy(format!(
        "the server holds as many request bodies as its memory budget allows ({} bytes); \
         retry in {RETRY_AFTER_S} s",
        budget.total_bytes()
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
    let mut reserved = Vec::new();
    if let Some(n) = declared.filter(|&n| n > 0) {
        match gate.budget.reserve(n) {
            Some(p) => reserved.push(p),
            None => return busy(&gate.budget),
        }
    }
    let (parts, body) = req.into_parts();
    // Room for what was declared (and reserved); a body without a length grows as it comes.
    let mut data = Vec::with_capacity(declared.unwrap_or(0) as usize);
    let mut body = body;
    let mut unreserved = 0u64;
    while let Some(frame) = body.frame().await {
        let frame = match frame {
            Ok(f) => f,
            Err(e) => {
                return ApiError::bad_request(format!("could not read the request body: {e}"))
                    .into_response()
            }
        };
        let Ok(chunk) = frame.into_data() else {
            continue; // trailers
        };
        let len = (data.len() + chunk.len()) as u64;
        if len > gate.limit {
            return too_large(gate.limit, format!("the body passed {} bytes", gate.limit));
        }
        if declared.is_none() {
            // Reserve in steps of at least 64 KiB, so that a chunked upload does not take a
            // permit per network read.
            unreserved += chunk.len() as u64;
            if unreserved >= 64 * UNIT || len == gate.limit {
                match gate.budget.reserve(unreserved) {
                    Some(p) => reserved.push(p),
                    None => return busy(&gate.budget),
                }
                unreserved = 0;
            }
        }
        data.extend_from_slice(&chunk);
    }
    if unreserved > 0 {
        match gate.budget.reserve(unreserved) {
            Some(p) => reserved.push(p),
            None => return busy(&gate.budget),
        }
    }
    let body = Bytes::from_owner(Held {
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
        let b = BodyBudget::new(10 * UNIT);
        let p = b.reserve(4 * UNIT + 1).unwrap(); // rounds up to 5 KiB
        assert_eq!(b.held_bytes(), 5 * UNIT);
        assert!(b.reserve(6 * UNIT).is_none(), "over the budget");
        let bytes = Bytes::from_owner(Held {
            data: vec![1, 2, 3],
            _reserved: vec![p],
        });
        let copy = bytes.clone();
        drop(bytes);
        assert_eq!(b.held_bytes(), 5 * UNIT, "a copy still holds it");
        drop(copy);
        assert_eq!(b.held_bytes(), 0);
        assert!(b.reserve(10 * UNIT).is_some());
    }
}
