//! `.cargo/mutants.toml` names each equivalent mutant the mutation pass may skip by
//! its file, line and column (as `cargo mutants` names it), its operator and its
//! function, and anchors it by the source it mutates (`# at `...``). When the code
//! moves, an entry stops matching its mutant, which the pass then reports as
//! missed, or worse matches another: every entry must still point at its anchor's
//! operator, inside the function it names. `MUTANTS_BLESS=1` writes the anchors'
//! new positions into the file instead of failing.
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
    /// The source the mutant changes, unique in its function; the operator is
    /// its first occurrence in it.
    anchor: String,
}

/// The regex of an entry as the plain mutant name it matches (the entries escape
/// `.`, `+`, `*` only).
fn unescape(s: &str) -> String {
    s.replace("\\.", ".")
        .replace("\\+", "+")
        .replace("\\*", "*")
}

fn parse(entry: &str, anchor: &str) -> Exclusion {
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
        anchor: anchor.to_string(),
    }
}

/// An entry's line of the file: its regex (unescaped) and its anchor.
fn entry_of(line: &str) -> Option<(String, String)> {
    let t = line.trim();
    let rest = t.strip_prefix('\'')?;
    let (regex, tail) = rest.split_once("',")?;
    let anchor = tail
        .trim()
        .strip_prefix("# at `")
        .and_then(|a| a.strip_suffix('`'))
        .unwrap_or_else(|| panic!("no `# at `...`` anchor after the entry: {t}"));
    Some((unescape(regex), anchor.to_string()))
}

/// Where the anchor of `e` is now: the line and column (1-based) of its
/// operator, on the one line of `e.function` that holds the anchor; an error
/// when no line or more than one does.
fn locate(lines: &[&str], e: &Exclusion) -> Result<(usize, usize), String> {
    let op = e.anchor.find(&e.operator);
    // The lines that hold the anchor first; only those look up their function.
    let found: Vec<(usize, usize)> = lines
        .iter()
        .enumerate()
        .flat_map(|(i, l)| {
            l.match_indices(e.anchor.as_str())
                .filter_map(move |(at, _)| Some((i + 1, l[..at + op?].chars().count() + 1)))
        })
        .filter(|&(line, _)| enclosing_fn(lines, line).as_deref() == Some(e.function.as_str()))
        .collect();
    match found.as_slice() {
        [one] => Ok(*one),
        [] => Err(format!(
            "{}: `{}` (with `{}`) is in no line of {}",
            e.file, e.anchor, e.operator, e.function
        )),
        _ => Err(format!(
            "{}: `{}` is on {} lines of {}: make the anchor unique",
            e.file,
            e.anchor,
            found.len(),
            e.function
        )),
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
    let path = root.join(".cargo/mutants.toml");
    let config = std::fs::read_to_string(&path).unwrap();
    let bless = std::env::var_os("MUTANTS_BLESS").is_some();
    let mut stale = Vec::new();
    let mut unanchored = Vec::new();
    let mut entries = 0;
    let mut out = String::new();
    for raw in config.lines() {
        let Some((regex, anchor)) = entry_of(raw) else {
            out.push_str(raw);
            out.push('\n');
            continue;
        };
        entries += 1;
        let e = parse(&regex, &anchor);
        let source = std::fs::read_to_string(root.join(&e.file)).unwrap();
        let lines: Vec<&str> = source.lines().collect();
        let mut line = raw.to_string();
        match locate(&lines, &e) {
            Ok((l, c)) if (l, c) != (e.line, e.column) => {
                stale.push(format!(
                    "{}:{}:{} is now {}:{}:{} (`{}` in {})",
                    e.file, e.line, e.column, e.file, l, c, e.anchor, e.function
                ));
                let (old, new) = (
                    format!(":{}:{}: replace", e.line, e.column),
                    format!(":{l}:{c}: replace"),
                );
                line = line.replacen(&old, &new, 1);
            }
            Ok(_) => {}
            Err(why) => unanchored.push(why),
        }
        out.push_str(&line);
        out.push('\n');
    }
    assert!(entries >= 10, "{entries} entries");
    assert!(unanchored.is_empty(), "{}", unanchored.join("\n"));
    if bless && !stale.is_empty() {
        std::fs::write(&path, out).unwrap();
        return;
    }
    assert!(
        stale.is_empty(),
        "stale entries in .cargo/mutants.toml (the code moved; \
         `MUTANTS_BLESS=1 cargo test -p firmware --test mutants_config` writes the new \
         positions):\n{}",
        stale.join("\n")
    );
}

#[test]
fn an_anchor_gives_its_operators_new_place_or_says_why_not() {
    let e = parse("x.rs:2:7: replace > with >= in f", "a > 1");
    let lines = ["fn f(a: u8) -> bool {", "    a > 1", "}"];
    assert_eq!(locate(&lines, &e), Ok((2, 7)));
    // Moved a line down and two columns right: its new place.
    let moved = ["fn f(a: u8) -> bool {", "", "      a > 1", "}"];
    assert_eq!(locate(&moved, &e), Ok((3, 9)));
    // Only in another function, or twice in its own: refused.
    let elsewhere = [
        "fn f(a: u8) -> bool {",
        "    a < 1",
        "}",
        "fn g(a: u8) -> bool {",
        "    a > 1",
        "}",
    ];
    assert!(locate(&elsewhere, &e).unwrap_err().contains("no line"));
    let twice = ["fn f(a: u8) -> bool {", "    a > 1 && a > 1", "}"];
    assert!(locate(&twice, &e).unwrap_err().contains("unique"));
    // The operator's first occurrence in the anchor.
    let second = parse("x.rs:2:12: replace > with >= in f", "1 && a >");
    assert_eq!(
        locate(
            &["fn f(a: u8) -> bool {", "    a > 1 && a > 1", "}"],
            &second
        ),
        Ok((2, 16))
    );
}
