//! A JSON request body that must be an object. axum's `Json<T>` deserialises a struct from
//! a JSON array too (serde reads a struct from a sequence of its fields in order), so `[]`
//! would be an empty PATCH and `["name", "read"]` a token request; every body this API
//! takes is documented as an object, and anything else is a 400.

use axum::extract::{FromRequest, Request};
use axum::Json;
use serde::de::DeserializeOwned;

use super::error::ApiError;

/// The body, parsed as `T` from a JSON object.
pub struct Object<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequest<S> for Object<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        let Json(value) = Json::<serde_json::Value>::from_request(req, state)
            .await
            .map_err(|r| ApiError::bad_request(r.body_text()))?;
        if !value.is_object() {
            return Err(ApiError::bad_request(
                "the body must be a JSON object ({…})",
            ));
        }
        serde_json::from_value(value)
            .map(Object)
            .map_err(|e| ApiError::bad_request(format!("the body: {e}")))
    }
}
