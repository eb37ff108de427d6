//! The header's params string as the format defines it (spec §3.2): settings separated
//! by single spaces, each `key=value`, values percent-encoded where they would hold
//! `%`, `=` or white space. [`ParamList`] reads and writes that form and compares two
//! of them the way a resume does (spec §9.2: every key but those ending in `_path`).
//!
//! What the keys mean is not the format's business: the job layer's typed
//! `RunParams` (`src/job/params.rs`) writes its settings through a [`ParamList`] and
//! reads them back from one. Any file's string, of any version, parses into a
//! [`ParamList`], unknown keys included, so the resume check here works on files that
//! older or newer versions wrote.

use std::fmt;

/// The settings of a params string, in order, as (key, value) pairs (a token without
/// `=` is a key with an empty value).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ParamList {
    entries: Vec<(String, String)>,
}

impl ParamList {
    /// The settings of `params` (any version's), in order.
    pub fn parse(params: &str) -> Self {
        let entries = params
            .split_ascii_whitespace()
            .map(|t| {
                let (k, v) = t.split_once('=').unwrap_or((t, ""));
                (k.to_string(), v.to_string())
            })
            .collect();
        ParamList { entries }
    }

    /// Adds `key=value` as it is: `value` must hold no white space or `=` (numbers,
    /// names, values already encoded; a path goes through [`ParamList::push_encoded`]).
    pub fn push(&mut self, key: &str, value: impl fmt::Display) {
        let value = value.to_string();
        debug_assert!(
            !value.contains(|c: char| c.is_whitespace() || c == '='),
            "{key}={value} needs encoding"
        );
        self.entries.push((key.to_string(), value));
    }

    /// Adds `key=value` with `value` percent-encoded ([`encode_value`]).
    pub fn push_encoded(&mut self, key: &str, value: &str) {
        self.entries.push((key.to_string(), encode_value(value)));
    }

    /// The value of `key` as stored (still percent-encoded), if the list has it.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.entries
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The (key, value) pairs in order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &str)> {
        self.entries.iter().map(|(k, v)| (k.as_str(), v.as_str()))
    }

    /// The pairs that decide the rows: all but the keys ending in `_path` (where an
    /// input was read from; the scene hash, or a `_hash` key, stands for its content).
    fn settings(&self) -> impl Iterator<Item = (&str, &str)> {
        self.iter().filter(|(k, _)| !k.ends_with("_path"))
    }

    /// The first setting in which a file's params (`self`) and a new run's (`new`)
    /// differ, said as a resume refuses it; None when they agree (spec §9.2).
    pub fn difference(&self, new: &ParamList) -> Option<String> {
        let value = |list: &ParamList, key: &str| {
            list.settings()
                .find(|(k, _)| *k == key)
                .map(|(_, v)| v.to_string())
        };
        for (k, v) in self.settings() {
            match value(new, k) {
                Some(w) if w == v => {}
                Some(w) => {
                    return Some(format!(
                        "{k} differs: the file was computed with {k}={v}, this run has {k}={w}"
                    ))
                }
                None => {
                    return Some(format!(
                        "the file was computed with {k}={v}, this run has no {k}"
                    ))
                }
            }
        }
        new.settings()
            .find(|(k, _)| value(self, k).is_none())
            .map(|(k, v)| format!("this run has {k}={v}, the file was computed without {k}"))
    }
}

impl fmt::Display for ParamList {
    /// The params string: `key=value` tokens joined by single spaces.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (n, (k, v)) in self.entries.iter().enumerate() {
            if n > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{k}={v}")?;
        }
        Ok(())
    }
}

/// `s` as one value of a params string: `%`, `=` and white space percent-encoded
/// (each byte of a white-space character as `%XX`).
pub fn encode_value(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '%' | '=' => out.push_str(&format!("%{:02X}", c as u32)),
            c if c.is_whitespace() => {
                let mut b = [0; 4];
                for byte in c.encode_utf8(&mut b).bytes() {
                    out.push_str(&format!("%{byte:02X}"));
                }
            }
            c => out.push(c),
        }
    }
    out
}

/// The text [`encode_value`] encoded (a `%` not followed by two hex digits is kept as
/// it is; bytes that are not UTF-8 become U+FFFD).
pub fn decode_value(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut k = 0;
    while k < b.len() {
        let hex = b
            .get(k + 1..k + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (b[k], hex) {
            (b'%', Some(byte)) => {
                out.push(byte);
                k += 3;
            }
            (c, _) => {
                out.push(c);
                k += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_resume_compares_every_key_but_paths_and_names_the_first_difference() {
        let old = ParamList::parse("a=1 b=2 scene_path=x.obj");
        assert_eq!(
            old.difference(&ParamList::parse("a=1 b=2 scene_path=y.obj")),
            None
        );
        assert_eq!(
            old.difference(&ParamList::parse("a=1 b=3")).unwrap(),
            "b differs: the file was computed with b=2, this run has b=3"
        );
        assert_eq!(
            old.difference(&ParamList::parse("b=2")).unwrap(),
            "the file was computed with a=1, this run has no a"
        );
        assert_eq!(
            old.difference(&ParamList::parse("a=1 b=2 c")).unwrap(),
            "this run has c=, the file was computed without c"
        );
    }

    #[test]
    fn encoded_values_hold_no_separator_and_decode_back() {
        let s = "my dir/a=b%c\tx.obj";
        let e = encode_value(s);
        assert_eq!(e, "my%20dir/a%3Db%25c%09x.obj");
        assert_eq!(decode_value(&e), s);
        let mut l = ParamList::default();
        l.push("n", 3);
        l.push_encoded("scene_path", s);
        assert_eq!(ParamList::parse(&l.to_string()), l);
    }
}
