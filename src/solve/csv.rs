//! The small part of CSV (RFC 4180) the solve files need: comma-separated fields,
//! double-quoted when they hold a comma, quote or line break, `""` for a quote inside.

use std::borrow::Cow;

/// Quote `field` if it needs it.
pub(crate) fn escape(field: &str) -> Cow<'_, str> {
    if field.contains([',', '"', '\n', '\r']) {
        Cow::Owned(format!("\"{}\"", field.replace('"', "\"\"")))
    } else {
        Cow::Borrowed(field)
    }
}

/// Split one line into fields (unquoted fields are trimmed).
///
/// # Errors
/// A message when a quoted field is not closed or is followed by other text.
pub(crate) fn split_line(line: &str) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    let mut chars = line.trim_end_matches(['\r', '\n']).chars().peekable();
    loop {
        // Skip leading blanks of the field.
        while chars.peek() == Some(&' ') || chars.peek() == Some(&'\t') {
            chars.next();
        }
        let mut field = String::new();
        if chars.peek() == Some(&'"') {
            chars.next();
            loop {
                match chars.next() {
                    None => return Err("unterminated quoted field".into()),
                    Some('"') if chars.peek() == Some(&'"') => {
                        chars.next();
                        field.push('"');
                    }
                    Some('"') => break,
                    Some(c) => field.push(c),
                }
            }
            while chars.peek() == Some(&' ') || chars.peek() == Some(&'\t') {
                chars.next();
            }
            match chars.next() {
                None => {
                    out.push(field);
                    return Ok(out);
                }
                Some(',') => out.push(field),
                Some(c) => return Err(format!("unexpected '{c}' after a quoted field")),
            }
        } else {
            loop {
                match chars.next() {
                    None => {
                        out.push(field.trim().to_string());
                        return Ok(out);
                    }
                    Some(',') => break,
                    Some(c) => field.push(c),
                }
            }
            out.push(field.trim().to_string());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_round_trips_through_split() {
        let fields = ["plain", "with,comma", "say \"hi\"", ""];
        let line = fields
            .iter()
            .map(|f| escape(f))
            .collect::<Vec<_>>()
            .join(",");
        assert_eq!(split_line(&line).unwrap(), fields);
    }

    #[test]
    fn split_trims_and_rejects_broken_quotes() {
        assert_eq!(split_line(" a , b,c \r\n").unwrap(), ["a", "b", "c"]);
        assert!(split_line("\"open").is_err());
        assert!(split_line("\"x\"y,z").is_err());
    }
}
