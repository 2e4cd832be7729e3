//! Text files of whitespace-separated numbers, one record per line (trajectories, benchmark
//! relations): blank lines and `#` comments skipped, every other line exactly `fields` finite
//! numbers.

/// Why a text file of numbers could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TextFileError {
    /// The file could not be read.
    #[error("cannot read {path}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A malformed line.
    #[error("{path} line {line}: {what}")]
    Line {
        /// File (or whatever named the text).
        path: String,
        /// 1-based line.
        line: usize,
        /// What was wrong.
        what: String,
    },
}

/// The 1-based number of a bad line, and what was wrong with it.
pub(crate) type BadLine = (usize, String);

/// [`parse`] with errors naming `path`.
pub(crate) fn parse_named(
    text: &str,
    path: &str,
    fields: usize,
    layout: &str,
) -> Result<Vec<Vec<f64>>, TextFileError> {
    parse(text, fields, layout).map_err(|(line, what)| TextFileError::Line {
        path: path.to_string(),
        line,
        what,
    })
}

/// Reads a file as text, with an error naming it.
pub(crate) fn read(path: &std::path::Path) -> Result<String, TextFileError> {
    std::fs::read_to_string(path).map_err(|source| TextFileError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// The records of `text`; on the first bad line, its number and what was wrong. `layout` names
/// the fields for the message, e.g. `t x y theta`.
pub(crate) fn parse(text: &str, fields: usize, layout: &str) -> Result<Vec<Vec<f64>>, BadLine> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let values: Vec<f64> = line
            .split_ascii_whitespace()
            .map(|f| {
                f.parse::<f64>()
                    .map_err(|_| (i + 1, format!("{f:?} is not a number")))
            })
            .collect::<Result<_, _>>()?;
        if values.len() != fields || values.iter().any(|v| !v.is_finite()) {
            return Err((
                i + 1,
                format!(
                    "expected {fields} finite numbers ({layout}), got {}",
                    values.len()
                ),
            ));
        }
        out.push(values);
    }
    Ok(out)
}
