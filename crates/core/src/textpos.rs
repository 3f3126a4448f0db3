//! Where in a TOML text a thing is: every file we read (scene, calibration,
//! daemon config) names the line of what it refuses, and they all find it
//! the same way.

/// Line (1-based) of a byte offset in `text` (a serde/toml error span).
pub fn line_of_offset(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Line of `key = …` inside `[table]` (best effort: the first line after the
/// table header that assigns the key; `""` for the top level), else the
/// table header's line, else 1. Used for values that parse but are
/// impossible, where the parser gives no span.
pub fn line_of_key(text: &str, table: &str, key: &str) -> usize {
    let mut in_table = table.is_empty();
    let mut header = 1;
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.starts_with('[') {
            in_table = l.trim_matches(|c| c == '[' || c == ']').trim() == table;
            if in_table {
                header = i + 1;
            }
            continue;
        }
        if in_table {
            if let Some((k, _)) = l.split_once('=') {
                if k.trim().trim_matches('"') == key {
                    return i + 1;
                }
            }
        }
    }
    header
}

/// The line of `key` in the `nth` `[[table]]` of `text` (or of that
/// table's header when the key is not in it): a scene's `[[beacons]]`,
/// a station file's.
pub fn line_of_key_nth(text: &str, table: &str, nth: usize, key: &str) -> usize {
    let mut seen = 0;
    let mut in_table = false;
    let mut header = 1;
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.starts_with('[') {
            let name = l.trim_matches(|c| c == '[' || c == ']').trim();
            in_table = false;
            if l.starts_with("[[") && name == table {
                in_table = seen == nth;
                if in_table {
                    header = i + 1;
                }
                seen += 1;
            }
            continue;
        }
        if in_table {
            if let Some((k, _)) = l.split_once('=') {
                if k.trim().trim_matches('"') == key {
                    return i + 1;
                }
            }
        }
    }
    header
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_and_keys() {
        let t = "a = 1\n[water]\nk_d = 2\n\n[beacon]\nv1 = 3\n";
        assert_eq!(line_of_offset(t, 0), 1);
        assert_eq!(line_of_offset(t, 6), 2);
        assert_eq!(line_of_offset(t, 10_000), 7);
        assert_eq!(line_of_key(t, "water", "k_d"), 3);
        assert_eq!(line_of_key(t, "beacon", "v1"), 6);
        assert_eq!(line_of_key(t, "beacon", "sigma"), 5);
        assert_eq!(line_of_key(t, "", "a"), 1);
        assert_eq!(line_of_key(t, "lamp", "x"), 1);
    }
}
