//! No import cycle between any two modules of the crate: every `crate::…` and
//! `super::…` path in `src/**/*.rs` (in `use` items and in code, groups
//! `{a, b::c}` expanded) is an edge from the module whose file holds it to the
//! deepest module the path names; the graph must have no cycle, directly
//! (`a ↔ b`) or through others (`a → b → c → a`). A `mod` declaration is not an
//! import; comments are not read.

use std::collections::{BTreeMap, BTreeSet};
mod support;

use std::path::{Path, PathBuf};

/// A module's path from the crate root, `""` for the root (`lib.rs`).
type Module = String;

/// The module a file under `src` defines: `lib.rs` the root, `a.rs` and
/// `a/mod.rs` the module `a`, `a/b.rs` the module `a::b`.
fn module_of(src: &Path, file: &Path) -> Module {
    let rel = file.strip_prefix(src).unwrap_or(file);
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if let Some(last) = parts.pop() {
        let stem = last.trim_end_matches(".rs").to_string();
        if stem != "lib" && stem != "mod" && stem != "main" {
            parts.push(stem);
        }
    }
    parts.join("::")
}

/// The text without its comments (line and block) and string literals' contents.
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'/' && b.get(i + 1) == Some(&b'/') {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                    depth += 1;
                    i += 2;
                } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if b[i] == b'"' {
            // A string literal (raw strings hold no `"` in this crate's paths).
            out.push(' ');
            i += 1;
            while i < b.len() && b[i] != b'"' {
                if b[i] == b'\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
        } else if b[i] == b'\'' && b.get(i + 2) == Some(&b'\'') {
            // A char literal such as '{'.
            out.push(' ');
            i += 3;
        } else {
            out.push(char::from(b[i]));
            i += 1;
        }
    }
    out
}

/// The paths of a `use` tree or an expression path starting at `s`, expanded:
/// `a::{b, c::d}` gives `a::b` and `a::c::d`.
fn paths_at(s: &str) -> Vec<Vec<String>> {
    fn tree(s: &[u8], i: &mut usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
        let mut path = prefix;
        loop {
            while *i < s.len() && s[*i].is_ascii_whitespace() {
                *i += 1;
            }
            if *i < s.len() && s[*i] == b'{' {
                *i += 1;
                loop {
                    tree(s, i, path.clone(), out);
                    while *i < s.len() && s[*i].is_ascii_whitespace() {
                        *i += 1;
                    }
                    if *i < s.len() && s[*i] == b',' {
                        *i += 1;
                        continue;
                    }
                    if *i < s.len() && s[*i] == b'}' {
                        *i += 1;
                    }
                    return;
                }
            }
            let start = *i;
            while *i < s.len() && (s[*i].is_ascii_alphanumeric() || s[*i] == b'_') {
                *i += 1;
            }
            if *i == start {
                // `*`, or the end of a group: the path so far.
                if *i < s.len() && s[*i] == b'*' {
                    *i += 1;
                }
                out.push(path);
                return;
            }
            path.push(String::from_utf8_lossy(&s[start..*i]).into_owned());
            if s.get(*i) == Some(&b':') && s.get(*i + 1) == Some(&b':') {
                *i += 2;
                continue;
            }
            out.push(path);
            return;
        }
    }
    let mut out = Vec::new();
    let mut i = 0;
    tree(s.as_bytes(), &mut i, Vec::new(), &mut out);
    out
}

/// The module a path names from `from` (a file's module, with the inline
/// modules such as `tests` the path is in), resolved against `modules`: the
/// deepest module it names (`crate::a::B` names `a`), `None` for one outside the
/// crate.
fn target(from: &Module, path: &[String], modules: &BTreeSet<Module>) -> Option<Module> {
    let mut segments: Vec<String> = if from.is_empty() {
        Vec::new()
    } else {
        from.split("::").map(str::to_string).collect()
    };
    let mut rest = path;
    match rest.first().map(String::as_str) {
        Some("crate") => {
            segments.clear();
            rest = &rest[1..];
        }
        Some("super") => {
            while rest.first().map(String::as_str) == Some("super") {
                segments.pop();
                rest = &rest[1..];
            }
        }
        Some("self") => rest = &rest[1..],
        _ => return None,
    }
    segments.extend(rest.iter().filter(|s| *s != "self").cloned());
    // The longest prefix that is a module of the crate (the root at least).
    (0..=segments.len())
        .rev()
        .map(|n| segments[..n].join("::"))
        .find(|m| modules.contains(m))
}

/// The inline modules (`mod tests { .. }`) open at each byte of `code`, by name.
fn inline_modules(code: &str) -> Vec<(usize, usize, String)> {
    let b = code.as_bytes();
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(k) = code[from..].find("mod ") {
        let at = from + k;
        from = at + 4;
        if at > 0 && (b[at - 1].is_ascii_alphanumeric() || b[at - 1] == b'_') {
            continue;
        }
        let rest = &code[at + 4..];
        let name: String = rest
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let after = rest[name.len()..].trim_start();
        if name.is_empty() || !after.starts_with('{') {
            continue;
        }
        let open = code.len() - after.len();
        let mut depth = 0usize;
        let mut end = code.len();
        for (x, c) in code[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = open + x;
                        break;
                    }
                }
                _ => {}
            }
        }
        out.push((open, end, name));
    }
    out
}

/// The import graph of the crate's modules.
fn graph() -> BTreeMap<Module, BTreeSet<Module>> {
    // `MODULE_GRAPH_SRC=DIR`: another module tree's (its `lib.rs` or `mod.rs`
    // the root), to see its cycles.
    let src = std::env::var_os("MODULE_GRAPH_SRC")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    let files = support::rust_files(&src);
    let modules: BTreeSet<Module> = files.iter().map(|f| module_of(&src, f)).collect();
    let mut edges: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for file in &files {
        let from = module_of(&src, file);
        let text = code_only(&std::fs::read_to_string(file).unwrap_or_default());
        let bytes = text.as_bytes();
        let inline = inline_modules(&text);
        let mut i = 0;
        // A path may also start at a child module of the file's (`replay::Replay`).
        let children: Vec<String> = modules
            .iter()
            .filter_map(|m| {
                let rest = if from.is_empty() {
                    Some(m.as_str())
                } else {
                    m.strip_prefix(from.as_str())?.strip_prefix("::")
                };
                rest.filter(|r| !r.is_empty() && !r.contains("::"))
                    .map(|r| format!("{r}::"))
            })
            .collect();
        let starts: Vec<String> = ["crate::", "super::", "self::"]
            .iter()
            .map(|s| s.to_string())
            .chain(children.iter().cloned())
            .collect();
        while let Some(k) = starts
            .iter()
            .filter_map(|p| text[i..].find(p.as_str()))
            .min()
        {
            let at = i + k;
            let word_start = at == 0
                || !(bytes[at - 1].is_ascii_alphanumeric()
                    || bytes[at - 1] == b'_'
                    || bytes[at - 1] == b':');
            i = at + 1;
            if !word_start {
                continue;
            }
            // The path's module: the file's, and the inline modules around it.
            let mut here = from.clone();
            for (open, end, name) in &inline {
                if *open < at && at < *end {
                    here = if here.is_empty() {
                        name.clone()
                    } else {
                        format!("{here}::{name}")
                    };
                }
            }
            for mut path in paths_at(&text[at..]) {
                let child = path
                    .first()
                    .is_some_and(|p| children.contains(&format!("{p}::")));
                if child {
                    // Absolute: the file's module, then the child.
                    let mut abs = vec!["crate".to_string()];
                    abs.extend(
                        from.split("::")
                            .filter(|s| !s.is_empty())
                            .map(str::to_string),
                    );
                    abs.append(&mut path);
                    path = abs;
                }
                if let Some(to) = target(&here, &path, &modules) {
                    if to != from {
                        edges.entry(from.clone()).or_default().insert(to);
                    }
                }
            }
        }
        edges.entry(from).or_default();
    }
    edges
}

/// The strongly connected components of more than one module (Tarjan).
fn cycles(edges: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    struct State<'a> {
        edges: &'a BTreeMap<Module, BTreeSet<Module>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        out: Vec<Vec<Module>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        let edges = s.edges;
        for w in edges.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low[v];
                s.low.insert(v, lv.min(lw));
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low[v];
                s.low.insert(v, lv.min(iw));
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                s.out.push(comp);
            }
        }
    }
    let mut s = State {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out
}

#[test]
fn no_two_modules_import_each_other() {
    let edges = graph();
    if std::env::var_os("MODULE_GRAPH_PRINT").is_some() {
        for (m, to) in &edges {
            eprintln!("{m}: {to:?}");
        }
    }
    assert!(edges.len() > 20, "modules found: {:?}", edges.keys());
    let found = cycles(&edges);
    let show = |m: &str| {
        if m.is_empty() {
            "crate".to_string()
        } else {
            m.to_string()
        }
    };
    let described: Vec<String> = found
        .iter()
        .map(|c| {
            let mut pairs = Vec::new();
            for a in c {
                for b in edges.get(a).into_iter().flatten() {
                    if c.contains(b) {
                        pairs.push(format!("{} → {}", show(a), show(b)));
                    }
                }
            }
            format!(
                "[{}]: {}",
                c.iter().map(|m| show(m)).collect::<Vec<_>>().join(", "),
                pairs.join("; ")
            )
        })
        .collect();
    assert!(
        described.is_empty(),
        "import cycles:\n{}",
        described.join("\n")
    );
}

#[test]
fn the_graph_reader_sees_groups_super_and_a_cycle() {
    let modules: BTreeSet<Module> = ["", "a", "b", "a::c"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let p = paths_at("crate::{a::X, b}; rest");
    assert_eq!(p.len(), 2);
    assert_eq!(
        target(&"a::c".into(), &p[0], &modules),
        Some("a".to_string())
    );
    assert_eq!(
        target(&"a::c".into(), &p[1], &modules),
        Some("b".to_string())
    );
    let up = paths_at("super::super::b::f(x)");
    assert_eq!(
        target(&"a::c".into(), &up[0], &modules),
        Some("b".to_string())
    );
    assert_eq!(code_only("x // crate::a\n\"crate::b\" y"), "x \n  y");
    let mut g: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    g.entry("a".into()).or_default().insert("b".into());
    g.entry("b".into()).or_default().insert("a::c".into());
    g.entry("a::c".into()).or_default().insert("a".into());
    assert_eq!(cycles(&g).len(), 1);
}
