//! Where a key sits in a TOML config file, for errors the parser cannot
//! place: a value of the right type that the program refuses (a baud of
//! 123456, a scan range out of order). The parser reports its own errors
//! with line and column; these come after it, from the typed config, and
//! without this the user gets a message but no line.

/// The 1-based line and column of `key` inside the `index`-th (0-based)
/// `[[table]]` of `text`, including its sub-tables (`[table.poll]`);
/// `None` when the key is not written there (a default was used).
pub(crate) fn key_in_table_array(
    text: &str,
    table: &str,
    index: usize,
    key: &str,
) -> Option<(usize, usize)> {
    let header = format!("[[{table}]]");
    let sub = format!("[{table}.");
    let mut seen = 0usize;
    let mut inside = false;
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') {
            if trimmed.starts_with(&header) {
                inside = seen == index;
                seen += 1;
            } else if !trimmed.starts_with(&sub) {
                inside = false;
            }
            continue;
        }
        if !inside {
            continue;
        }
        if let Some(after) = trimmed.strip_prefix(key) {
            if after.trim_start().starts_with('=') {
                return Some((n + 1, line.len() - trimmed.len() + 1));
            }
        }
    }
    None
}

/// The 1-based line of the `index`-th (0-based) `[[table]]` header of `text`.
pub(crate) fn table_array_line(text: &str, table: &str, index: usize) -> Option<usize> {
    let header = format!("[[{table}]]");
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.trim_start().starts_with(&header))
        .nth(index)
        .map(|(n, _)| n + 1)
}

#[cfg(test)]
mod tests {
    use super::{key_in_table_array, table_array_line};

    #[test]
    fn finds_the_header_of_the_nth_table() {
        assert_eq!(table_array_line(TEXT, "bus", 1), Some(7));
        assert_eq!(table_array_line(TEXT, "limit", 0), Some(14));
        assert_eq!(table_array_line(TEXT, "limit", 1), None);
    }

    const TEXT: &str = "listen = \"127.0.0.1:8080\"\n\n[[bus]]\nname = \"a\"\nbaud = 500000\n\n[[bus]]\nname = \"b\"\n  baud = 123456\n\n[bus.poll]\ncontrol_share = 2.0\n\n[[limit]]\nbaud = 1\n";

    #[test]
    fn finds_a_key_in_the_right_table_of_the_array() {
        assert_eq!(key_in_table_array(TEXT, "bus", 0, "baud"), Some((5, 1)));
        assert_eq!(key_in_table_array(TEXT, "bus", 1, "baud"), Some((9, 3)));
    }

    #[test]
    fn finds_a_key_in_a_sub_table_and_not_past_the_array() {
        assert_eq!(
            key_in_table_array(TEXT, "bus", 1, "control_share"),
            Some((12, 1))
        );
        assert_eq!(key_in_table_array(TEXT, "bus", 0, "control_share"), None);
        assert_eq!(key_in_table_array(TEXT, "bus", 2, "baud"), None);
    }

    #[test]
    fn a_key_that_only_starts_the_same_is_not_it() {
        let text = "[[bus]]\nbaud_level = 1\nbaud = 7\n";
        assert_eq!(key_in_table_array(text, "bus", 0, "baud"), Some((3, 1)));
    }
}
