//! No function of the crate is longer than [`MAX_LINES`] lines, from its `fn`
//! line to its closing brace: a longer one is split into its phases.

mod support;

use std::path::Path;

/// The longest a function may be, lines.
const MAX_LINES: usize = 150;

/// The functions of `text` as `(name, first line, lines)`: a line whose code
/// starts with `fn` (after `pub`, `pub(crate)`, `const`, ...) up to the first
/// line after it that is the same indentation's `}`.
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let code = line.trim_start();
        let indent = &line[..line.len() - code.len()];
        let mut rest = code;
        for prefix in [
            "pub(crate) ",
            "pub(super) ",
            "pub ",
            "const ",
            "async ",
            "unsafe ",
        ] {
            rest = rest.strip_prefix(prefix).unwrap_or(rest);
        }
        let Some(sig) = rest.strip_prefix("fn ") else {
            continue;
        };
        let name: String = sig
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let close = format!("{indent}}}");
        if let Some(end) = lines[i + 1..].iter().position(|l| *l == close) {
            out.push((name, i + 1, end + 2));
        }
    }
    out
}

#[test]
fn no_function_is_longer_than_its_phases_need() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = support::rust_files(&src);
    let mut long = Vec::new();
    let mut count = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap_or_default();
        for (name, line, len) in functions(&text) {
            count += 1;
            if len > MAX_LINES {
                long.push(format!("{}:{line} `{name}`: {len} lines", file.display()));
            }
        }
    }
    assert!(count > 300, "functions found: {count}");
    assert!(
        long.is_empty(),
        "longer than {MAX_LINES} lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn a_function_runs_to_its_own_closing_brace() {
    let text = "pub fn a() {\n    if x {\n    }\n}\n\n    pub(crate) fn b(\n        y: u8,\n    ) {\n    }\n";
    assert_eq!(
        functions(text),
        vec![("a".to_string(), 1, 4), ("b".to_string(), 6, 4)]
    );
}
