//! `x-websocket` of the document: `GET /ws`'s parameters and the binary stream's frames
//! (docs/streams.md), with the format's numbers from `binary` and the status table from
//! `UavStatus`.

use crate::binary::{
    FLAG_FILTERED, FLAG_PAUSED, KIND_RESERVATIONS, KIND_ROSTER, KIND_TICK, RECORD_BYTES, TICK_HEADER_BYTES,
    VERSION,
};
use engine::snapshot::{UAV_ARRIVED, UAV_LOST, UavStatus};
use serde_json::{Value, json};

/// The description of the stream.
pub fn description() -> Value {
    // The status byte is the status's number; the list is in that order, so its index is the byte.
    let status_codes: Vec<Value> =
        UavStatus::ALL.iter().map(|s| serde_json::to_value(s).unwrap_or(Value::Null)).collect();
    json!({
        "path": "/ws",
        "parameters": {
            "rate": "frames per second, 0 < rate <= 1000 (default: every tick)",
            "format": "`json` (default) or `bin`",
            "bbox": "`x0,y0,x1,y1` (m), finite, x0 <= x1, y0 <= y1; only with format=bin",
        },
        "binary_format_version": VERSION,
        "roster_frame": format!("bytes 0 u8 version ({VERSION}), 1 u8 kind ({KIND_ROSTER}), 2 u16 reserved, 4 u32 roster_version, 8.. UTF-8 JSON {{\"uavs\": [{{\"id\", \"policy\", \"goal\", \"link\"}}]}} in index order; sent first and whenever ids, policies, goals or links change"),
        "reservations_frame": format!("bytes 0 u8 version ({VERSION}), 1 u8 kind ({KIND_RESERVATIONS}), 2 u16 reserved, 4 u32 version, 8.. UTF-8 JSON {{\"reservations\": [...]}} as in the snapshot; sent first and whenever a single-file section's state changes"),
        "tick_frame": format!("little-endian; header {TICK_HEADER_BYTES} bytes: 0 u8 version ({VERSION}), 1 u8 kind ({KIND_TICK}), 2 u16 flags ({FLAG_PAUSED} paused, {FLAG_FILTERED} filtered by bbox), 4 u32 roster_version, 8 u64 tick, 16 f64 time (s), 24 u32 fleet size, 28 u32 record count, 32 u32 road_version, 36 f32 min_collision_margin_m (NaN: none), 40 f32 min_road_margin_m (NaN: none), 44 f32 d_c, 48 f32 d_s; then count records of {RECORD_BYTES} bytes: 0 u32 index in the roster, 4 f32 p[2], 12 f32 v[2], 20 f32 u[2], 28 f32 target[2], 36 u8 status, 37 u8 flags ({UAV_ARRIVED} arrived, {UAV_LOST} lost), 38 u16 reserved"),
        "status_codes": status_codes,
    })
}
