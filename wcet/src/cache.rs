//! The ART accelerator's instruction cache, for the cycle bounds: which loops
//! fetch each of their flash lines once per entry instead of once per trip.
//!
//! RM0090 §3.5.2 (STM32F405): the instruction cache holds 64 lines of 128 bits;
//! every line read from flash on a miss is copied into it, and once it is full the
//! least recently used line is replaced. The ECU's `init` enables it (`FLASH_ACR`:
//! `ICEN`, `DCEN`, 5 wait states, prefetch off).
//!
//! Persistence: a loop whose blocks call nothing and touch at most 64 distinct
//! lines uses only those lines while it runs, so between two uses of one of them
//! at most 63 others are used and an LRU cache of 64 lines still holds it. Each of
//! its lines is then fetched from flash at most once per entry of the loop. The
//! bound charges the loop's lines once per entry ([`Region::lines`] ×
//! the line fetch cost) and its blocks without their fetch. A preemption may
//! evict the lines: the response-time analysis charges each preemption the
//! refill of the lines the preempting activation can evict, its evicting cache
//! blocks: the distinct flash lines of the code it can run, at most the whole
//! cache ([`evicting_lines`], [`PREEMPTION_REFILL_CYCLES`]). With LRU replacement
//! a preempted task's lines keep their order and age by at most that many places,
//! so at most that many of them are evicted and fetched again.

use super::cfg::Program;
use super::data_cache::DATA_CACHE_LINES;
use super::loops::Loop;
use std::collections::{BTreeSet, HashMap};

/// Lines of the instruction cache.
pub const CACHE_LINES: u64 = 64;

/// Cache-related preemption delay when nothing is known of the preempting
/// code: it may evict every line of the preempted task's instruction cache and
/// data cache ([`super::data_cache`]), which then fetches them again, 64 + 8
/// lines of 6 cycles (5 wait states and the access).
pub const PREEMPTION_REFILL_CYCLES: f64 = ((CACHE_LINES + DATA_CACHE_LINES as u64) * 6) as f64;

/// The data-cache lines ([`super::data_cache`]) an activation that can run the functions `reach` can
/// evict: the distinct lines they read, at most [`DATA_CACHE_LINES`] (all when
/// one reads a line not known statically).
pub fn evicting_data_lines(program: &Program, reach: &[usize]) -> u64 {
    let mut lines = BTreeSet::new();
    for &f in reach {
        match &program.functions[f].data_lines {
            None => return u64::from(DATA_CACHE_LINES),
            Some(l) => lines.extend(l.iter().copied()),
        }
    }
    (lines.len() as u64).min(u64::from(DATA_CACHE_LINES))
}

/// The evicting cache blocks of an activation: the distinct flash lines of the
/// code the functions `reach` can run, at most [`CACHE_LINES`]: the most lines of
/// another task's cache a preemption by it can evict.
pub fn evicting_lines(program: &Program, reach: &[usize]) -> u64 {
    let mut lines: BTreeSet<u64> = BTreeSet::new();
    for &f in reach {
        for b in &program.functions[f].blocks {
            if let Some((lo, hi)) = b.lines {
                lines.extend(lo..=hi);
            }
            if lines.len() as u64 >= CACHE_LINES {
                return CACHE_LINES;
            }
        }
    }
    lines.len() as u64
}

/// A loop whose lines stay in the cache while it runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Region {
    /// Function index.
    pub function: usize,
    /// Loop index in that function's loops.
    pub loop_index: usize,
    /// The loop's header block (every entry goes to it).
    pub header: usize,
    /// Distinct flash lines its blocks touch (at most [`CACHE_LINES`]).
    pub lines: u64,
    /// Its blocks.
    pub blocks: BTreeSet<usize>,
}

/// The persistent loops of a program: in each function, the outermost loops
/// that call nothing and touch at most [`CACHE_LINES`] lines.
#[derive(Debug, Clone, Default)]
pub struct Persistence {
    regions: Vec<Region>,
    by_block: HashMap<(usize, usize), usize>,
    line_cycles: u64,
}

impl Persistence {
    /// The persistent loops of every function of `program`.
    pub fn new(program: &Program, loops: &[Vec<Loop>]) -> Self {
        let mut out = Persistence {
            line_cycles: program.line_fetch_cycles,
            ..Persistence::default()
        };
        for (f, ls) in loops.iter().enumerate() {
            let Some(func) = program.functions.get(f) else {
                continue;
            };
            let lines_of = |l: &Loop| -> Option<u64> {
                let mut lines = BTreeSet::new();
                for &b in &l.blocks {
                    let block = func.blocks.get(b)?;
                    if !block.calls.is_empty() {
                        return None;
                    }
                    let (lo, hi) = block.lines?;
                    lines.extend(lo..=hi);
                }
                let n = lines.len() as u64;
                (!l.irreducible && n <= CACHE_LINES).then_some(n)
            };
            let fits: Vec<Option<u64>> = ls.iter().map(lines_of).collect();
            for (k, l) in ls.iter().enumerate() {
                let outermost = l
                    .parent
                    .is_none_or(|p| fits.get(p).copied().flatten().is_none());
                let (Some(lines), true) = (fits[k], outermost) else {
                    continue;
                };
                let r = out.regions.len();
                for &b in &l.blocks {
                    out.by_block.insert((f, b), r);
                }
                out.regions.push(Region {
                    function: f,
                    loop_index: k,
                    header: l.header,
                    lines,
                    blocks: l.blocks.iter().copied().collect(),
                });
            }
        }
        out
    }

    /// The persistent loops.
    pub fn regions(&self) -> &[Region] {
        &self.regions
    }

    /// The region block `b` of function `f` is in.
    pub fn region_of(&self, f: usize, b: usize) -> Option<&Region> {
        self.by_block.get(&(f, b)).map(|&r| &self.regions[r])
    }

    /// Cycles a region's entry costs: each of its lines fetched once.
    pub fn entry_cycles(&self, region: &Region) -> u64 {
        region.lines * self.line_cycles
    }

    /// Worst-case cycles of one execution of block `b` of `f`: without its fetch
    /// inside a persistent loop (charged per entry of the loop instead).
    pub fn block_cycles(&self, program: &Program, f: usize, b: usize) -> u64 {
        let block = &program.functions[f].blocks[b];
        if self.by_block.contains_key(&(f, b)) {
            block.cycles - block.fetch_cycles
        } else {
            block.cycles
        }
    }

    /// Cycles the edge `a → b` of `f` saves on the two blocks' costs:
    ///
    /// * on the fall-through, its saving ([`Block::fall_through_saving`]: the
    ///   untaken branch's refill and the line already read);
    /// * on a taken branch whose target starts in the line the branch is in, that
    ///   line: the branch's own line was just read, so the instruction cache holds
    ///   it (every line read on a miss is copied into it, RM0090 §3.5.2; at most
    ///   the next line, fetched ahead by the core, was read since, and the cache
    ///   keeps 64 lines, least recently used replaced), and the target is served
    ///   without a flash access. A preemption in between is charged a refill of
    ///   the whole cache ([`PREEMPTION_REFILL_CYCLES`]).
    ///
    /// Between two blocks of one persistent loop no line is saved: their fetch is
    /// charged per entry of the loop, not per block.
    ///
    /// [`Block::fall_through_saving`]: super::cfg::Block::fall_through_saving
    pub fn edge_saving(&self, program: &Program, f: usize, a: usize, b: usize) -> u64 {
        let func = &program.functions[f];
        let block = &func.blocks[a];
        let same_loop = matches!(
            (self.by_block.get(&(f, a)), self.by_block.get(&(f, b))),
            (Some(x), Some(y)) if x == y
        );
        let line_saving = |line: u64| if same_loop { 0 } else { line };
        if block.fall_through == Some(b) {
            let (refill, line) = block.fall_through_saving;
            return refill + line_saving(line);
        }
        match (block.lines, func.blocks.get(b).and_then(|t| t.lines)) {
            (Some((_, branch_line)), Some((target_line, _))) if branch_line == target_line => {
                line_saving(self.line_cycles)
            }
            _ => 0,
        }
    }

    /// The region entered on the step `prev → b` of `f`: `b` heads a region and
    /// `prev` (none at the function's entry) is outside it.
    pub fn entered(&self, f: usize, prev: Option<usize>, b: usize) -> Option<&Region> {
        let r = self.region_of(f, b)?;
        (r.header == b && prev.is_none_or(|a| !r.blocks.contains(&a))).then_some(r)
    }
}
