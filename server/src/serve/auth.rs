//! Access control: when a token is configured, every request that may change something (any method
//! but GET, HEAD and OPTIONS) needs `Authorization: Bearer <token>`; reads stay open.

use super::error::ApiError;
use super::state::AppState;
use axum::extract::{Request, State};
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

/// Compares in time independent of where the strings differ (no early exit on the first byte).
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// True when `value` is `Bearer <token>`.
pub fn authorised(value: Option<&HeaderValue>, token: &str) -> bool {
    let Some(value) = value.and_then(|v| v.to_str().ok()) else {
        return false;
    };
    let Some((scheme, given)) = value.split_once(' ') else {
        return false;
    };
    scheme.eq_ignore_ascii_case("bearer") && same(given.trim().as_bytes(), token.as_bytes())
}

/// Middleware refusing unauthenticated changes with 401.
pub async fn require_token(State(app): State<AppState>, request: Request, next: Next) -> Response {
    let read = matches!(*request.method(), Method::GET | Method::HEAD | Method::OPTIONS);
    match &app.token {
        Some(token) if !read && !authorised(request.headers().get(header::AUTHORIZATION), token) => {
            let mut response = ApiError::new(
                StatusCode::UNAUTHORIZED,
                "unauthorized",
                "this server needs `Authorization: Bearer <token>` for changes",
            )
            .into_response();
            response.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            response
        }
        _ => next.run(request).await,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_exact_bearer_token_passes() {
        let ok = HeaderValue::from_static("Bearer s3cret");
        assert!(authorised(Some(&ok), "s3cret"));
        assert!(authorised(Some(&HeaderValue::from_static("bearer s3cret")), "s3cret"));
        for bad in ["Bearer s3cre", "Bearer s3cret2", "Basic s3cret", "s3cret", "Bearer "] {
            assert!(!authorised(Some(&HeaderValue::from_static(bad)), "s3cret"), "{bad}");
        }
        assert!(!authorised(None, "s3cret"));
    }
}
