//! A user's CSV file (tracks, obstacles) read line by line ([`csv_lines`]: an
//! optional header, `#` comments) and one number read from one of its cells:
//! finite, in metres, or an error that names the file, the line, the column and
//! what was found.

use std::io::Read;

/// A line of a user's CSV file, as [`csv_lines`] reads it.
#[derive(Debug)]
pub enum CsvLine {
    /// The first line, read as a header.
    Header {
        /// 1-based line number.
        line: u64,
        /// The column names: lower case, the leading `#` and spaces removed.
        names: Vec<String>,
        /// The line as found, its cells joined by commas.
        found: String,
    },
    /// A line of data.
    Row {
        /// 1-based line number.
        line: u64,
        /// Its cells, trimmed.
        record: csv::StringRecord,
    },
}

/// The lines of a user's CSV file: cells trimmed, any number of them per line;
/// the first line is a header when it starts with `#` or `is_data` says it is
/// not data; later lines starting with `#` are comments, skipped. A line that
/// cannot be read gives its 1-based line number and the reader's error.
pub fn csv_lines<R: Read>(
    reader: R,
    is_data: impl Fn(&csv::StringRecord) -> bool,
) -> impl Iterator<Item = Result<CsvLine, (u64, csv::Error)>> {
    let mut first = true;
    csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(reader)
        .into_records()
        .filter_map(move |rec| {
            let rec = match rec {
                Ok(rec) => rec,
                Err(cause) => return Some(Err((cause.position().map_or(0, |p| p.line()), cause))),
            };
            let line = rec.position().map_or(0, |p| p.line());
            let comment = rec.get(0).unwrap_or("").starts_with('#');
            let is_first = std::mem::replace(&mut first, false);
            if is_first && (comment || !is_data(&rec)) {
                let names = rec
                    .iter()
                    .enumerate()
                    .map(|(i, f)| {
                        let f = if i == 0 { f.trim_start_matches('#') } else { f };
                        f.trim().to_ascii_lowercase()
                    })
                    .collect();
                let found = rec.iter().collect::<Vec<_>>().join(",");
                Some(Ok(CsvLine::Header { line, names, found }))
            } else if comment {
                None
            } else {
                Some(Ok(CsvLine::Row { line, record: rec }))
            }
        })
}

/// A cell that is not a finite number.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CsvValueError {
    /// A value that is not a number.
    #[error("{file}: line {line}: column `{column}` is `{value}`, which is not a number; write a decimal number in metres")]
    NotANumber {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Column name.
        column: &'static str,
        /// The text found.
        value: String,
    },
    /// A NaN or infinite value.
    #[error("{file}: line {line}: column `{column}` is {value}; every value must be a finite number of metres")]
    NonFinite {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Column name.
        column: &'static str,
        /// The value found.
        value: f64,
    },
}

/// Parses `text` (surrounding spaces allowed) as a finite number of metres.
pub fn finite_metres(
    file: &str,
    line: u64,
    column: &'static str,
    text: &str,
) -> Result<f64, CsvValueError> {
    let v: f64 = text.trim().parse().map_err(|_| CsvValueError::NotANumber {
        file: file.to_string(),
        line,
        column,
        value: text.to_string(),
    })?;
    if !v.is_finite() {
        return Err(CsvValueError::NonFinite {
            file: file.to_string(),
            line,
            column,
            value: v,
        });
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finite_numbers_pass_and_others_name_their_cell() {
        assert_eq!(finite_metres("t.csv", 3, "x_m", " -1.5 "), Ok(-1.5));
        let e = finite_metres("t.csv", 3, "x_m", "abc");
        assert!(matches!(e, Err(CsvValueError::NotANumber { line: 3, .. })));
        let message = e.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(
            message.contains("t.csv: line 3: column `x_m` is `abc`"),
            "{message}"
        );
        for bad in ["NaN", "inf", "-inf"] {
            let e = finite_metres("t.csv", 4, "y_m", bad);
            assert!(
                matches!(e, Err(CsvValueError::NonFinite { line: 4, .. })),
                "{bad}"
            );
        }
    }
}
