//! The API's errors: `{"error": {"code", "message", "field"?}}` with a 4xx status (5xx only when
//! the fleet loop is gone), and a JSON body extractor whose rejections use the same shape.

use axum::extract::{FromRequest, Request};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use engine::ApplyError;
use engine::command::ChangeError;
use fleet::EditError;
use serde::de::DeserializeOwned;

/// An error answered to a client.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    /// HTTP status.
    pub status: StatusCode,
    /// Stable machine-readable code, e.g. `invalid_body`, `unknown_uav`.
    pub code: &'static str,
    /// What is wrong, for people.
    pub message: String,
    /// The request field at fault (JSON path), when one is.
    pub field: Option<String>,
    /// Extra members of the error object (e.g. `segment`, `rule` of a road error).
    pub extra: Option<serde_json::Map<String, serde_json::Value>>,
}

impl ApiError {
    /// An error with a status, code and message.
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        Self { status, code, message: message.into(), field: None, extra: None }
    }

    /// The same error naming the request field at fault.
    pub fn field(mut self, field: impl Into<String>) -> Self {
        self.field = Some(field.into());
        self
    }

    /// 422 for a field with an invalid value.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_value", message).field(field)
    }

    /// 404 for an unknown UAV.
    pub fn unknown_uav(id: &str) -> Self {
        Self::new(StatusCode::NOT_FOUND, "unknown_uav", format!("no UAV with id `{id}`")).field("id")
    }

    /// 503 when a bounded resource is exhausted; nothing changed and the client may retry.
    pub fn busy(message: impl Into<String>) -> Self {
        Self::new(StatusCode::SERVICE_UNAVAILABLE, "busy", message)
    }

    /// 503 when the fleet loop does not answer.
    pub fn loop_unavailable() -> Self {
        Self::new(StatusCode::SERVICE_UNAVAILABLE, "loop_unavailable", "the fleet loop is not running")
    }
}

impl From<ApplyError> for ApiError {
    fn from(e: ApplyError) -> Self {
        match e {
            ApplyError::Unavailable => Self::loop_unavailable(),
            ApplyError::Busy => Self::busy(e.to_string()),
            ApplyError::Refused(e) => e.into(),
            ApplyError::StorageTimeout => {
                Self::new(StatusCode::SERVICE_UNAVAILABLE, "storage_timeout", e.to_string())
            }
        }
    }
}

impl From<EditError> for ApiError {
    fn from(e: EditError) -> Self {
        match e {
            EditError::UnknownUav(id) => Self::unknown_uav(&id),
            EditError::DuplicateId(id) => Self::new(
                StatusCode::CONFLICT,
                "duplicate_id",
                format!("a UAV with id `{id}` exists already"),
            )
            .field("id"),
            EditError::InvalidId(reason) => Self::invalid("id", reason),
            EditError::Unsafe { field, reason } => {
                Self::new(StatusCode::UNPROCESSABLE_ENTITY, "unsafe", reason).field(field)
            }
            EditError::RoadConflict(reason) => {
                Self::new(StatusCode::CONFLICT, "unsafe_road", reason).field("segments")
            }
            EditError::UnknownPolicy(reason) => {
                Self::new(StatusCode::UNPROCESSABLE_ENTITY, "unknown_policy", reason).field("policy")
            }
        }
    }
}

impl From<ChangeError> for ApiError {
    fn from(e: ChangeError) -> Self {
        match e {
            ChangeError::Edit(e) => e.into(),
            ChangeError::NotDurable(reason) => Self::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "not_durable",
                format!("the change could not be saved to disk and was not applied: {reason}"),
            ),
            e @ ChangeError::FleetFull { .. } => {
                Self::new(StatusCode::UNPROCESSABLE_ENTITY, "fleet_full", e.to_string()).field("uavs")
            }
            ChangeError::Withdrawn => {
                Self::busy("the fleet loop did not take the change in time; nothing changed")
            }
            e @ ChangeError::Standby(_) => Self::new(StatusCode::CONFLICT, "standby", e.to_string()),
        }
    }
}

/// The code and message of an error answer, attached to its response for the audit log.
#[derive(Debug, Clone)]
pub struct ErrorInfo {
    /// The error code.
    pub code: &'static str,
    /// The message.
    pub message: String,
}

/// The body of every error answer: `{"error": {"code", "message", "field"?, ...}}`.
#[derive(Debug, serde::Serialize, schemars::JsonSchema)]
#[schemars(rename = "Error")]
pub struct ErrorBody {
    /// What went wrong.
    pub error: ErrorObject,
}

/// The `error` of an [`ErrorBody`].
#[derive(Debug, serde::Serialize, schemars::JsonSchema)]
pub struct ErrorObject {
    /// Stable machine-readable code, e.g. `invalid_body`, `unknown_uav`.
    pub code: &'static str,
    /// What is wrong, for people.
    pub message: String,
    /// The request field at fault (JSON path), when one is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// Members some errors add: `rule` and `segment` of a road's refusal, `region` and `regions`
    /// of a deployment's.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let info = ErrorInfo { code: self.code, message: self.message.clone() };
        let mut extra = self.extra.unwrap_or_default();
        for key in ["code", "message", "field"] {
            extra.remove(key);
        }
        let error = ErrorObject { code: self.code, message: self.message, field: self.field, extra };
        let mut response = (self.status, axum::Json(ErrorBody { error })).into_response();
        response.extensions_mut().insert(info);
        response
    }
}

/// Largest request body accepted (bytes): a road of 10,000 segments (the most accepted) is about 1.5 MB.
pub const MAX_BODY_BYTES: usize = 4 << 20;

/// True when the request says `Content-Type: application/json` (or another `+json` type).
pub fn is_json(headers: &HeaderMap) -> bool {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .is_some_and(|m| {
            let m = m.trim().to_ascii_lowercase();
            m == "application/json" || (m.starts_with("application/") && m.ends_with("+json"))
        })
}

/// How long a client may take to send its body.
pub const BODY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// Bodies above this size are parsed on the blocking pool, not on an async worker.
const PARSE_INLINE_BYTES: usize = 16 << 10;

/// Reads the whole body within [`BODY_TIMEOUT`] and the size limit.
async fn read_body<S: Send + Sync>(req: Request, state: &S) -> Result<axum::body::Bytes, ApiError> {
    let read = axum::body::Bytes::from_request(req, state);
    match tokio::time::timeout(BODY_TIMEOUT, read).await {
        Ok(Ok(bytes)) => Ok(bytes),
        Ok(Err(e)) => Err(ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, "body_too_large", e.body_text())),
        Err(_) => Err(ApiError::new(
            StatusCode::REQUEST_TIMEOUT,
            "body_timeout",
            format!("the body did not arrive within {} s", BODY_TIMEOUT.as_secs()),
        )),
    }
}

/// A JSON request body. Malformed JSON (also trailing data after the document) is a 400, a wrong
/// type, missing or unknown key a 422 naming the field by its JSON path, a missing or wrong content
/// type a 415, a body slower than [`BODY_TIMEOUT`] a 408.
pub struct ApiJson<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned + Send + 'static> FromRequest<S> for ApiJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        read_json(req, state, parse::<T>).await.map(ApiJson)
    }
}

/// Reads a JSON body as [`ApiJson`] does (content type, size, time) and parses it with
/// `parse_with`, on the blocking pool when it is large.
pub async fn read_json<S: Send + Sync, T: Send + 'static>(
    req: Request,
    state: &S,
    parse_with: fn(&[u8]) -> Result<T, ApiError>,
) -> Result<T, ApiError> {
    if !is_json(req.headers()) {
        return Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            "the body must be JSON with `Content-Type: application/json`",
        ));
    }
    let bytes = read_body(req, state).await?;
    if bytes.len() <= PARSE_INLINE_BYTES {
        return parse_with(&bytes);
    }
    match tokio::task::spawn_blocking(move || parse_with(&bytes)).await {
        Ok(parsed) => parsed,
        Err(_) => Err(ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "internal_error", "parsing failed")),
    }
}

/// The body of a change that takes none: empty, or the empty JSON object `{}`.
pub struct NoBody;

impl<S: Send + Sync> FromRequest<S> for NoBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        no_body(&read_body(req, state).await?)
    }
}

/// Reads the body of a change that takes none: nothing, or `{}`.
pub fn no_body(bytes: &[u8]) -> Result<NoBody, ApiError> {
    if bytes.is_empty() {
        return Ok(NoBody);
    }
    match parse::<serde_json::Map<String, serde_json::Value>>(bytes) {
        Ok(object) if object.is_empty() => Ok(NoBody),
        Ok(_) => Err(ApiError::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_body",
            "this request takes no body (or the empty object `{}`)",
        )),
        Err(e) => Err(e),
    }
}

/// Parses a JSON body, naming the field at fault on error. Every body is a JSON object: serde's
/// derived structs would also take their fields as an array (`[[]]` for `{"ids": []}`), which no
/// schema of the API allows.
pub fn parse<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let de = &mut serde_json::Deserializer::from_slice(bytes);
    match serde_path_to_error::deserialize(&mut *de) {
        Ok(value) => match de.end() {
            Ok(()) if bytes.trim_ascii_start().first() != Some(&b'{') => Err(ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid_body",
                "the body must be a JSON object",
            )),
            Ok(()) => Ok(value),
            Err(e) => Err(ApiError::new(
                StatusCode::BAD_REQUEST,
                "malformed_json",
                format!("data after the JSON document: {e}"),
            )),
        },
        Err(e) => {
            let path = e.path().to_string();
            let inner = e.into_inner();
            let message = inner.to_string();
            if inner.is_syntax() || inner.is_eof() {
                Err(ApiError::new(StatusCode::BAD_REQUEST, "malformed_json", message))
            } else {
                let field = if path == "." { None } else { Some(path) };
                let mut err = ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_body", message);
                err.field = field;
                Err(err)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Body {
        goal: [f64; 2],
    }

    #[test]
    fn parse_errors_name_the_field_and_pick_the_status() {
        let e = parse::<Body>(b"{\"goal\": [1, \"x\"]}").unwrap_err();
        assert_eq!((e.status, e.field.as_deref()), (StatusCode::UNPROCESSABLE_ENTITY, Some("goal[1]")));
        let e = parse::<Body>(b"{\"goal\": [1, 2]").unwrap_err();
        assert_eq!((e.status, e.code), (StatusCode::BAD_REQUEST, "malformed_json"));
        let e = parse::<Body>(b"{\"goal\": [1, 2], \"x\": 1}").unwrap_err();
        assert_eq!(e.status, StatusCode::UNPROCESSABLE_ENTITY);
        assert!(e.message.contains("unknown field `x`"), "{}", e.message);
        // JSON has no NaN: a non-finite number is a syntax error, not a panic.
        let e = parse::<Body>(b"{\"goal\": [NaN, 1]}").unwrap_err();
        assert_eq!(e.status, StatusCode::BAD_REQUEST);
        // One document per body: trailing data is malformed, trailing whitespace is not.
        let e = parse::<Body>(b"{\"goal\": [1, 0]} xyz").unwrap_err();
        assert_eq!((e.status, e.code), (StatusCode::BAD_REQUEST, "malformed_json"));
        assert!(parse::<Body>(b"{\"goal\": [1, 0]} {}").is_err());
        assert!(parse::<Body>(b"{\"goal\": [1, 0]}\n ").is_ok());
    }

    #[test]
    fn a_body_is_an_object_never_its_fields_as_an_array() {
        // serde's derived struct would read `[[1, 0]]` as `{"goal": [1, 0]}`.
        let e = parse::<Body>(b" [[1, 0]]").unwrap_err();
        assert_eq!((e.status, e.code), (StatusCode::UNPROCESSABLE_ENTITY, "invalid_body"));
        assert!(e.message.contains("JSON object"), "{}", e.message);
        assert!(parse::<Body>(b" \n{\"goal\": [1, 0]}").is_ok());
        // A malformed array stays a syntax error.
        assert_eq!(parse::<Body>(b"[[1, 0]").unwrap_err().code, "malformed_json");
    }
}
