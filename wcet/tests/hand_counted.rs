//! The static WCET analysis on small hand-written disassemblies: graphs, loops,
//! constant loop bounds and the IPET bound, each checked against a count done by
//! hand.
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use wcet::cfg::{self, IndirectTargets, MemoryModel, Program};
use wcet::flash_data::FlashData;
use wcet::ipet::{self, Cost, IpetError, LoopFact, Per};
use wcet::{bounds, demangle, loops, WcetError};

/// The memory model the hand counts assume: 5 flash wait states, 16-byte
/// lines, flash at 0x0800_0000 (a Cortex-M4 behind an STM32F4's flash).
const MODEL: MemoryModel = MemoryModel {
    flash_wait_states: 5,
    flash_line_bytes: 16,
    flash: (0x0800_0000, 0x0810_0000),
    flash_data: FlashData::Anywhere(Vec::new()),
    accelerator_setup: "the hand-made program's set-up",
};

/// `root` runs a loop of 16 iterations (r4 from 16 down to 0) calling `leaf`.
const COUNTED: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: 2410         \tmovs\tr4, #0x10
 8000004: f000 f806    \tbl\t0x8000014 <leaf> @ imm = #0xc
 8000008: 3c01         \tsubs\tr4, #0x1
 800000a: d1fb         \tbne\t0x8000004 <root+0x4> @ imm = #-0xa
 800000c: bd10         \tpop\t{r4, pc}

08000014 <leaf>:
 8000014: 4770         \tbx\tlr
";

/// `a` calls `b`, which calls `a`.
const RECURSIVE: &str = "
08000000 <a>:
 8000000: b580         \tpush\t{r7, lr}
 8000002: f000 f801    \tbl\t0x8000008 <b> @ imm = #0x2
 8000006: bd80         \tpop\t{r7, pc}

08000008 <b>:
 8000008: b580         \tpush\t{r7, lr}
 800000a: f7ff fff9    \tbl\t0x8000000 <a> @ imm = #-0xe
 800000e: bd80         \tpop\t{r7, pc}
";

fn program(text: &str) -> Program {
    let raw = cfg::parse_disassembly(text);
    cfg::build_program(&raw, &IndirectTargets::default(), &MODEL, demangle).unwrap()
}

/// The index, in `ls[function]`, of the loop headed at `addr`.
fn loop_at(p: &Program, ls: &[Vec<loops::Loop>], function: usize, addr: u32) -> usize {
    let f = &p.functions[function];
    ls[function]
        .iter()
        .position(|l| f.blocks[l.header].start == addr)
        .unwrap()
}

fn all_loops(p: &Program) -> Vec<Vec<loops::Loop>> {
    p.functions
        .iter()
        .map(|f| loops::natural_loops(f).unwrap())
        .collect()
}

#[test]
fn blocks_loops_and_the_counted_bound() {
    let p = program(COUNTED);
    let root = p.find("root")[0];
    let f = &p.functions[root];
    let starts: Vec<u32> = f.blocks.iter().map(|b| b.start).collect();
    assert_eq!(starts, vec![0x8000000, 0x8000004, 0x800000c]);
    assert_eq!(f.blocks[1].calls, vec![p.find("leaf")[0]]);
    let ls = loops::natural_loops(f).unwrap();
    assert_eq!(ls.len(), 1);
    assert_eq!(ls[0].header, 1);
    assert_eq!(ls[0].back_edges, vec![(1, 1)]);
    // 16 iterations: the back edge is taken 15 times.
    assert_eq!(bounds::constant_bound(f, &ls[0]), Some(15));
}

#[test]
fn ipet_counts_the_worst_path_by_hand() {
    let p = program(COUNTED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let facts = [LoopFact {
        function: root,
        loop_index: 0,
        bound: 15,
        per: Per::Entry,
        group: None,
        iterations: false,
    }];
    let b = ipet::task_bound(
        &p,
        &ls,
        root,
        &facts,
        0,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    // 2 (prologue) + 16 × 3 (loop) + 1 (return) + 16 × 1 (leaf).
    assert_eq!(b.bound, 67);
    // What the bound is made of, block by block: the loop's body first (16 × 3),
    // then the leaf (16 × 1), the prologue and the return; together the bound.
    let shares: Vec<(f64, u64)> = b.by_block.iter().map(|s| (s.count, s.cost)).collect();
    assert_eq!(shares, [(16.0, 3), (16.0, 1), (1.0, 2), (1.0, 1)]);
    assert_eq!(b.by_block[0].function, "root");
    assert_eq!(b.by_block[1].function, "leaf");
    let total: f64 = b.by_block.iter().map(|s| s.count * s.cost as f64).sum();
    assert_eq!(total, 67.0);
    // A tighter fact gives a smaller bound: the loop fact is in the program.
    let tighter = [LoopFact {
        bound: 7,
        ..facts[0].clone()
    }];
    let t = ipet::task_bound(
        &p,
        &ls,
        root,
        &tighter,
        0,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    assert_eq!(t.bound, 2 + 8 * 3 + 1 + 8);
    // Per activation: the same here (one entry per activation).
    let act = [LoopFact {
        per: Per::Activation,
        ..facts[0].clone()
    }];
    let a = ipet::task_bound(
        &p,
        &ls,
        root,
        &act,
        0,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    assert_eq!(a.bound, 67);
    // Cycles are at least the instructions.
    let c = ipet::task_bound(&p, &ls, root, &facts, 0, &Default::default(), Cost::Cycles).unwrap();
    assert!(c.bound > 67);
}

/// `root` runs a rotated loop: its header (a branch inside the body) cannot leave
/// the loop; the test that ends it is in the latch.
const ROTATED: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: 2410         \tmovs\tr4, #0x10
 8000004: 2800         \tcmp\tr0, #0x0
 8000006: d000         \tbeq\t0x800000a <root+0xa> @ imm = #0x0
 8000008: 3101         \tadds\tr1, #0x1
 800000a: 3c01         \tsubs\tr4, #0x1
 800000c: d1fa         \tbne\t0x8000004 <root+0x4> @ imm = #-0xc
 800000e: bd10         \tpop\t{r4, pc}
";

#[test]
fn a_bound_on_iterations_counts_the_header_of_a_rotated_loop() {
    let p = program(ROTATED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let f = &p.functions[root];
    assert_eq!(ls[root].len(), 1);
    assert!(ipet::header_starts_iterations(f, &ls[root][0]));
    let on_back_edges = [LoopFact {
        function: root,
        loop_index: 0,
        bound: 16,
        per: Per::Entry,
        group: None,
        iterations: false,
    }];
    let bound = |facts: &[LoopFact]| {
        ipet::task_bound(
            &p,
            &ls,
            root,
            facts,
            0,
            &Default::default(),
            Cost::Instructions,
        )
        .unwrap()
        .bound
    };
    // 16 back edges: the header and the body run 17 times.
    // 2 (prologue) + 17 × 5 (cmp, beq, adds, subs, bne) + 1 (return).
    assert_eq!(bound(&on_back_edges), 2 + 17 * 5 + 1);
    // 16 iterations: the header runs 16 times, the back edge is taken 15 times.
    let on_iterations = [LoopFact {
        iterations: true,
        ..on_back_edges[0].clone()
    }];
    assert_eq!(bound(&on_iterations), 2 + 16 * 5 + 1);
    assert_eq!(
        ipet::back_edges_per_entry(&on_iterations[0], f, &ls[root][0], false),
        15
    );
    // Shared with a nested binary loop (one source loop), the rule is not used.
    assert_eq!(
        ipet::back_edges_per_entry(&on_iterations[0], f, &ls[root][0], true),
        16
    );
    // A top-tested loop (the header leaves the loop) keeps one more header run:
    // the counted loop's header is its only block, and it leaves.
    let c = program(COUNTED);
    let cl = all_loops(&c);
    let croot = c.find("root")[0];
    assert!(!ipet::header_starts_iterations(
        &c.functions[croot],
        &cl[croot][0]
    ));
}

/// `root` counts r4 from 16 down to 0 in a loop of one flash line that calls
/// nothing.
const CALL_FREE: &str = "
08000000 <root>:
 8000000: 2410         \tmovs\tr4, #0x10
 8000002: 3c01         \tsubs\tr4, #0x1
 8000004: d1fd         \tbne\t0x8000002 <root+0x2> @ imm = #-0x6
 8000006: 4770         \tbx\tlr
";

#[test]
fn cycles_by_hand_with_fall_throughs_calls_and_a_cached_loop() {
    // COUNTED: the loop calls `leaf`, so it is not kept in the cache.
    // Block 0: push 3 + movs 1 + its line 6 = 10; it falls into block 1 in the
    // same line (-6). Block 1, 16 times: bl 4 + subs 1 + bne 4 + its line 6 + the
    // line of bl's return address 6 = 21; its back edge, 15 times, branches into
    // the line the bne is in (-6: the cache holds the line just read). Its
    // fall-through to block 2: the bne not taken (-3) in the same line (-6).
    // Block 2: pop {r4, pc} 6 + its line 6. `leaf`, 16 times: bx lr 4 + its line 6.
    let p = program(COUNTED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let facts = [LoopFact {
        function: root,
        loop_index: 0,
        bound: 15,
        per: Per::Entry,
        group: None,
        iterations: false,
    }];
    let c = ipet::task_bound(&p, &ls, root, &facts, 0, &Default::default(), Cost::Cycles).unwrap();
    assert_eq!(c.bound, 10 - 6 + 16 * 21 - 15 * 6 - 9 + 12 + 16 * 10);
    assert!(wcet::cache::Persistence::new(&p, &ls).regions().is_empty());

    // CALL_FREE: the loop's one line is fetched once per entry.
    // Block 0: movs 1 + line 6, falling into block 1 in the same line (-6).
    // Block 1, 16 times: subs 1 + bne 4 (its line charged once on entry: 6).
    // Its fall-through to block 2: not taken (-3), same line (-6). Block 2: bx lr
    // 4 + line 6.
    let p = program(CALL_FREE);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let regions = wcet::cache::Persistence::new(&p, &ls);
    assert_eq!(regions.regions().len(), 1);
    assert_eq!(regions.regions()[0].lines, 1);
    let facts = [LoopFact {
        function: root,
        ..facts[0].clone()
    }];
    let c = ipet::task_bound(&p, &ls, root, &facts, 0, &Default::default(), Cost::Cycles).unwrap();
    assert_eq!(c.bound, 7 - 6 + 16 * 5 + 6 - 9 + 10);
}

#[test]
fn a_loop_without_a_bound_is_refused() {
    let p = program(COUNTED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    match ipet::task_bound(
        &p,
        &ls,
        root,
        &[],
        0,
        &Default::default(),
        Cost::Instructions,
    ) {
        Err(WcetError::Ipet(IpetError::Unbounded(l))) => assert_eq!(l.len(), 1, "{l:?}"),
        other => panic!("expected a refusal, got {other:?}"),
    }
}

#[test]
fn recursion_is_refused() {
    let p = program(RECURSIVE);
    let ls = all_loops(&p);
    let a = p.find("a")[0];
    assert_eq!(p.recursions(&[a]).len(), 1);
    assert!(matches!(
        ipet::task_bound(&p, &ls, a, &[], 0, &Default::default(), Cost::Instructions),
        Err(WcetError::Ipet(IpetError::Recursion(_)))
    ));
}

/// An atomic increment: load-exclusive, add, store-exclusive, retry on failure.
const EXCLUSIVE: &str = "
08000000 <root>:
 8000000: e850 1f00    \tldrex\tr1, [r0]
 8000004: 3101         \tadds\tr1, #0x1
 8000006: e840 1200    \tstrex\tr2, r1, [r0]
 800000a: 2a00         \tcmp\tr2, #0x0
 800000c: d1f8         \tbne\t0x8000000 <root> @ imm = #-0x10
 800000e: 4770         \tbx\tlr
";

#[test]
fn retry_loops_share_the_activations_retries() {
    let p = program(EXCLUSIVE);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    assert_eq!(ls[root].len(), 1);
    let facts = [LoopFact {
        function: root,
        loop_index: 0,
        bound: 1,
        per: Per::Preemption,
        group: None,
        iterations: false,
    }];
    // Without preemption the store succeeds at once: 5 + 1 instructions.
    let none = ipet::task_bound(
        &p,
        &ls,
        root,
        &facts,
        0,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    assert_eq!(none.bound, 6);
    // Three retries allowed: 4 × 5 + 1.
    let three = ipet::task_bound(
        &p,
        &ls,
        root,
        &facts,
        3,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    assert_eq!(three.bound, 21);
}

/// `root` copies 64 then 8 bytes with `memcpy`, a loop of one back edge per byte.
const COPIES: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: 2240         \tmovs\tr2, #0x40
 8000004: f000 f80c    \tbl\t0x8000020 <memcpy> @ imm = #0x18
 8000008: 2208         \tmovs\tr2, #0x8
 800000a: f000 f809    \tbl\t0x8000020 <memcpy> @ imm = #0x12
 800000e: bd10         \tpop\t{r4, pc}

08000020 <memcpy>:
 8000020: 3a01         \tsubs\tr2, #0x1
 8000022: d1fd         \tbne\t0x8000020 <memcpy> @ imm = #-0x6
 8000024: 4770         \tbx\tlr
";

#[test]
fn block_copies_are_bounded_by_the_bytes_of_their_call_sites() {
    let p = program(COPIES);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let copy = p.find("memcpy")[0];
    // Per entry alone, each call may take the largest size's 64 back edges.
    let facts = [LoopFact {
        function: copy,
        loop_index: 0,
        bound: 64,
        per: Per::Entry,
        group: None,
        iterations: false,
    }];
    let per_entry = ipet::task_bound(
        &p,
        &ls,
        root,
        &facts,
        0,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    // root 6 + per call (2 + 2·back + 1): 6 + 2·3 + 2·2·64 = 268.
    assert_eq!(per_entry.bound, 268);
    // The sizes the binary loads before each call (r2): 64 + 8 back edges in all.
    let f = &p.functions[root];
    let preds = f.predecessors();
    let call_at = |addr: u32| {
        f.instructions
            .iter()
            .position(|i| i.address == addr)
            .unwrap()
    };
    let sizes: Vec<Option<u64>> = [0x8000004, 0x800000a]
        .iter()
        .map(|&a| bounds::constant_before(f, &preds, 0, call_at(a), "r2", 4))
        .collect();
    assert_eq!(sizes, vec![Some(64), Some(8)]);
    let copies = ipet::CopySizes {
        family: [copy].into_iter().collect(),
        sites: sizes
            .iter()
            .map(|&bytes| ipet::CopySite {
                function: root,
                callee: copy,
                block: 0,
                bytes,
                at: "root".into(),
            })
            .collect(),
        caps: Vec::new(),
        counters: Default::default(),
    };
    let by_site = ipet::task_bound(&p, &ls, root, &facts, 0, &copies, Cost::Instructions).unwrap();
    assert_eq!(by_site.bound, 6 + 2 * 3 + 2 * 72);
    // A site whose size is unknown is an error of the analysis, not a guess.
    let mut unknown = copies.clone();
    unknown.sites[1].bytes = None;
    assert!(matches!(
        ipet::task_bound(&p, &ls, root, &facts, 0, &unknown, Cost::Instructions),
        Err(WcetError::Ipet(IpetError::Unbounded(_)))
    ));
}

/// `root` copies 67 bytes with a word copy (`NAME`: a loop of one word a trip,
/// then the rest handed to `memcpy`, a loop of one byte a trip).
const WORD_COPY: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: 2243         \tmovs\tr2, #0x43
 8000004: f000 f80c    \tbl\t0x8000020 <NAME> @ imm = #0x18
 8000008: bd10         \tpop\t{r4, pc}

08000020 <NAME>:
 8000020: 2a03         \tcmp\tr2, #0x3
 8000022: d906         \tbls\t0x8000032 <NAME+0x12> @ imm = #0xc
 8000024: f851 3b04    \tldr\tr3, [r1], #4
 8000028: f840 3b04    \tstr\tr3, [r0], #4
 800002c: 3a04         \tsubs\tr2, #0x4
 800002e: 2a03         \tcmp\tr2, #0x3
 8000030: d8f8         \tbhi\t0x8000024 <NAME+0x4> @ imm = #-0x10
 8000032: f000 b805    \tb.w\t0x8000040 <memcpy> @ imm = #0xa

08000040 <memcpy>:
 8000040: 2a00         \tcmp\tr2, #0x0
 8000042: d005         \tbeq\t0x8000050 <memcpy+0x10> @ imm = #0xa
 8000044: f811 3b01    \tldrb\tr3, [r1], #1
 8000048: f800 3b01    \tstrb\tr3, [r0], #1
 800004c: 3a01         \tsubs\tr2, #0x1
 800004e: d1f9         \tbne\t0x8000044 <memcpy+0x4> @ imm = #-0xe
 8000050: 4770         \tbx\tlr
";

/// The instruction bound of `root` in `text`, the block copies' family
/// `family` (function names), each with one loop bounded per entry by `facts`
/// (name, back edges) and called from `root`'s first block as `sites` (callee,
/// bytes).
fn copy_family_bound(
    text: &str,
    family: &[&str],
    facts: &[(&str, u64)],
    sites: &[(&str, u64)],
) -> u64 {
    let p = program(text);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let at = |name: &str| p.find(name)[0];
    let facts: Vec<LoopFact> = facts
        .iter()
        .map(|&(name, bound)| LoopFact {
            function: at(name),
            loop_index: 0,
            bound,
            per: Per::Entry,
            group: None,
            iterations: false,
        })
        .collect();
    let copies = ipet::CopySizes {
        family: family.iter().map(|&name| at(name)).collect(),
        sites: sites
            .iter()
            .map(|&(callee, bytes)| ipet::CopySite {
                function: root,
                callee: at(callee),
                block: 0,
                bytes: Some(bytes),
                at: "root".into(),
            })
            .collect(),
        caps: Vec::new(),
        counters: Default::default(),
    };
    ipet::task_bound(&p, &ls, root, &facts, 0, &copies, Cost::Instructions)
        .unwrap()
        .bound
}

/// The bound of [`WORD_COPY`] with its word copy named `name`: per entry alone,
/// 16 words and all 67 bytes one by one.
fn word_copy_bound(name: &str) -> u64 {
    copy_family_bound(
        &WORD_COPY.replace("NAME", name),
        &[name, "memcpy"],
        &[(name, 16), ("memcpy", 67)],
        &[(name, 67)],
    )
}

#[test]
fn a_word_copy_hands_memcpy_at_most_its_remainder() {
    // root 4, the word copy 2 + 5·(1 + w) + 1, memcpy 2 + 4·(1 + b) + 1, with w
    // words and b bytes: 19 + 5w + 4b, and 4w + b ≤ 67 (the call's bytes).
    // An unknown copy function handing over to memcpy: the shared budget alone
    // lets the worst path move all 67 bytes one by one (b = 67, w = 0).
    assert_eq!(word_copy_bound("copy_words"), 19 + 4 * 67);
    // `__aeabi_memcpy4` hands over at most 3 bytes: b ≤ 3, then w = 16.
    assert_eq!(word_copy_bound("__aeabi_memcpy4"), 19 + 5 * 16 + 4 * 3);
}

/// `root` moves 8 bytes through `NAME`, which forwards to `memmove` (a loop of
/// one byte a trip, 4 instructions), and fills 64 with `memset` (a loop of four
/// bytes a trip, 3 instructions).
const FORWARDER: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: 2208         \tmovs\tr2, #0x8
 8000004: f000 f80c    \tbl\t0x8000020 <NAME> @ imm = #0x18
 8000008: 2240         \tmovs\tr2, #0x40
 800000a: f000 f821    \tbl\t0x8000050 <memset> @ imm = #0x42
 800000e: bd10         \tpop\t{r4, pc}

08000020 <NAME>:
 8000020: f000 b80e    \tb.w\t0x8000040 <memmove> @ imm = #0x1c

08000040 <memmove>:
 8000040: f811 3b01    \tldrb\tr3, [r1], #1
 8000044: f800 3b01    \tstrb\tr3, [r0], #1
 8000048: 3a01         \tsubs\tr2, #0x1
 800004a: d1f9         \tbne\t0x8000040 <memmove> @ imm = #-0xe
 800004c: 4770         \tbx\tlr

08000050 <memset>:
 8000050: f840 1b04    \tstr\tr1, [r0], #4
 8000054: 3a04         \tsubs\tr2, #0x4
 8000056: d1fb         \tbne\t0x8000050 <memset> @ imm = #-0xa
 8000058: 4770         \tbx\tlr
";

/// The bound of [`FORWARDER`] with its forwarder named `name`: per entry alone,
/// all 72 bytes one by one, 16 words.
fn forwarder_bound(name: &str) -> u64 {
    copy_family_bound(
        &FORWARDER.replace("NAME", name),
        &[name, "memmove", "memset"],
        &[("memmove", 72), ("memset", 16)],
        &[(name, 8), ("memset", 64)],
    )
}

#[test]
fn a_forwarded_copy_moves_only_its_callers_bytes() {
    // root 6, the forwarder 1, memmove 4·(1 + m) + 1, memset 3·(1 + w) + 1, with m
    // and w back edges (the last trip of each loop is its entry's, not a back
    // edge): 16 + 4m + 3w, and m + 4w ≤ 72 (the calls' bytes).
    // An unknown function calling memmove: the shared budget alone lets the
    // worst path spend all 72 bytes one by one in memmove (m = 72, w = 0).
    assert_eq!(forwarder_bound("copy_through"), 16 + 4 * 72);
    // `__aeabi_memmove8` forwards its call unchanged: memmove moves its 8 bytes
    // (m ≤ 8), memset its 64 (4w ≤ 64).
    assert_eq!(forwarder_bound("__aeabi_memmove8"), 16 + 4 * 8 + 3 * 16);
}

/// `root` returns at once, or counts `r0` down and panics: the loop is on a path
/// that never completes.
const ENDS_IN_PANIC: &str = "
08000000 <root>:
 8000000: 2800         \tcmp\tr0, #0x0
 8000002: d000         \tbeq\t0x8000006 <root+0x6> @ imm = #0x0
 8000004: 4770         \tbx\tlr
 8000006: 3801         \tsubs\tr0, #0x1
 8000008: d1fd         \tbne\t0x8000006 <root+0x6> @ imm = #-0x6
 800000a: f000 f801    \tbl\t0x8000010 <panic> @ imm = #0x2

08000010 <panic>:
 8000010: e7fe         \tb\t0x8000010 <panic> @ imm = #-0x4
";

#[test]
fn loops_on_paths_that_never_complete_need_no_bound() {
    let p = program(ENDS_IN_PANIC);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let f = &p.functions[root];
    let live = f.completing();
    let at = |a: u32| f.block_at(a).unwrap();
    assert!(live[at(0x8000000)] && live[at(0x8000004)]);
    assert!(!live[at(0x8000006)] && !live[at(0x800000a)]);
    assert!(!p
        .completing_reachable(&[root])
        .contains(&p.find("panic")[0]));
    // No fact for the count-down loop: the completing path is cmp, beq, bx lr.
    let b = ipet::task_bound(
        &p,
        &ls,
        root,
        &[],
        0,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    assert_eq!(b.bound, 3);
}

#[test]
fn a_cap_per_loop_entry_bounds_the_blocks_of_its_line() {
    let p = program(COUNTED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let facts = [LoopFact {
        function: root,
        loop_index: 0,
        bound: 15,
        per: Per::Entry,
        group: None,
        iterations: false,
    }];
    let free = ipet::task_bound(
        &p,
        &ls,
        root,
        &facts,
        0,
        &Default::default(),
        Cost::Instructions,
    )
    .unwrap();
    assert_eq!(free.bound, 67);
    // The block with the call to `leaf` at most once per entry of the loop: the
    // loop's body runs once, 2 + 3 + 1 (leaf) + 1.
    let capped = ipet::CopySizes {
        caps: vec![ipet::BlockCap {
            function: root,
            blocks: vec![1],
            loop_index: Some(0),
            bound: 1,
            activation_group: None,
            annotation: None,
        }],
        ..Default::default()
    };
    let b = ipet::task_bound(&p, &ls, root, &facts, 0, &capped, Cost::Instructions).unwrap();
    assert_eq!(b.bound, 7);
}

/// `root` calls `mid` twice; `mid` runs an outer loop (r5) around an inner one
/// (r4): a loop nest whose inner loop a bound per call caps over all its entries.
const NESTED: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: f000 f805    \tbl\t0x8000010 <mid> @ imm = #0xa
 8000006: f000 f803    \tbl\t0x8000010 <mid> @ imm = #0x6
 800000a: bd10         \tpop\t{r4, pc}

08000010 <mid>:
 8000010: 2504         \tmovs\tr5, #0x4
 8000012: 2404         \tmovs\tr4, #0x4
 8000014: 3c01         \tsubs\tr4, #0x1
 8000016: d1fd         \tbne\t0x8000014 <mid+0x4> @ imm = #-0x6
 8000018: 3d01         \tsubs\tr5, #0x1
 800001a: d1fa         \tbne\t0x8000012 <mid+0x2> @ imm = #-0xc
 800001c: 4770         \tbx\tlr
";

#[test]
fn a_bound_per_call_caps_the_inner_loop_over_all_its_entries() {
    let p = program(NESTED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let mid = p.find("mid")[0];
    let at = |addr: u32| loop_at(&p, &ls, mid, addr);
    let (outer, inner) = (at(0x8000012), at(0x8000014));
    let facts = |per: Per| {
        [
            LoopFact {
                function: mid,
                loop_index: outer,
                bound: 3,
                per: Per::Entry,
                group: None,
                iterations: false,
            },
            LoopFact {
                function: mid,
                loop_index: inner,
                bound: 6,
                per,
                group: None,
                iterations: false,
            },
        ]
    };
    let bound = |per: Per| {
        ipet::task_bound(
            &p,
            &ls,
            root,
            &facts(per),
            0,
            &Default::default(),
            Cost::Instructions,
        )
        .unwrap()
        .bound
    };
    // Per call of `mid`: movs r5 (1) + 4 × movs r4 (4) + the inner block
    // (2 instructions) 4 entries + 6 back edges (20) + 4 × subs/bne r5 (8) + bx (1)
    // = 34; root 4 + 2 × 34.
    assert_eq!(bound(Per::Call), 72);
    // Per entry: the inner block runs 4 + 4 × 6 = 28 times per call: 1 + 4 + 56 +
    // 8 + 1 = 70; root 4 + 2 × 70.
    assert_eq!(bound(Per::Entry), 144);
}

#[test]
fn a_cap_per_activation_counts_every_copy_of_its_line_together() {
    let p = program(COUNTED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let facts = [LoopFact {
        function: root,
        loop_index: 0,
        bound: 15,
        per: Per::Entry,
        group: None,
        iterations: false,
    }];
    let cap = |bound: u64| ipet::BlockCap {
        function: root,
        blocks: vec![1],
        loop_index: None,
        bound,
        activation_group: Some(7),
        annotation: None,
    };
    let run = |caps: Vec<ipet::BlockCap>| {
        let copies = ipet::CopySizes {
            caps,
            ..Default::default()
        };
        ipet::task_bound(&p, &ls, root, &facts, 0, &copies, Cost::Instructions)
            .unwrap()
            .bound
    };
    // The loop's body (the block with the call of `leaf`) at most 3 times per
    // activation: 2 + 3 × (3 + 1) + 1.
    assert_eq!(run(vec![cap(3)]), 15);
    // Two copies of one line in one group share the cap: the body's runs are
    // counted twice against 3, 1.5 runs in the linear relaxation; `leaf`'s entry
    // count is an integer, so the body, which calls it once a run, runs once:
    // 2 + 1 × 4 + 1.
    assert_eq!(run(vec![cap(3), cap(3)]), 7);
}

/// Two loops of 16 iterations in `root`: the first (2 instructions) alone, the
/// second (3 instructions) calling `leaf` (1).
const TWO_COUNTED: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: 2410         \tmovs\tr4, #0x10
 8000004: 3c01         \tsubs\tr4, #0x1
 8000006: d1fd         \tbne\t0x8000004 <root+0x4> @ imm = #-0x6
 8000008: 2410         \tmovs\tr4, #0x10
 800000a: f000 f805    \tbl\t0x8000018 <leaf> @ imm = #0xa
 800000e: 3c01         \tsubs\tr4, #0x1
 8000010: d1fb         \tbne\t0x800000a <root+0xa> @ imm = #-0xa
 8000012: bd10         \tpop\t{r4, pc}

08000018 <leaf>:
 8000018: 4770         \tbx\tlr
";

#[test]
fn a_counter_bounds_a_loop_and_a_call_together() {
    let p = program(TWO_COUNTED);
    let ls = all_loops(&p);
    let root = p.find("root")[0];
    let f = &p.functions[root];
    let (first, second) = (
        loop_at(&p, &ls, root, 0x8000004),
        loop_at(&p, &ls, root, 0x800000a),
    );
    let call_block = f.blocks.iter().position(|b| b.start == 0x800000a).unwrap();
    let bound = |per: Per, group: usize| {
        let facts = [
            LoopFact {
                function: root,
                loop_index: first,
                bound: 15,
                per,
                group: None,
                iterations: false,
            },
            LoopFact {
                function: root,
                loop_index: second,
                bound: 15,
                per: Per::Entry,
                group: None,
                iterations: false,
            },
        ];
        let copies = ipet::CopySizes {
            caps: vec![ipet::BlockCap {
                function: root,
                blocks: vec![call_block],
                loop_index: None,
                bound: 15,
                activation_group: Some(group),
                annotation: None,
            }],
            counters: [(group, 7)].into_iter().collect(),
            ..Default::default()
        };
        ipet::task_bound(&p, &ls, root, &facts, 0, &copies, Cost::Instructions)
            .unwrap()
            .bound
    };
    // Separate caps: the first loop's 15 back edges (16 runs of 2) and the call's
    // 15 runs (of 3 + 1): 2 + 32 + 1 + 60 + 1.
    assert_eq!(bound(Per::Activation, 3), 96);
    // One counter (the call's group 3 counted in group 7, with the loop): 15 in
    // all, best spent on the dearer call, the first loop's block once: 2 + 2 + 1
    // + 60 + 1.
    assert_eq!(bound(Per::Counted(7), 3), 66);
}

/// A copy loop that stores 8 bytes per trip on its short path (two `str`) and 9 on
/// its long one (and one `strb`); a conditional store (`strne`) and a store to the
/// stack do not count.
const COPY_LOOP: &str = "
08000000 <copy>:
 8000000: f851 3b04    \tldr\tr3, [r1], #4
 8000004: f840 3b04    \tstr\tr3, [r0], #4
 8000008: 9300         \tstr\tr3, [sp]
 800000a: bf18         \tit\tne
 800000c: 6003         \tstrne\tr3, [r0]
 800000e: 2a04         \tcmp\tr2, #0x4
 8000010: d001         \tbeq\t0x8000016 <copy+0x16> @ imm = #0x2
 8000012: 7003         \tstrb\tr3, [r0]
 8000014: e7ff         \tb\t0x8000016 <copy+0x16> @ imm = #-0x2
 8000016: f840 3b04    \tstr\tr3, [r0], #4
 800001a: 3a08         \tsubs\tr2, #0x8
 800001c: d1f0         \tbne\t0x8000000 <copy> @ imm = #-0x20
 800001e: 4770         \tbx\tlr
";

#[test]
fn a_copy_loop_trip_stores_the_bytes_of_its_shortest_path() {
    let p = program(COPY_LOOP);
    let f = &p.functions[p.find("copy")[0]];
    let ls = loops::natural_loops(f).unwrap();
    assert_eq!(ls.len(), 1);
    assert_eq!(loops::min_stored_bytes_per_trip(f, &ls, &ls[0]), 8);
    let bytes: Vec<u64> = f.instructions.iter().map(loops::stored_bytes).collect();
    assert_eq!(bytes, vec![0, 4, 0, 0, 0, 0, 0, 1, 0, 4, 0, 0, 0]);
}

/// Only pc-relative loads read flash once the model knows data is not there: a
/// load through a register costs the wait states under the default model only.
#[test]
fn flash_wait_states_follow_where_data_can_be() {
    const LOADS: &str = "
08000000 <f>:
 8000000: 6808         \tldr\tr0, [r1]
 8000002: 4a01         \tldr\tr2, [pc, #0x4]
 8000004: 4770         \tbx\tlr
";
    let raw = cfg::parse_disassembly(LOADS);
    let anywhere = MODEL;
    let pools = MemoryModel {
        flash_data: cfg::FlashData::ConstantPools(Default::default()),
        ..MODEL
    };
    let insns = &raw[0].instructions[..2];
    // ldr 2 + ldr 2, one 16-byte flash line (6): 10; each flash read 5 more.
    assert_eq!(pools.block_cycles(0x0800_0000, insns), 10 + 5);
    assert_eq!(anywhere.block_cycles(0x0800_0000, insns), 10 + 5 + 5);
    // A function that addresses a constant island is charged as before.
    let listed = MemoryModel {
        flash_data: cfg::FlashData::ConstantPools([(0x0800_0000, "f".into())].into()),
        ..MODEL
    };
    assert_eq!(listed.block_cycles(0x0800_0000, insns), 10 + 5 + 5);
}

/// A root that either calls `looper` (a loop of `subs`/`bne` capped per
/// activation) or runs a long straight path of 40 `adds`.
const ONE_BRANCH_LOOPS: &str = "
08000000 <root>:
 8000000: b510         \tpush\t{r4, lr}
 8000002: 2800         \tcmp\tr0, #0x0
 8000004: d002         \tbeq\t0x800000c <root+0xc> @ imm = #0x4
 8000006: f000 f81b    \tbl\t0x8000040 <looper> @ imm = #0x36
 800000a: bd10         \tpop\t{r4, pc}
 800000c: 3101         \tadds\tr1, #0x1
LONG
 8000036: bd10         \tpop\t{r4, pc}

08000040 <looper>:
 8000040: 2410         \tmovs\tr4, #0x10
 8000042: 3c01         \tsubs\tr4, #0x1
 8000044: d1fd         \tbne\t0x8000042 <looper+0x2> @ imm = #-0x6
 8000046: 4770         \tbx\tlr
";

#[test]
fn a_cap_per_activation_is_not_charged_on_the_branch_that_skips_its_loop() {
    let long: String = (1..21u32)
        .map(|k| format!(" {:7x}: 3101         \tadds\tr1, #0x1\n", 0x800000c + 2 * k))
        .collect();
    let p = program(&ONE_BRANCH_LOOPS.replace("LONG\n", &long));
    let ls = all_loops(&p);
    let (root, looper) = (p.find("root")[0], p.find("looper")[0]);
    let lp = loop_at(&p, &ls, looper, 0x8000042);
    let bound = |per: Per, cap: u64| {
        let facts = [LoopFact {
            function: looper,
            loop_index: lp,
            bound: cap,
            per,
            group: None,
            iterations: false,
        }];
        ipet::task_bound(
            &p,
            &ls,
            root,
            &facts,
            0,
            &ipet::CopySizes::default(),
            Cost::Instructions,
        )
        .unwrap()
        .bound
    };
    // The long path: push, cmp, beq, 21 adds, pop = 25 instructions. The call with
    // 10 back edges: push, cmp, beq, bl, movs, 11 × (subs, bne), bx, pop = 29.
    // Before the per-entry ties the relaxation took the long path and still ran
    // the loop's 10 capped back edges (a circulation with no entry): 45.
    assert_eq!(bound(Per::Activation, 10), 29);
    assert_eq!(bound(Per::Counted(3), 10), 29);
    // Where the call is the dearer path the tie cuts nothing: 4 + 1 + 21 × 2 + 2.
    assert_eq!(bound(Per::Activation, 20), 49);
    // A cap below the long path's cost leaves the long path.
    assert_eq!(bound(Per::Activation, 1), 25);
}
