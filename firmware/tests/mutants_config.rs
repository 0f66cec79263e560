//! `.cargo/mutants.toml` names each equivalent mutant the mutation pass may skip by
//! its file, line and column (as `cargo mutants` names it), its operator and its
//! function. When the code moves, an entry stops matching its mutant, which the
//! pass then reports as missed, or worse matches another: every entry must still
//! point at the operator it names, inside the function it names.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::Path;

/// One exclusion: file, line, column (1-based), the operator, the function.
#[derive(Debug)]
struct Exclusion {
    file: String,
    line: usize,
    column: usize,
    operator: String,
    function: String,
}

/// The regex of an entry as the plain mutant name it matches (the entries escape
/// `.`, `+`, `*` only).
fn unescape(s: &str) -> String {
    s.replace("\\.", ".")
        .replace("\\+", "+")
        .replace("\\*", "*")
}

fn parse(entry: &str) -> Exclusion {
    // "firmware/src/pid.rs:316:36: replace > with >= in update_within"
    let (location, what) = entry
        .split_once(": replace ")
        .unwrap_or_else(|| panic!("not `FILE:LINE:COL: replace A with B in F`: {entry}"));
    let mut parts = location.rsplitn(3, ':');
    let column = parts.next().unwrap().parse().unwrap();
    let line = parts.next().unwrap().parse().unwrap();
    let file = parts.next().unwrap().to_string();
    let (operator, rest) = what.split_once(" with ").unwrap();
    let (_, function) = rest.split_once(" in ").unwrap();
    Exclusion {
        file,
        line,
        column,
        operator: operator.to_string(),
        function: function.rsplit("::").next().unwrap().to_string(),
    }
}

/// The name of the last `fn` declared at or above line `line` (1-based).
fn enclosing_fn(lines: &[&str], line: usize) -> Option<String> {
    lines[..line].iter().rev().find_map(|l| {
        let (_, after) = l.split_once("fn ")?;
        let name: String = after
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        (!name.is_empty()).then_some(name)
    })
}

#[test]
fn every_excluded_mutant_still_names_its_operator_in_its_function() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let config = std::fs::read_to_string(root.join(".cargo/mutants.toml")).unwrap();
    let entries: Vec<Exclusion> = config
        .lines()
        .filter_map(|l| {
            let t = l.trim();
            t.strip_prefix('\'')?.strip_suffix("',").map(unescape)
        })
        .map(|e| parse(&e))
        .collect();
    assert!(entries.len() >= 10, "{entries:?}");
    let mut stale = Vec::new();
    for e in &entries {
        let source = std::fs::read_to_string(root.join(&e.file)).unwrap();
        let lines: Vec<&str> = source.lines().collect();
        let at: String = lines.get(e.line - 1).map_or(String::new(), |l| {
            l.chars()
                .skip(e.column - 1)
                .take(e.operator.chars().count())
                .collect()
        });
        let function = enclosing_fn(&lines, e.line.min(lines.len()));
        if at != e.operator || function.as_deref() != Some(e.function.as_str()) {
            stale.push(format!(
                "{}:{}:{}: `{}` in {} expected, found `{at}` in {function:?}",
                e.file, e.line, e.column, e.operator, e.function
            ));
        }
    }
    assert!(
        stale.is_empty(),
        "stale entries in .cargo/mutants.toml (the code moved: find the mutant's new \
         line and column with `cargo mutants --list -f FILE`):\n{}",
        stale.join("\n")
    );
}

#[test]
fn a_moved_operator_is_reported_as_stale() {
    let lines = ["fn f(a: u8) -> bool {", "    a > 1", "}"];
    let e = parse("x.rs:2:7: replace > with >= in f");
    let at: String = lines[e.line - 1]
        .chars()
        .skip(e.column - 1)
        .take(1)
        .collect();
    assert_eq!(at, ">");
    assert_eq!(enclosing_fn(&lines, e.line).as_deref(), Some("f"));
    let moved = parse("x.rs:2:8: replace > with >= in f");
    let at: String = lines[moved.line - 1]
        .chars()
        .skip(moved.column - 1)
        .take(1)
        .collect();
    assert_ne!(at, ">");
}
