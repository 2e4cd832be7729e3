//! Text files of whitespace-separated numbers, one record per line (trajectories, benchmark
//! relations): blank lines and `#` comments skipped, every other line exactly `fields` finite
//! numbers.

/// The 1-based number of a bad line, and what was wrong with it.
pub(crate) type BadLine = (usize, String);

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
