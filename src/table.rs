//! CSV tables (RFC 4180), read and written through the `csv` crate: the one place
//! that knows the dialect of every CSV file ffstream reads or writes (patch tables,
//! radiosity, emission cases).
//!
//! Reading: fields are trimmed, lines starting with `#` and blank lines are skipped,
//! a UTF-8 byte-order mark is ignored, a record is one line, and every record comes
//! with its 1-based line number, so errors can name it. The crate is lenient with
//! quotes (an unclosed one runs to the end of its line); the readers then find a
//! record of the wrong shape and name its line. Writing: fields are quoted only when they need it.

use std::io::Write;
use std::path::Path;

/// A record of a CSV text and the line it starts on.
pub(crate) struct Record {
    pub(crate) line: usize,
    pub(crate) fields: Vec<String>,
}

/// The records of `text` in order (see the module docs), one per line: a quoted
/// field cannot span lines (none of ffstream's files needs one), which keeps line
/// numbers exact (the crate's own count leaves out comment and blank lines).
pub(crate) fn records(text: &str) -> impl Iterator<Item = Result<Record, (usize, String)>> + '_ {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.lines().enumerate().filter_map(|(k, raw)| {
        let line = k + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            return None;
        }
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .trim(csv::Trim::All)
            .from_reader(trimmed.as_bytes());
        Some(match reader.records().next() {
            Some(Ok(rec)) => Ok(Record {
                line,
                fields: rec.iter().map(str::to_owned).collect(),
            }),
            Some(Err(e)) => Err((line, e.to_string())),
            None => Err((line, "no fields".into())),
        })
    })
}

/// A CSV writer on a file, whose errors name the file.
pub(crate) struct TableWriter<W: Write> {
    inner: csv::Writer<W>,
}

impl TableWriter<std::io::BufWriter<std::fs::File>> {
    /// Creates (or truncates) `path`.
    pub(crate) fn create(path: &Path) -> std::io::Result<Self> {
        let file = std::fs::File::create(path)?;
        Ok(Self::new(std::io::BufWriter::new(file)))
    }
}

impl<W: Write> TableWriter<W> {
    pub(crate) fn new(w: W) -> Self {
        TableWriter {
            inner: csv::WriterBuilder::new().flexible(true).from_writer(w),
        }
    }

    /// Writes one record (fields as given; quoted when they need it).
    pub(crate) fn record<I, T>(&mut self, fields: I) -> std::io::Result<()>
    where
        I: IntoIterator<Item = T>,
        T: AsRef<[u8]>,
    {
        self.inner.write_record(fields).map_err(into_io)
    }

    /// Flushes what is buffered (call before dropping: errors are lost on drop).
    pub(crate) fn finish(mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

fn into_io(e: csv::Error) -> std::io::Error {
    match e.into_kind() {
        csv::ErrorKind::Io(e) => e,
        other => std::io::Error::other(format!("{other:?}")),
    }
}

/// `x` for a message, a title or a column name: as Rust prints it from 1e-4 to 1e6
/// (`0.5`, `300`), else in exponent form (`1e300`, `5e-324`), never hundreds of digits
/// (a value at the end of a documented range, issue 48: `--max-edge 1.8e308` was
/// printed as 309 digits, `--da-threshold 5e-324` as 324).
pub fn brief_number(x: f64) -> String {
    match x.abs() {
        a if a == 0.0 || (1e-4..1e6).contains(&a) || !a.is_finite() => x.to_string(),
        _ => format!("{x:e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_round_trip_and_lines_are_counted() {
        let fields = ["plain", "with,comma", "say \"hi\"", ""];
        let mut w = TableWriter::new(Vec::new());
        w.record(["a", "b"]).unwrap();
        w.record(fields).unwrap();
        w.record(["last", "x"]).unwrap();
        let text = String::from_utf8(w.inner.into_inner().unwrap()).unwrap();
        let recs: Vec<Record> = records(&text).map(Result::unwrap).collect();
        assert_eq!(recs[1].fields, fields);
        assert_eq!((recs[0].line, recs[1].line, recs[2].line), (1, 2, 3));
    }

    #[test]
    fn trims_skips_comments_blanks_and_the_bom_and_names_broken_lines() {
        let text = "\u{feff}h1,h2\n# comment\n\n a , b \n   \n\"open,x\n";
        let mut it = records(text);
        let r = it.next().unwrap().unwrap();
        assert_eq!((r.line, r.fields), (1, vec!["h1".to_string(), "h2".into()]));
        let r = it.next().unwrap().unwrap();
        assert_eq!((r.line, r.fields), (4, vec!["a".to_string(), "b".into()]));
        // An unclosed quote runs to the end of its line (the csv crate is lenient):
        // the readers then see one odd field on that line and name it.
        let r = it.next().unwrap().unwrap();
        assert_eq!((r.line, r.fields), (6, vec!["open,x".to_string()]));
        assert!(it.next().is_none());
    }
}
