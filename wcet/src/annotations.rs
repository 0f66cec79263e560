//! Loop bounds written beside the loops in the target's source (its source
//! folders, [`SourceDir`]), as expressions of the target's own constants
//! ([`crate::target::Target::constants`]), matched to the binary's loops through
//! the DWARF line table.
//!
//! ```text
//! // wcet-bound: HORIZON
//! for k in 0..HORIZON {
//!
//! while i < m { // wcet-bound: NC
//!
//! // wcet-bound: QP_MAX_ITER per activation
//! loop {
//!
//! let now = loop { // wcet-bound: 1 per preemption
//!
//! // wcet-bound: NV * 4 bytes
//! tail.fill(T::ZERO);
//! ```
//!
//! The expression bounds the loop's iterations per entry (or, with `per
//! activation`, over the task's whole activation: a cap that spans the loop's
//! entries, such as the QP iterations summed over the MPC's passes); a loop of
//! `n` iterations takes its back edge at most `n` times, so the expression is also
//! the bound on back edges, and `n − 1` times where the compiler rotated the loop
//! so that its header cannot leave it: every run of the header is then an
//! iteration, and the IPET bounds the header's runs by `n`
//! ([`super::ipet::header_starts_iterations`]). It is made of integer literals, the names in
//! the target's constants ([`crate::target::Target::constants`]), `+ - * /` (integer division rounding up) and
//! parentheses. A comment alone on its line applies to the next line of code; a
//! comment after code applies to its own line.
//!
//! With `per loop entry`, the annotation is not a loop's either: the code of its
//! line (a call, inlined or not) runs at most EXPR times per entry of the
//! innermost loop around it (a retry done once in a loop of attempts).
//!
//! With `per call`, the bound counts the loop's iterations over one call of the
//! function that holds it, summed over the loop's entries in that call: the
//! inner loop of a triangular nest (`for l in 0..n { for k in 0..l {..} }` runs
//! its body `n(n−1)/2` times, not `n·n`). The function must not be inlined
//! into its callers (`#[inline(never)]`), or one "call" would be the caller's:
//! the analysis refuses the bound where it is.
//!
//! With `times per activation`, the annotation is not a loop's: the calls made
//! from its line (the `bl` instructions whose inlining chain holds the line) run
//! at most EXPR times over one activation, summed over every copy of the line
//! the compiler made: a recovery step the code caps per activation.
//!
//! With `, counted in NAME` after `per activation` or `times per activation`,
//! the annotation shares its bound with every other annotation counted in
//! `NAME` (all of them must give the same bound): the loop's iterations and the
//! line's calls, summed over all of them, run at most EXPR times over one
//! activation. One counter the code increments in several places (the QP's
//! iterations: its main loop's and the removals that retry an addition) is then
//! one constraint, not a cap per place.
//!
//! With `// wcet-bound in NAME: EXPR` (a loop's scopes only), the annotation holds
//! for the copy of the line inlined into the binary function `NAME` (the last
//! segment of its path; a task's handler, the interrupt RTIC runs it in, which
//! differs between the ECU's builds, by the task's name: `control`, `plan`,
//! `link`), and the line's plain annotation for every other copy: a
//! loop whose bound depends on its caller. `per call` then counts the calls of
//! `NAME`. A factor rebuilt row by row appends rows to a factor of `0, 1, ...`
//! rows, so the loops of one append, `n` iterations each, sum to `W(W − 1)/2`
//! over the rebuild. An annotation for a copy that no loop takes is an error.
//!
//! With `bytes`, the annotation is not a loop's: it bounds the size of the block
//! copies and fills (`memcpy`, `memset`, ...) called from its line, where the
//! binary does not set the size to a constant before the call. Every loop of
//! those functions takes at most one back edge per byte.
//!
//! With `same loop` (no expression), the annotation states that the binary loop
//! holding its line is part of the binary loop around it: one source loop the
//! compiler split into nested binary loops (a `continue` path that jumps past the
//! loop's head). Their back edges together take the enclosing loop's bound per
//! its entry, a flow fact the traces check like the others.
//!
//! A binary loop is matched by the source line of its back-edge branch, else of
//! the first instruction of its header, else of the other instructions of those
//! two blocks (each the innermost frame in the firmware's own sources, inlining
//! followed). A loop nested in another loop matched to the same annotation is
//! refused: it needs its own (a bound, or `same loop`). A loop whose every
//! instruction is a dependency's code (a library loop inlined into a firmware
//! line: a checksum's loop, a list walk inside a call) takes the
//! line's annotation only when no loop of the firmware's own code in the same
//! function took it (the annotation is then the library loop's: the checksum's
//! bytes); else it takes a dependency fact ([`crate::target::Target::dependency_facts`]) about its own
//! source line, or none.

use crate::WcetError;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// What an annotation bounds against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Scope {
    /// Iterations per entry of the loop.
    Entry,
    /// Iterations over one activation of the task.
    Activation,
    /// Iterations per preemption of the task's activation, summed over every such
    /// loop the task runs: a retry loop whose retry needs an interrupt between
    /// two reads (a load-exclusive/store-exclusive pair).
    Preemption,
    /// Iterations per preemption of the task's activation by the monotonic's
    /// tick (`SysTick`), summed like [`Scope::Preemption`]: a retry loop whose
    /// retry needs the tick counter to change between two reads, which no other
    /// interrupt does.
    Tick,
    /// Not a loop's: the most bytes a block copy or fill called from the line
    /// moves.
    Bytes,
    /// Not a loop's: the most times the code of the line (a call, inlined or
    /// not) runs per entry of the innermost loop around it.
    LoopEntry,
    /// Iterations per call of the function that holds the loop, over all the
    /// entries of the loop in that call (a triangular loop nest: the inner loop
    /// runs `0 + 1 + ... + (n − 1)` times per call). The function must not be
    /// inlined (`#[inline(never)]`): the analysis checks it.
    Call,
    /// Not a loop's: the most times the calls of the line run over one activation
    /// of the task, summed over every place the line's code was inlined (a
    /// recovery step with its own cap per activation).
    Runs,
    /// `same loop`: the binary loop holding the line is part of the source loop
    /// around it, which the compiler split into nested binary loops (a `continue`
    /// path that skips the loop's head): their back edges together take the
    /// enclosing loop's bound, per its entry.
    SameLoop,
}

/// One `// wcet-bound:` annotation.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Annotation {
    /// The file, relative to the workspace (`firmware/src/mpc.rs`).
    pub file: String,
    /// The 1-based line of the loop it annotates.
    pub line: u32,
    /// The expression as written.
    pub expression: String,
    /// Its value.
    pub bound: u64,
    /// Per entry or per activation.
    pub scope: Scope,
    /// `// wcet-bound in NAME:`: the annotation holds for the copy of the line
    /// inlined into the binary function `NAME` (the last segment of its path, a
    /// function that is not inlined) and the line's plain annotation for every
    /// other copy: a loop whose bound depends on its caller (the rows appended one
    /// by one when a factor is rebuilt, each a longer loop than the last).
    pub within: Option<String>,
    /// `, counted in NAME`: the counter whose one bound the annotation shares with
    /// every other annotation counted in `NAME` (scopes per activation only).
    pub counter: Option<String>,
}

/// Evaluates an annotation's expression.
pub fn evaluate(expr: &str, constants: &BTreeMap<&'static str, u64>) -> Result<u64, WcetError> {
    #[derive(Debug, Clone, PartialEq)]
    enum Tok {
        Num(u64),
        Op(char),
    }
    let mut toks = Vec::new();
    let chars: Vec<char> = expr.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() {
            let start = i;
            while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '_') {
                i += 1;
            }
            let s: String = chars[start..i].iter().filter(|&&c| c != '_').collect();
            toks.push(Tok::Num(
                s.parse()
                    .map_err(|e| WcetError::Annotation(format!("`{s}`: {e}")))?,
            ));
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_ascii_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            let name: String = chars[start..i].iter().collect();
            let v = constants.get(name.as_str()).ok_or_else(|| {
                WcetError::Annotation(format!(
                    "unknown constant `{name}` (known: {})",
                    constants.keys().copied().collect::<Vec<_>>().join(", ")
                ))
            })?;
            toks.push(Tok::Num(*v));
        } else if "+-*/()".contains(c) {
            toks.push(Tok::Op(c));
            i += 1;
        } else {
            return Err(WcetError::Annotation(format!(
                "unexpected `{c}` in `{expr}`"
            )));
        }
    }
    // Shunting-yard to reverse Polish notation, then evaluation.
    let prec = |c: char| if c == '+' || c == '-' { 1 } else { 2 };
    let mut out: Vec<Tok> = Vec::new();
    let mut ops: Vec<char> = Vec::new();
    for t in toks {
        match t {
            Tok::Num(_) => out.push(t),
            Tok::Op('(') => ops.push('('),
            Tok::Op(')') => loop {
                match ops.pop() {
                    Some('(') => break,
                    Some(o) => out.push(Tok::Op(o)),
                    None => {
                        return Err(WcetError::Annotation(format!("unbalanced `)` in `{expr}`")))
                    }
                }
            },
            Tok::Op(o) => {
                while let Some(&top) = ops.last() {
                    if top != '(' && prec(top) >= prec(o) {
                        out.push(Tok::Op(top));
                        ops.pop();
                    } else {
                        break;
                    }
                }
                ops.push(o);
            }
        }
    }
    while let Some(o) = ops.pop() {
        if o == '(' {
            return Err(WcetError::Annotation(format!("unbalanced `(` in `{expr}`")));
        }
        out.push(Tok::Op(o));
    }
    let mut stack: Vec<u64> = Vec::new();
    for t in out {
        match t {
            Tok::Num(v) => stack.push(v),
            Tok::Op(o) => {
                let (Some(b), Some(a)) = (stack.pop(), stack.pop()) else {
                    return Err(WcetError::Annotation(format!(
                        "malformed expression `{expr}`"
                    )));
                };
                stack.push(
                    match o {
                        '+' => a.checked_add(b),
                        '-' => a.checked_sub(b),
                        '*' => a.checked_mul(b),
                        _ => (b != 0).then(|| a.div_ceil(b)),
                    }
                    .ok_or_else(|| {
                        WcetError::Annotation(format!(
                            "`{expr}` overflows, goes negative or divides by 0"
                        ))
                    })?,
                );
            }
        }
    }
    match stack.as_slice() {
        [v] => Ok(*v),
        _ => Err(WcetError::Annotation(format!(
            "malformed expression `{expr}`"
        ))),
    }
}

/// The marker of an annotation comment.
pub const MARKER: &str = "// wcet-bound:";

/// The marker of an annotation for one caller's copy of a line: `// wcet-bound in
/// NAME: EXPR` ([`Annotation::within`]).
pub const WITHIN_MARKER: &str = "// wcet-bound in ";

/// Parses the annotations of one source file's text (`file` as it is reported).
pub fn parse_source(
    file: &str,
    text: &str,
    constants: &BTreeMap<&'static str, u64>,
) -> Result<Vec<Annotation>, WcetError> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (k, line) in lines.iter().enumerate() {
        let (pos, spec, within) = if let Some(pos) = line.find(MARKER) {
            (pos, line[pos + MARKER.len()..].trim(), None)
        } else if let Some(pos) = line.find(WITHIN_MARKER) {
            let rest = &line[pos + WITHIN_MARKER.len()..];
            let (name, spec) = rest.split_once(':').ok_or_else(|| {
                WcetError::Annotation(format!(
                    "{file}:{}: `{WITHIN_MARKER}NAME: EXPR` lacks its `:`",
                    k + 1
                ))
            })?;
            let name = name.trim();
            if name.is_empty() || !name.chars().all(|c| c.is_alphanumeric() || c == '_') {
                return Err(WcetError::Annotation(format!(
                    "{file}:{}: `{WITHIN_MARKER}{name}:` names no function (one identifier)",
                    k + 1
                )));
            }
            (pos, spec.trim(), Some(name.to_string()))
        } else {
            continue;
        };
        let (spec, counter) = match spec.rsplit_once(", counted in ") {
            Some((head, name)) => {
                let name = name.trim();
                if name.is_empty() || !name.chars().all(|c| c.is_alphanumeric() || c == '_') {
                    return Err(WcetError::Annotation(format!(
                        "{file}:{}: `counted in {name}` names no counter (one identifier)",
                        k + 1
                    )));
                }
                (head.trim(), Some(name.to_string()))
            }
            None => (spec, None),
        };
        let (expr, scope) = if spec == "same loop" {
            ("0", Scope::SameLoop)
        } else if let Some(e) = spec.strip_suffix("times per activation") {
            (e.trim(), Scope::Runs)
        } else if let Some(e) = spec.strip_suffix("per call") {
            (e.trim(), Scope::Call)
        } else if let Some(e) = spec.strip_suffix("per activation") {
            (e.trim(), Scope::Activation)
        } else if let Some(e) = spec.strip_suffix("per preemption") {
            (e.trim(), Scope::Preemption)
        } else if let Some(e) = spec.strip_suffix("per tick") {
            (e.trim(), Scope::Tick)
        } else if let Some(e) = spec.strip_suffix("per loop entry") {
            (e.trim(), Scope::LoopEntry)
        } else if let Some(e) = spec.strip_suffix("bytes") {
            (e.trim(), Scope::Bytes)
        } else {
            (spec, Scope::Entry)
        };
        let bound = evaluate(expr, constants)
            .map_err(|e| WcetError::Annotation(format!("{file}:{}: {e}", k + 1)))?;
        if within.is_some() && !matches!(scope, Scope::Entry | Scope::Call | Scope::Activation) {
            return Err(WcetError::Annotation(format!(
                "{file}:{}: `{WITHIN_MARKER}NAME:` bounds a loop (per entry, per call or per activation), not a call or a copy",
                k + 1
            )));
        }
        if counter.is_some() && !matches!(scope, Scope::Activation | Scope::Runs) {
            return Err(WcetError::Annotation(format!(
                "{file}:{}: `counted in NAME` shares a bound per activation: write it after `per activation` or `times per activation`",
                k + 1
            )));
        }
        let alone = line[..pos].trim().is_empty();
        let target = if alone {
            // The next line that is neither blank nor a comment.
            (k + 1..lines.len())
                .find(|&j| {
                    let t = lines[j].trim();
                    !t.is_empty() && !t.starts_with("//") && !t.starts_with("#[")
                })
                .ok_or_else(|| {
                    WcetError::Annotation(format!("{file}:{}: annotation before no code", k + 1))
                })?
        } else {
            k
        };
        out.push(Annotation {
            file: file.to_string(),
            line: target as u32 + 1,
            expression: expr.to_string(),
            bound,
            scope,
            within,
            counter,
        });
    }
    Ok(out)
}

/// Each counter's group, by name: the index of the first annotation counted in
/// it (every other annotation is a group of its own, its index). Fails when two
/// annotations of one counter give different bounds.
pub fn counter_groups(annotations: &[Annotation]) -> Result<BTreeMap<String, usize>, WcetError> {
    let mut first: BTreeMap<String, usize> = BTreeMap::new();
    for (k, a) in annotations.iter().enumerate() {
        let Some(name) = a.counter.as_deref() else {
            continue;
        };
        let head = &annotations[*first.entry(name.to_string()).or_insert(k)];
        if head.bound != a.bound {
            return Err(WcetError::Annotation(format!(
                "{}:{}: counted in `{name}` with the bound `{}` = {}, but {}:{} gives it `{}` = {}: one counter has one bound",
                a.file, a.line, a.expression, a.bound, head.file, head.line, head.expression, head.bound
            )));
        }
    }
    Ok(first)
}

/// One crate's source folder: where it is read, and the workspace-relative
/// folder its files are reported under (one of the target's
/// [`crate::target::Target::source_labels`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceDir {
    /// The folder read (e.g. `../qp/src`, or an edited copy).
    pub dir: PathBuf,
    /// The folder from the workspace root the files are reported under (`qp/src`).
    pub label: &'static str,
}

/// The annotations of every `.rs` file under each folder of `sources`, files
/// reported under its label (`firmware/src/...`, `qp/src/...`), with the target's
/// `constants` bound as given (all of them, or tighter for a task's light
/// activations, [`crate::target::LightActivations`]).
pub fn scan_sources_with(
    sources: &[SourceDir],
    constants: &BTreeMap<&'static str, u64>,
) -> Result<Vec<Annotation>, WcetError> {
    let mut out = Vec::new();
    for source in sources {
        let root = source.dir.as_path();
        let mut files: Vec<PathBuf> = Vec::new();
        let mut dirs = vec![root.to_path_buf()];
        while let Some(d) = dirs.pop() {
            let entries = std::fs::read_dir(&d)
                .map_err(|e| WcetError::Annotation(format!("{}: {e}", d.display())))?;
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    dirs.push(p);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    files.push(p);
                }
            }
        }
        files.sort();
        for p in files {
            let text = std::fs::read_to_string(&p)
                .map_err(|e| WcetError::Annotation(format!("{}: {e}", p.display())))?;
            let rel = p
                .strip_prefix(root)
                .map(|r| format!("{}/{}", source.label, r.display()))
                .unwrap_or_else(|_| p.display().to_string());
            out.extend(parse_source(&rel, &text, constants)?);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made target's constants.
    fn firmware_constants() -> BTreeMap<&'static str, u64> {
        BTreeMap::from([("HORIZON", 16), ("NU", 2), ("NV", 32), ("WS", 12)])
    }

    #[test]
    fn an_annotation_for_one_callers_copy() -> Result<(), WcetError> {
        let c = firmware_constants();
        let text = "fn f() {\n    // wcet-bound: WS\n    // wcet-bound in rebuild: WS * (WS - 1) / 2 per call\n    for l in 0..n {}\n}\n";
        let t = parse_source("qp/src/factor.rs", text, &c)?;
        assert_eq!(t.len(), 2);
        assert_eq!((t[0].line, t[0].within.as_deref()), (4, None));
        let ws = c["WS"];
        assert_eq!(
            (t[1].line, t[1].bound, t[1].scope, t[1].within.as_deref()),
            (4, ws * (ws - 1) / 2, Scope::Call, Some("rebuild"))
        );
        let bad = parse_source("f.rs", "// wcet-bound in a b: 3\nfor x in y {}\n", &c);
        assert!(bad.is_err_and(|e| e.to_string().contains("names no function")));
        let cap = parse_source(
            "f.rs",
            "// wcet-bound in g: 3 times per activation\nf();\n",
            &c,
        );
        assert!(cap.is_err_and(|e| e.to_string().contains("bounds a loop")));
        Ok(())
    }

    #[test]
    fn a_counter_shares_one_bound_per_activation() -> Result<(), WcetError> {
        let c = firmware_constants();
        let text = "loop { // wcet-bound: 30 per activation, counted in iters\n}\n\
                    // wcet-bound: 30 times per activation, counted in iters\nf();\n\
                    // wcet-bound: 30 times per activation\ng();\n";
        let a = parse_source("x.rs", text, &c)?;
        assert_eq!(
            a.iter()
                .map(|a| (a.line, a.bound, a.scope, a.counter.as_deref()))
                .collect::<Vec<_>>(),
            vec![
                (1, 30, Scope::Activation, Some("iters")),
                (4, 30, Scope::Runs, Some("iters")),
                (6, 30, Scope::Runs, None),
            ]
        );
        // Both counted in `iters` share the group of the first (index 0); the
        // third, counted in nothing, is in no counter's group.
        assert_eq!(
            counter_groups(&a)?,
            BTreeMap::from([("iters".to_string(), 0)])
        );
        // One counter, two bounds: refused, naming both lines.
        let two = parse_source(
            "x.rs",
            "loop { // wcet-bound: 30 per activation, counted in iters\n}\n\
             // wcet-bound: 31 times per activation, counted in iters\nf();\n",
            &c,
        )?;
        let e = counter_groups(&two)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("x.rs:4") && e.contains("x.rs:1"), "{e}");
        // A counter is per activation: not on a bound per entry, nor unnamed.
        let per_entry = parse_source("x.rs", "loop { // wcet-bound: 3, counted in i\n", &c);
        assert!(per_entry.is_err_and(|e| e.to_string().contains("per activation")));
        let unnamed = parse_source(
            "x.rs",
            "loop { // wcet-bound: 3 per activation, counted in a b\n",
            &c,
        );
        assert!(unnamed.is_err_and(|e| e.to_string().contains("names no counter")));
        Ok(())
    }

    #[test]
    fn expressions() {
        let c = firmware_constants();
        assert_eq!(evaluate("HORIZON", &c).ok(), Some(16));
        assert_eq!(evaluate("HORIZON * NU + 1", &c).ok(), Some(33));
        assert_eq!(evaluate("(HORIZON + 1) * 2", &c).ok(), Some(34));
        assert_eq!(evaluate("17 / 4", &c).ok(), Some(5));
        assert!(evaluate("HORIZONS", &c).is_err());
        assert!(evaluate("1 - 2", &c).is_err());
        assert!(evaluate("(1 + 2", &c).is_err());
    }

    #[test]
    fn comments_apply_to_the_loop_line() {
        let c = firmware_constants();
        let text = "fn f() {\n    // wcet-bound: HORIZON\n    for k in 0..HORIZON {\n        while x { // wcet-bound: 3 per activation\n        }\n    }\n}\n";
        let a = parse_source("firmware/src/x.rs", text, &c).unwrap_or_default();
        assert_eq!(a.len(), 2);
        assert_eq!((a[0].line, a[0].bound, a[0].scope), (3, 16, Scope::Entry));
        assert_eq!(
            (a[1].line, a[1].bound, a[1].scope),
            (4, 3, Scope::Activation)
        );
        assert!(parse_source("x.rs", "// wcet-bound: NOPE\nloop {}\n", &c).is_err());
        let t = parse_source("x.rs", "loop { // wcet-bound: 2 per tick\n", &c).unwrap_or_default();
        assert_eq!((t[0].bound, t[0].scope), (2, Scope::Tick));
        let r = parse_source("x.rs", "loop { // wcet-bound: 1 per preemption\n", &c)
            .unwrap_or_default();
        assert_eq!((r[0].bound, r[0].scope), (1, Scope::Preemption));
        let b = parse_source(
            "x.rs",
            "    // wcet-bound: NV * 4 bytes\n    tail.fill(0.0);\n",
            &c,
        )
        .unwrap_or_default();
        assert_eq!((b[0].line, b[0].bound, b[0].scope), (2, 128, Scope::Bytes));
        let t = parse_source(
            "x.rs",
            "for k in 0..l { // wcet-bound: WS * (WS - 1) / 2 per call\n    // wcet-bound: 2 times per activation\n    self.rebuild();\n",
            &c,
        )
        .unwrap_or_default();
        assert_eq!(
            (t[0].line, t[0].bound, t[0].scope),
            (1, c["WS"] * (c["WS"] - 1) / 2, Scope::Call)
        );
        assert_eq!((t[1].line, t[1].bound, t[1].scope), (3, 2, Scope::Runs));
    }
}
