//! The one rule for UAV ids, shared by scenario files, the fleet and the REST API: ids appear in
//! URL paths, logs and the dashboard, so they are 1 to 64 characters from `A-Z a-z 0-9 _ - .`.

/// Longest UAV id, in characters (ids are ASCII, so also in bytes).
pub const MAX_UAV_ID_LEN: usize = 64;

/// The rule, as error messages state it.
pub const UAV_ID_RULE: &str = "must be 1 to 64 characters from A-Z, a-z, 0-9, _, - and .";

/// True for the characters an id may contain: `A-Z a-z 0-9 _ - .`.
pub fn is_uav_id_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')
}

/// Checks a UAV id: 1 to [`MAX_UAV_ID_LEN`] characters from `A-Z a-z 0-9 _ - .`. The error starts
/// with [`UAV_ID_RULE`] and says what is wrong; it never repeats the id, and shows a refused
/// character escaped (`'\u{202e}'`), so control and bidi characters cannot reach a log or a page.
pub fn check_uav_id(id: &str) -> Result<(), String> {
    if id.is_empty() {
        return Err(format!("{UAV_ID_RULE} (got an empty id)"));
    }
    if let Some((k, c)) = id.chars().enumerate().find(|&(_, c)| !is_uav_id_char(c)) {
        return Err(format!("{UAV_ID_RULE} (got {c:?} at character {k})"));
    }
    // Every character is ASCII here: bytes are characters.
    if id.len() > MAX_UAV_ID_LEN {
        return Err(format!("{UAV_ID_RULE} (got {} characters)", id.len()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_allowed_characters_and_lengths_pass() {
        for id in ["a", "uav1", "cf_1-b.2", "A-Z.a_z", &"x".repeat(64), "0", "...", "-_"] {
            assert_eq!(check_uav_id(id), Ok(()), "{id}");
        }
    }

    #[test]
    fn every_refused_class_is_named() {
        let cases: [(&str, &str); 9] = [
            ("", "(got an empty id)"),
            (&"x".repeat(65), "(got 65 characters)"),
            ("a/b", "(got '/' at character 1)"),
            ("a b", "(got ' ' at character 1)"),
            ("a\nb", "(got '\\n' at character 1)"),
            ("a\u{7}", "(got '\\u{7}' at character 1)"),
            ("ab\u{202e}c", "(got '\\u{202e}' at character 2)"),
            ("é", "(got 'é' at character 0)"),
            ("uav\u{2028}", "(got '\\u{2028}' at character 3)"),
        ];
        for (id, detail) in cases {
            let e = check_uav_id(id).unwrap_err();
            assert_eq!(e, format!("{UAV_ID_RULE} {detail}"), "{id:?}");
            assert!(!e.contains('\u{202e}') && !e.contains('\n'), "{e:?} must not carry the raw character");
        }
        // A long id of refused characters is refused for its first character, not its length.
        assert!(check_uav_id(&"é".repeat(40)).unwrap_err().ends_with("(got 'é' at character 0)"));
        assert!(check_uav_id("Ωmega").is_err() && check_uav_id("ｕａｖ").is_err(), "non-ASCII letters");
    }
}
