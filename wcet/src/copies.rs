//! Block copies and fills (`memcpy`, `memset` and the AEABI helpers): which
//! functions they are, and at each call site how many bytes it moves, a constant
//! the binary sets before the call or the `bytes` annotation at its source line.
//! [`super::ipet`] bounds their loops by those bytes.

use super::cfg::{Exit, Program};
use super::source_lines::SourceLines;
use super::target::Target;
use super::{annotations, bounds, ipet, loops};
use std::collections::BTreeMap;

/// The register holding the size argument of a block copy or fill, by the
/// function's name; `None` for other functions. The AEABI `memset`/`memclr`
/// helpers take `(dest, n, c)`; `memcpy`, `memmove`, `memset` and the other AEABI
/// helpers take the size third.
pub fn copy_size_register(name: &str) -> Option<&'static str> {
    let base = name.rsplit("::").next().unwrap_or(name);
    if base.starts_with("__aeabi_memset") || base.starts_with("__aeabi_memclr") {
        Some("r1")
    } else if base.starts_with("__aeabi_memcpy")
        || base.starts_with("__aeabi_memmove")
        || matches!(base, "memcpy" | "memmove" | "memset")
    {
        Some("r2")
    } else {
        None
    }
}

/// The block copies and fills of the program and their call sites with their
/// sizes: a constant move into the size register before the call, else the
/// `bytes` annotation at the call's source line.
pub(super) fn copy_sizes(
    build: &Target,
    program: &Program,
    ctx: &SourceLines,
    annotations: &[annotations::Annotation],
    counter_groups: &BTreeMap<String, usize>,
) -> ipet::CopySizes {
    let family: std::collections::BTreeSet<usize> = program
        .functions
        .iter()
        .enumerate()
        .filter(|(_, f)| copy_size_register(&f.demangled).is_some())
        .map(|(k, _)| k)
        .collect();
    let by_address: BTreeMap<u32, usize> = program
        .functions
        .iter()
        .enumerate()
        .map(|(k, f)| (f.address, k))
        .collect();
    let bytes_at: BTreeMap<(String, u32), u64> = annotations
        .iter()
        .filter(|a| a.scope == annotations::Scope::Bytes)
        .map(|a| ((a.file.clone(), a.line), a.bound))
        .collect();
    // The tasks' completing activations: the sites elsewhere (init, the stop and
    // fault paths) do not matter.
    let roots: Vec<usize> = build
        .tasks()
        .iter()
        .filter_map(|(_, sym)| program.find(sym).first().copied())
        .collect();
    let reach = program.completing_reachable(&roots);
    let mut sites = Vec::new();
    for &k in &reach {
        let func = &program.functions[k];
        if family.contains(&k) {
            continue;
        }
        let preds = func.predecessors();
        let live = func.completing();
        for (b, block) in func.blocks.iter().enumerate() {
            if !live[b] {
                continue;
            }
            for i in block.first..block.end {
                let ins = &func.instructions[i];
                let Some(&callee) = ins.target.and_then(|t| by_address.get(&t)) else {
                    continue;
                };
                let tail = i + 1 == block.end && block.exit == Exit::TailCall(callee);
                if !family.contains(&callee) || !(ins.base().starts_with("bl") || tail) {
                    continue;
                }
                let Some(reg) = copy_size_register(&program.functions[callee].demangled) else {
                    continue;
                };
                let (file, line) = ctx.location(ins.address);
                let key = (ctx.short_path(&file), line);
                let bytes = bounds::constant_before(func, &preds, b, i, reg, 4)
                    .or_else(|| bytes_at.get(&key).copied());
                sites.push(ipet::CopySite {
                    function: k,
                    callee,
                    block: b,
                    bytes,
                    at: format!(
                        "`{}` {:#x} ({}:{})",
                        func.demangled, ins.address, key.0, key.1
                    ),
                });
            }
        }
    }
    // `per loop entry` and `times per activation` annotations: the blocks whose
    // calls come from the line (in any frame of their inlining chain), grouped by
    // the innermost loop around them (per loop entry) or by annotation (per
    // activation, every copy of the line together).
    let capped: BTreeMap<(String, u32), (u64, Option<usize>, usize)> = annotations
        .iter()
        .enumerate()
        .filter(|(_, a)| a.within.is_none())
        .filter_map(|(k, a)| match a.scope {
            annotations::Scope::LoopEntry => Some(((a.file.clone(), a.line), (a.bound, None, k))),
            annotations::Scope::Runs => Some(((a.file.clone(), a.line), (a.bound, Some(k), k))),
            _ => None,
        })
        .collect();
    let mut caps = Vec::new();
    if !capped.is_empty() {
        for &k in &reach {
            let func = &program.functions[k];
            let ls = loops::natural_loops(func).unwrap_or_default();
            // (innermost loop, bound, activation group, annotation) → blocks.
            type CapKey = (Option<usize>, u64, Option<usize>, usize);
            let mut groups: BTreeMap<CapKey, Vec<usize>> = BTreeMap::new();
            for (b, block) in func.blocks.iter().enumerate() {
                let hit = func.instructions[block.first..block.end]
                    .iter()
                    .filter(|i| i.base().starts_with("bl"))
                    .flat_map(|i| ctx.frames(i.address))
                    .find_map(|(file, line)| capped.get(&(ctx.short_path(&file), line)).copied());
                let Some((bound, group, annotation)) = hit else {
                    continue;
                };
                // The innermost loop holding the block: the smallest.
                let inner = match group {
                    Some(_) => None,
                    None => ls
                        .iter()
                        .enumerate()
                        .filter(|(_, l)| l.blocks.binary_search(&b).is_ok())
                        .min_by_key(|(_, l)| l.blocks.len())
                        .map(|(x, _)| x),
                };
                groups
                    .entry((inner, bound, group, annotation))
                    .or_default()
                    .push(b);
            }
            for ((loop_index, bound, activation_group, annotation), blocks) in groups {
                caps.push(ipet::BlockCap {
                    function: k,
                    blocks,
                    loop_index,
                    bound,
                    activation_group,
                    annotation: Some(annotation),
                });
            }
        }
    }
    ipet::CopySizes {
        family,
        sites,
        caps,
        counters: annotations
            .iter()
            .enumerate()
            .filter_map(|(k, a)| Some((k, *counter_groups.get(a.counter.as_deref()?)?)))
            .filter(|&(k, g)| k != g)
            .collect(),
    }
}
