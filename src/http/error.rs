//! One JSON error shape for every failure: `{"error": {"code": "...", "message": "..."}}`,
//! with the status that says whose fault it is. 5xx bodies never carry internals; those go
//! to the log.

use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;

use crate::service;

#[derive(Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
    /// Seconds to wait before trying again (503s at a capacity limit), sent as `Retry-After`.
    pub retry_after: Option<u64>,
}

impl ApiError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        ApiError {
            status,
            code,
            message: message.into(),
            retry_after: None,
        }
    }

    pub fn bad_request(message: impl Into<String>) -> Self {
        ApiError::new(StatusCode::BAD_REQUEST, "bad_request", message)
    }

    /// 401, with the `WWW-Authenticate` challenge that names the scheme.
    pub fn unauthorized(message: impl Into<String>) -> Self {
        ApiError::new(StatusCode::UNAUTHORIZED, "unauthorized", message)
    }

    /// 503 at a capacity limit, with `Retry-After`.
    pub fn busy(message: impl Into<String>) -> Self {
        ApiError {
            retry_after: Some(crate::limits::RETRY_AFTER_S),
            ..ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "busy", message)
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::json!({"error": {"code": self.code, "message": self.message}});
        let mut r = (self.status, Json(body)).into_response();
        if self.status == StatusCode::UNAUTHORIZED {
            r.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"mocapstore\""),
            );
        }
        if let Some(s) = self.retry_after {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        r
    }
}

impl From<service::Error> for ApiError {
    fn from(e: service::Error) -> Self {
        use service::Error as E;
        let (status, code) = match &e {
            E::BadInput(_) => (StatusCode::UNPROCESSABLE_ENTITY, "unreadable_take"),
            E::InvalidRequest(_) => (StatusCode::BAD_REQUEST, "bad_request"),
            E::NotFound(_) => (StatusCode::NOT_FOUND, "not_found"),
            E::OutOfRange(_) => (StatusCode::RANGE_NOT_SATISFIABLE, "out_of_range"),
            E::Unsatisfiable(_) => (StatusCode::CONFLICT, "unsatisfiable"),
            E::Conflict(_) => (StatusCode::CONFLICT, "conflict"),
            E::Busy(_) | E::Moved(_) => return ApiError::busy(e.to_string()),
            E::Unauthorized(_) => return ApiError::unauthorized(e.to_string()),
            E::Forbidden(_) => (StatusCode::FORBIDDEN, "forbidden"),
            E::Codec(crate::codec::Error::Invalid(_)) => (StatusCode::BAD_REQUEST, "bad_request"),
            E::Store(crate::store::Error::Conflict(_)) => (StatusCode::CONFLICT, "conflict"),
            E::Store(s) if s.is_unavailable() => {
                tracing::warn!(error = %e, "the database is unavailable");
                return ApiError::busy(
                    "the database is unavailable (restarting or out of connections); retry shortly",
                );
            }
            E::Codec(_) | E::Store(_) | E::Corrupt(_) | E::Internal(_) => {
                tracing::error!(error = %e, "request failed");
                return ApiError::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "internal",
                    "internal error; see the server log",
                );
            }
        };
        ApiError::new(status, code, e.to_string())
    }
}

impl From<axum::extract::rejection::QueryRejection> for ApiError {
    fn from(r: axum::extract::rejection::QueryRejection) -> Self {
        ApiError::bad_request(r.body_text())
    }
}

impl From<axum::extract::rejection::BytesRejection> for ApiError {
    fn from(r: axum::extract::rejection::BytesRejection) -> Self {
        let status = r.status();
        let code = if status == StatusCode::PAYLOAD_TOO_LARGE {
            "too_large"
        } else {
            "bad_body"
        };
        ApiError::new(status, code, r.body_text())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::Error as C;

    /// The caller's mistakes are 4xx with what was wrong; our faults are 500 with nothing of
    /// the inside in the body (it goes to the log).
    #[test]
    fn a_codec_error_is_the_callers_or_ours_and_answers_so() {
        let status = |e: C| ApiError::from(service::Error::Codec(e));
        let bad = status(C::Invalid("frames 9..3 outside 0..5".into()));
        assert_eq!(bad.status, StatusCode::BAD_REQUEST);
        assert!(bad.message.contains("outside"), "{}", bad.message);
        for ours in [
            C::Fault("chunk 3 was not supplied".into()),
            C::Malformed("stored chunk".into()),
            C::BoundMissed {
                codec: "rot".into(),
                detail: "chunk 2".into(),
            },
        ] {
            let e = status(ours);
            assert_eq!(e.status, StatusCode::INTERNAL_SERVER_ERROR);
            assert!(!e.message.contains("chunk"), "{}", e.message);
        }
    }
}
