//! JSON schemas of the values this crate's rules check, for the OpenAPI document (`schemars`):
//! marker types whose schema states the rule, used with `#[schemars(with = ...)]` on wire fields.

use crate::id::MAX_UAV_ID_LEN;
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use std::borrow::Cow;

/// The schema of a UAV id ([`crate::check_uav_id`]): 1 to 64 characters from `A-Z a-z 0-9 _ - .`.
pub struct UavId;

/// The character class of [`UavId`]'s pattern: exactly the characters [`crate::is_uav_id_char`] takes.
pub const UAV_ID_CLASS: &str = "[A-Za-z0-9_.-]";

impl JsonSchema for UavId {
    fn schema_name() -> Cow<'static, str> {
        "UavId".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "string",
            "pattern": format!("^{UAV_ID_CLASS}{{1,{MAX_UAV_ID_LEN}}}$"),
            "description": "a UAV id: 1 to 64 characters from `A-Z a-z 0-9 _ - .` (every UAV has one; anything else names no UAV)"
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pattern_takes_exactly_the_characters_of_an_id() {
        let class = |c: char| c.is_ascii_alphanumeric() || "_.-".contains(c);
        assert_eq!(UAV_ID_CLASS, "[A-Za-z0-9_.-]");
        for c in (0u8..=127).map(char::from) {
            assert_eq!(class(c), crate::is_uav_id_char(c), "{c:?}");
        }
        assert!(!crate::is_uav_id_char('é'));
    }
}
