//! Loop bounds recognised from the binary: counted loops whose trip count is a
//! constant of the code.
//!
//! A loop is recognised when it has one back edge, taken by a conditional branch
//! at the end of its latch block, governed by the flags of a counter register `r`
//! that the loop writes exactly once per iteration, in a block that dominates the
//! latch, by a constant step (`adds r, #k`, `sub.w r, r, #k`, a post- or
//! pre-indexed load or store through `r`, `vldmia r!, {..}`), and compared with a
//! constant: the flags of the update itself (`subs r, #k; bne`), `cmp r, #N`, or
//! `cmp r, q` with `q` not written in the loop and set before it to a constant or
//! to `r`'s initial value plus a constant (`add.w q, r, #64`: an end pointer). The
//! initial value of `r` (or its distance to the limit) is read from the loop's
//! only entry, walking back at most a few blocks. Anything else is left to an
//! annotation in the source (see [`super::annotations`]).
//!
//! The bound is on back edges per entry of the loop: the test is at the bottom
//! (LLVM rotates loops), so a loop whose body runs `n` times takes its back edge
//! `n − 1` times.

use super::cfg::{Function, Instruction};
use super::loops::{immediate_dominators, Loop};

/// Register names as the disassembler prints them.
fn is_register(s: &str) -> bool {
    matches!(s, "sb" | "sl" | "fp" | "ip" | "lr")
        || s.strip_prefix('r')
            .is_some_and(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()))
}

fn imm(s: &str) -> Option<i64> {
    let s = s.trim().strip_prefix('#')?;
    let (neg, s) = match s.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, s),
    };
    let v = match s.strip_prefix("0x") {
        Some(h) => i64::from_str_radix(h, 16).ok()?,
        None => s.parse().ok()?,
    };
    Some(if neg { -v } else { v })
}

fn operands(i: &Instruction) -> Vec<String> {
    i.operands
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// Registers of a `{r4, r5-r7}` list.
fn list_registers(ops: &str) -> Vec<String> {
    let (Some(a), Some(b)) = (ops.find('{'), ops.rfind('}')) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for item in ops[a + 1..b].split(',').map(str::trim) {
        match item.split_once('-') {
            Some((x, y)) => {
                let n = |r: &str| r.strip_prefix('r').and_then(|v| v.parse::<u32>().ok());
                if let (Some(p), Some(q)) = (n(x), n(y)) {
                    out.extend((p..=q).map(|k| format!("r{k}")));
                } else {
                    out.push(x.to_string());
                    out.push(y.to_string());
                }
            }
            None => out.push(item.to_string()),
        }
    }
    out
}

/// Whether `i` may write core register `r`.
fn writes(i: &Instruction, r: &str) -> bool {
    let base = i.base();
    let ops = operands(i);
    let first = ops.first().map(String::as_str).unwrap_or("");
    if base.starts_with("bl") {
        // A call clobbers the argument and scratch registers.
        return matches!(r, "r0" | "r1" | "r2" | "r3" | "ip" | "r12" | "lr");
    }
    let writeback =
        i.operands.contains(&format!("[{r}]")) && ops.len() > 2 && !i.operands.ends_with(']')
            || i.operands.contains(&format!("[{r},")) && i.operands.ends_with("]!")
            || ops.first().is_some_and(|o| o == &format!("{r}!"));
    if writeback {
        return true;
    }
    if base.starts_with("pop") || base.starts_with("ldm") {
        return list_registers(&i.operands).iter().any(|x| x == r);
    }
    let no_dest = base.starts_with("str")
        || base.starts_with("cmp")
        || base.starts_with("cmn")
        || base.starts_with("tst")
        || base.starts_with("teq")
        || base.starts_with("push")
        || base.starts_with("stm")
        || base.starts_with("vst")
        || base.starts_with("vpush")
        || base.starts_with("vcmp")
        || base.starts_with("it")
        || base == "b"
        || base.starts_with("cb")
        || (base.len() == 3
            && base.starts_with('b')
            && !base.starts_with("bl")
            && base != "bic"
            && base != "bfi"
            && base != "bfc");
    if no_dest {
        return false;
    }
    if first == r {
        return true;
    }
    // Second destination: ldrd, umull/smull/umlal/smlal, vmov rA, rB, dN.
    let two = base.starts_with("ldrd")
        || base.starts_with("umull")
        || base.starts_with("smull")
        || base.starts_with("umlal")
        || base.starts_with("smlal")
        || (base.starts_with("vmov")
            && ops.len() == 3
            && ops.iter().take(2).all(|o| is_register(o)));
    two && ops.get(1).is_some_and(|o| o == r)
}

/// The constant step by which `i` changes `r`, if it is a recognised update.
fn step(i: &Instruction, r: &str) -> Option<i64> {
    let base = i.base();
    let ops = operands(i);
    let sign = if base.starts_with("add") {
        1
    } else if base.starts_with("sub") {
        -1
    } else {
        0
    };
    if sign != 0 && ops.first().is_some_and(|o| o == r) {
        return match ops.as_slice() {
            [_, k] => imm(k).map(|k| sign * k),
            [_, s, k] if s == r => imm(k).map(|k| sign * k),
            _ => None,
        };
    }
    // Post-indexed `[r], #k` and pre-indexed `[r, #k]!`.
    let post = format!("[{r}]");
    if let Some(pos) = i.operands.find(&post) {
        let rest = &i.operands[pos + post.len()..];
        return rest.trim().strip_prefix(',').and_then(imm);
    }
    let pre = format!("[{r}, ");
    if i.operands.ends_with("]!") {
        if let Some(pos) = i.operands.find(&pre) {
            let inner = i.operands[pos + pre.len()..].trim_end_matches("]!");
            return imm(inner);
        }
    }
    // `vldmia r!, {s0-s3}`, `ldm r!, {..}`: 4 bytes a register (8 a d-register).
    if ops.first().is_some_and(|o| o == &format!("{r}!"))
        && (base.ends_with("ia") || base == "ldm" || base == "stm")
    {
        let regs = list_registers(&i.operands);
        let bytes: i64 = regs
            .iter()
            .map(|x| if x.starts_with('d') { 8 } else { 4 })
            .sum();
        return Some(bytes);
    }
    None
}

/// Whether the instruction sets the flags (`cmp`, `adds`, ...), for the search of
/// the compare that governs the latch.
fn sets_flags(i: &Instruction) -> bool {
    let b = i.base();
    if b.starts_with("cmp") || b.starts_with("cmn") || b.starts_with("tst") || b.starts_with("teq")
    {
        return true;
    }
    if b.starts_with("vmrs") {
        return true;
    }
    // `adds`, `subs`, `movs`, `lsls`, `ands`, ... (in an IT block the `s` is dropped
    // by the assembler syntax, so this errs on the side of "sets flags").
    b.len() > 3
        && b.ends_with('s')
        && !matches!(
            b,
            "vabs" | "vcvts" | "bls" | "bhs" | "blos" | "vnegs" | "vmuls" | "pls"
        )
        || matches!(
            b,
            "movs"
                | "adds"
                | "subs"
                | "ands"
                | "orrs"
                | "eors"
                | "lsls"
                | "lsrs"
                | "asrs"
                | "negs"
                | "muls"
                | "rsbs"
                | "bics"
                | "mvns"
        )
}

/// The condition of a conditional branch `bne`, `blo.w`.
fn condition(i: &Instruction) -> Option<&str> {
    let b = i.base();
    let c = b.strip_prefix('b')?;
    (c.len() == 2).then_some(c)
}

/// The value written by a constant move (`movs r, #c`, `mov.w r, #c`, `movw r, #c`).
fn constant_move(i: &Instruction, r: &str) -> Option<i64> {
    let b = i.base();
    let ops = operands(i);
    (matches!(b, "mov" | "movs" | "movw") && ops.first().is_some_and(|o| o == r))
        .then(|| ops.get(1).and_then(|o| imm(o)))
        .flatten()
}

/// Walks back from the end of block `b` (and up to `depth` unique predecessors)
/// to the last instruction that writes `r`; returns it.
fn last_write<'f>(
    f: &'f Function,
    preds: &[Vec<usize>],
    mut b: usize,
    r: &str,
    mut depth: usize,
) -> Option<&'f Instruction> {
    loop {
        let block = f.blocks.get(b)?;
        for i in f.instructions[block.first..block.end].iter().rev() {
            if writes(i, r) {
                return Some(i);
            }
        }
        depth = depth.checked_sub(1)?;
        match preds.get(b)?.as_slice() {
            [p] => b = *p,
            _ => return None,
        }
    }
}

/// The constant in register `r` when the instruction at index `at` of block `b`
/// runs: the last write before it (in the block, then up to `depth` unique
/// predecessors) is a constant move. For the sizes passed to block copies.
pub fn constant_before(
    f: &Function,
    preds: &[Vec<usize>],
    b: usize,
    at: usize,
    r: &str,
    depth: usize,
) -> Option<u64> {
    let block = f.blocks.get(b)?;
    let before = f.instructions.get(block.first..at.min(block.end))?;
    let write = match before.iter().rev().find(|i| writes(i, r)) {
        Some(i) => i,
        None => {
            let p = match preds.get(b)?.as_slice() {
                [p] => *p,
                _ => return None,
            };
            last_write(f, preds, p, r, depth)?
        }
    };
    constant_move(write, r).and_then(|v| u64::try_from(v).ok())
}

/// Trip count from the counter's start distance to the limit `d = N − c`, its step
/// `k` and the condition under which the loop goes on (after the update).
fn trips(d: i64, k: i64, cond: &str) -> Option<i64> {
    if k == 0 {
        return None;
    }
    // Normalise to a counter rising by k > 0 towards d > 0.
    let (d, k, cond) = if k < 0 {
        let flipped = match cond {
            "hi" => "lo",
            "gt" => "lt",
            "hs" | "cs" => "ls",
            "ge" => "le",
            "ne" => "ne",
            _ => return None,
        };
        (-d, -k, flipped)
    } else {
        (d, k, cond)
    };
    match cond {
        "ne" => (d > 0 && d % k == 0).then_some(d / k),
        "lo" | "cc" | "lt" => Some(if d <= 0 { 1 } else { (d + k - 1) / k }),
        "ls" | "le" => Some(if d < 0 { 1 } else { d / k + 1 }),
        _ => None,
    }
}

/// Reverses a condition for swapped compare operands (`cmp q, r`).
fn swap(cond: &str) -> Option<&'static str> {
    Some(match cond {
        "ne" => "ne",
        "eq" => "eq",
        "lo" | "cc" => "hi",
        "hi" => "lo",
        "ls" => "hs",
        "hs" | "cs" => "ls",
        "lt" => "gt",
        "gt" => "lt",
        "le" => "ge",
        "ge" => "le",
        _ => return None,
    })
}

/// The constant bound on back edges per entry of `l`, if it is a counted loop of a
/// recognised shape.
pub fn constant_bound(f: &Function, l: &Loop) -> Option<u64> {
    let [(latch, header)] = l.back_edges.as_slice() else {
        return None;
    };
    let [(pre, _)] = l.entry_edges.as_slice() else {
        return None;
    };
    if *pre == usize::MAX {
        return None;
    }
    let lb = f.blocks.get(*latch)?;
    let branch = f.instructions.get(lb.end.checked_sub(1)?)?;
    if branch.target != Some(f.blocks.get(*header)?.start) {
        return None;
    }
    let cond = condition(branch)?;
    // The flag-setting instruction governing the branch, in the latch.
    let mut flagger: Option<&Instruction> = None;
    for i in f.instructions[lb.first..lb.end.checked_sub(1)?]
        .iter()
        .rev()
    {
        if sets_flags(i) {
            flagger = Some(i);
            break;
        }
        if i.base().starts_with("it") {
            return None;
        }
    }
    let flagger = flagger?;
    let fops = operands(flagger);
    // Candidate counters: the flag setter's first operand (cmp r, .. / subs r, ..)
    // or, for `cmp q, r`, its second.
    let is_cmp = flagger.base().starts_with("cmp");
    let mut candidates: Vec<(String, bool)> = Vec::new();
    if let Some(a) = fops.first().filter(|a| is_register(a)) {
        candidates.push((a.clone(), false));
    }
    if is_cmp {
        if let Some(b) = fops.get(1).filter(|b| is_register(b)) {
            candidates.push((b.clone(), true));
        }
    }
    let idom = immediate_dominators(f);
    let dominates = |a: usize, mut b: usize| loop {
        if a == b {
            return true;
        }
        match idom.get(b).copied().flatten() {
            Some(p) => b = p,
            None => return false,
        }
    };
    let preds = f.predecessors();
    for (r, swapped) in candidates {
        // Exactly one write of r in the loop, a constant step, in a block
        // dominating the latch; and, when the flags come from a compare, before it.
        let mut writes_found: Vec<(usize, usize)> = Vec::new();
        for &b in &l.blocks {
            let blk = &f.blocks[b];
            for x in blk.first..blk.end {
                if writes(&f.instructions[x], &r) {
                    writes_found.push((b, x));
                }
            }
        }
        let [(wb, wx)] = writes_found.as_slice() else {
            continue;
        };
        if !dominates(*wb, *latch) {
            continue;
        }
        let Some(k) = step(&f.instructions[*wx], &r) else {
            continue;
        };
        let flag_x = (lb.first..lb.end).find(|&x| std::ptr::eq(&f.instructions[x], flagger))?;
        if *wb == *latch && *wx > flag_x {
            continue;
        }
        let cond_here = if swapped { swap(cond)? } else { cond };
        // Distance from the initial value to the limit.
        let d = if is_cmp {
            let other = if swapped { fops.first() } else { fops.get(1) }?;
            if let Some(n) = imm(other) {
                let init = last_write(f, &preds, *pre, &r, 3)?;
                n - constant_move(init, &r)?
            } else if is_register(other) {
                // q not written in the loop, set before it.
                if l.blocks.iter().any(|&b| {
                    let blk = &f.blocks[b];
                    f.instructions[blk.first..blk.end]
                        .iter()
                        .any(|i| writes(i, other))
                }) {
                    continue;
                }
                let def = last_write(f, &preds, *pre, other, 3)?;
                if let Some(n) = constant_move(def, other) {
                    let init = last_write(f, &preds, *pre, &r, 3)?;
                    n - constant_move(init, &r)?
                } else {
                    // q = r + d, with r not written after q's definition.
                    let dops = operands(def);
                    let b = def.base();
                    if !(b.starts_with("add") && dops.len() == 3 && dops[1] == r) {
                        continue;
                    }
                    let d = imm(&dops[2])?;
                    let init = last_write(f, &preds, *pre, &r, 3)?;
                    if !std::ptr::eq(init, def) && init.address > def.address {
                        continue;
                    }
                    d
                }
            } else {
                continue;
            }
        } else {
            // Flags from the update itself (`subs r, #k`): compared with 0.
            if !std::ptr::eq(flagger, &f.instructions[*wx]) {
                continue;
            }
            let init = last_write(f, &preds, *pre, &r, 3)?;
            let c = constant_move(init, &r)?;
            let d = -c;
            match cond_here {
                "ne" | "hi" | "gt" => {}
                _ => continue,
            }
            d
        };
        let n = trips(
            d,
            k,
            if !is_cmp && cond_here == "gt" {
                "hi"
            } else {
                cond_here
            },
        )?;
        return Some(n.saturating_sub(1).max(0) as u64);
    }
    None
}

/// Why a loop is not recognised as counted (for the report and for annotating it).
pub fn why_not(f: &Function, l: &Loop) -> String {
    if l.back_edges.len() != 1 {
        return format!("{} back edges", l.back_edges.len());
    }
    if l.entry_edges.len() != 1 {
        return format!("{} entries", l.entry_edges.len());
    }
    let (latch, header) = l.back_edges[0];
    let lb = &f.blocks[latch];
    let Some(branch) = lb.end.checked_sub(1).and_then(|x| f.instructions.get(x)) else {
        return "empty latch".into();
    };
    if branch.target != Some(f.blocks[header].start) || condition(branch).is_none() {
        return format!("latch ends in `{} {}`", branch.mnemonic, branch.operands);
    }
    let flagger = f.instructions[lb.first..lb.end - 1]
        .iter()
        .rev()
        .find(|i| sets_flags(i));
    match flagger {
        None => "no compare in the latch".into(),
        Some(i) => format!("counter of `{} {}` not recognised", i.mnemonic, i.operands),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trip_counts() {
        assert_eq!(trips(16, 1, "ne"), Some(16));
        assert_eq!(trips(16, 4, "lo"), Some(4));
        assert_eq!(trips(17, 4, "lo"), Some(5));
        assert_eq!(trips(17, 4, "ne"), None);
        assert_eq!(trips(-16, -1, "ne"), Some(16));
        assert_eq!(trips(-8, -2, "hi"), Some(4));
        assert_eq!(trips(15, 1, "ls"), Some(16));
    }

    #[test]
    fn writes_and_steps() {
        let i = |m: &str, o: &str| Instruction {
            address: 0,
            bytes: 2,
            mnemonic: m.into(),
            operands: o.into(),
            target: None,
        };
        assert!(writes(&i("adds", "r0, #0x1"), "r0"));
        assert!(!writes(&i("cmp", "r0, #0x10"), "r0"));
        assert!(writes(&i("ldr", "r2, [r0], #4"), "r0"));
        assert!(writes(&i("ldrd", "r1, r3, [r0]"), "r3"));
        assert!(writes(&i("bl", "0x8000000"), "r2"));
        assert!(!writes(&i("bl", "0x8000000"), "r4"));
        assert!(writes(&i("pop", "{r4, r5-r7, pc}"), "r6"));
        assert_eq!(step(&i("adds", "r0, #0x1"), "r0"), Some(1));
        assert_eq!(step(&i("sub.w", "r8, r8, #0x4"), "r8"), Some(-4));
        assert_eq!(step(&i("ldr", "r2, [r0], #4"), "r0"), Some(4));
        assert_eq!(step(&i("vldmia", "r1!, {s0, s1}"), "r1"), Some(8));
    }
}
