//! One JSON error shape for every failure: `{"error": {"code": "...", "message": "..."}}`,
//! with the status that says whose fault it is. 5xx bodies never carry internals; those go
//! to the log.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;

use crate::service;

#[derive(Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
}

impl ApiError {
    pub fn bad_request(message: impl Into<String>) -> Self {
        ApiError {
            status: StatusCode::BAD_REQUEST,
            code: "bad_request",
            message: message.into(),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::json!({"error": {"code": self.code, "message": self.message}});
        (self.status, Json(body)).into_response()
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
            E::Codec(crate::codec::Error::Invalid(_)) => (StatusCode::BAD_REQUEST, "bad_request"),
            E::Store(crate::store::Error::Conflict(_)) => (StatusCode::CONFLICT, "conflict"),
            E::Codec(_) | E::Store(_) | E::Internal(_) => {
                tracing::error!(error = %e, "request failed");
                return ApiError {
                    status: StatusCode::INTERNAL_SERVER_ERROR,
                    code: "internal",
                    message: "internal error; see the server log".into(),
                };
            }
        };
        ApiError {
            status,
            code,
            message: e.to_string(),
        }
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
        ApiError {
            status,
            code: if status == StatusCode::PAYLOAD_TOO_LARGE {
                "too_large"
            } else {
                "bad_body"
            },
            message: r.body_text(),
        }
    }
}
