//! One number read from a cell of a user's CSV file (tracks, obstacles): finite, in
//! metres, or an error that names the file, the line, the column and what was found.

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
