//! A small strict reader for the flat YAML of a ROS map_server map file.
//!
//! Why not a YAML crate: a map file is a handful of `key: value` lines with one list
//! (`origin`), and the maintained YAML crates (serde_yaml is archived; its forks and
//! yaml-rust2/saphyr) each pull in a full YAML 1.2 parser for that. Forty lines that accept
//! exactly the subset map_server files use, and say precisely what is wrong with anything
//! else, are leaner and give better errors. Accepted: comments (`#`), blank lines,
//! `key: scalar`, `key: [a, b, c]` and a block list (`key:` then `- a` lines); scalars may be
//! single- or double-quoted. Anything else (nesting, anchors, multi-line strings) is refused.

use std::collections::BTreeMap;

/// A value: one scalar or a list of scalars.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A scalar, quotes removed.
    Scalar(String),
    /// A flow or block list of scalars.
    List(Vec<String>),
}

/// A parsed file: each key with the line it was on (1-based) and its value.
pub type Document = BTreeMap<String, (usize, Value)>;

/// A syntax error: the line (1-based) and what was wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntaxError {
    /// Line number, 1-based.
    pub line: usize,
    /// What was expected.
    pub message: String,
}

fn unquote(s: &str) -> String {
    let s = s.trim();
    for q in ['"', '\''] {
        if s.len() >= 2 && s.starts_with(q) && s.ends_with(q) {
            return s[1..s.len() - 1].to_string();
        }
    }
    s.to_string()
}

/// Strips a `#` comment that is not inside quotes.
fn strip_comment(line: &str) -> &str {
    let mut quote = None;
    for (i, ch) in line.char_indices() {
        match (quote, ch) {
            (None, '"' | '\'') => quote = Some(ch),
            (Some(q), c) if c == q => quote = None,
            // A comment starts a line or follows whitespace (YAML's rule).
            (None, '#') if i == 0 || line[..i].ends_with([' ', '\t']) => return &line[..i],
            _ => {}
        }
    }
    line
}

/// Parses the flat subset described in the module doc.
pub fn parse(text: &str) -> Result<Document, SyntaxError> {
    let mut doc = Document::new();
    // The key of an open block list, and its items so far.
    let mut block: Option<(String, usize, Vec<String>)> = None;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let err = |message: String| SyntaxError {
            line: line_no,
            message,
        };
        let line = strip_comment(raw).trim_end();
        if line.trim().is_empty() || line.trim() == "---" {
            continue;
        }
        let trimmed = line.trim_start();
        if let Some(item) =
            trimmed
                .strip_prefix("- ")
                .or(if trimmed == "-" { Some("") } else { None })
        {
            let Some((_, _, items)) = block.as_mut() else {
                return Err(err("a list item `- ...` outside a list".into()));
            };
            items.push(unquote(item));
            continue;
        }
        if let Some((key, at, items)) = block.take() {
            doc.insert(key, (at, Value::List(items)));
        }
        if line.starts_with([' ', '\t']) {
            return Err(err(format!(
                "unexpected indentation (map files are flat `key: value` lines): `{}`",
                line.trim()
            )));
        }
        let Some((key, value)) = line.split_once(':') else {
            return Err(err(format!(
                "expected `key: value`, found `{}`",
                line.trim()
            )));
        };
        let key = key.trim().to_string();
        if key.is_empty() || key.contains(char::is_whitespace) {
            return Err(err(format!("bad key `{key}`")));
        }
        if doc.contains_key(&key) {
            return Err(err(format!("`{key}` given twice")));
        }
        let value = value.trim();
        if value.is_empty() {
            block = Some((key, line_no, Vec::new()));
        } else if let Some(inner) = value.strip_prefix('[') {
            let Some(inner) = inner.strip_suffix(']') else {
                return Err(err(format!(
                    "`{key}`: a list must close with `]` on the same line"
                )));
            };
            let items = if inner.trim().is_empty() {
                Vec::new()
            } else {
                inner.split(',').map(unquote).collect()
            };
            doc.insert(key, (line_no, Value::List(items)));
        } else if value.starts_with(['{', '&', '*', '|', '>']) {
            return Err(err(format!(
                "`{key}`: only plain scalars and lists are supported, found `{value}`"
            )));
        } else {
            doc.insert(key, (line_no, Value::Scalar(unquote(value))));
        }
    }
    if let Some((key, at, items)) = block {
        doc.insert(key, (at, Value::List(items)));
    }
    Ok(doc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_map_server_file() {
        let doc = parse(
            "# header\nimage: 'my map.pgm'\nresolution: 0.05 # metres\norigin: [-1.5, 2, 0.0]\nnegate: 0\n",
        )
        .expect("valid");
        assert_eq!(doc["image"].1, Value::Scalar("my map.pgm".into()));
        assert_eq!(doc["resolution"], (3, Value::Scalar("0.05".into())));
        assert_eq!(
            doc["origin"].1,
            Value::List(vec!["-1.5".into(), "2".into(), "0.0".into()])
        );
    }

    #[test]
    fn reads_a_block_list() {
        let doc = parse("origin:\n  - 1\n  - 2\n  - 0\nnegate: 1\n").expect("valid");
        assert_eq!(
            doc["origin"].1,
            Value::List(vec!["1".into(), "2".into(), "0".into()])
        );
        assert_eq!(doc["negate"].1, Value::Scalar("1".into()));
    }

    #[test]
    fn refuses_what_it_does_not_understand() {
        assert_eq!(parse("a: 1\na: 2\n").expect_err("dup").line, 2);
        assert_eq!(parse("a: 1\n  b: 2\n").expect_err("nested").line, 2);
        assert_eq!(parse("origin: [1, 2\n").expect_err("open").line, 1);
        assert_eq!(parse("just words\n").expect_err("no colon").line, 1);
        assert_eq!(parse("- 1\n").expect_err("stray item").line, 1);
        assert_eq!(parse("a: {b: 1}\n").expect_err("mapping").line, 1);
    }
}
