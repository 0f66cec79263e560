//! QEMU's `-d in_asm,exec,nochain` log read as a stream of executed translation
//! blocks: each `IN:` listing resolved once to the program's instructions, each
//! `Trace` line an execution, with the icount corrections (an execution `Stopped`
//! before it ran is dropped, one rewound by `cpu_io_recompile` counts up to the
//! rewound instruction) applied before an execution is handed out.

use crate::WcetError;
use std::collections::{HashMap, VecDeque};
use std::io::BufRead;

/// An executed instruction, resolved once per translation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Resolved {
    /// Its address.
    pub(super) address: u32,
    /// `(function, instruction index, block starting here)`.
    pub(super) at: Option<(usize, usize, Option<usize>)>,
}

/// What the log's reader hands the replay.
pub(super) enum Event {
    /// The first `count` instructions of translation `tb` ran.
    Executed { tb: usize, count: usize },
    /// An execution of an unknown translation: the stream is broken.
    Untraced,
}

fn hex(s: &str) -> Option<u32> {
    u32::from_str_radix(s.trim().trim_start_matches("0x"), 16).ok()
}

/// The TB host code pointer, the first `0x…` word of a `Trace` or `Stopped` line.
fn host_pointer(line: &str) -> Option<u64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix("0x"))
        .and_then(|h| u64::from_str_radix(h, 16).ok())
}

/// The pc of a `Trace` line's `[cs_base/pc/flags/cflags]`, or of a `Stopped`
/// line's `[pc]`.
fn bracket_pc(line: &str) -> Option<u32> {
    let open = line.find('[')?;
    let close = line[open..].find(']')? + open;
    let inside = line.get(open + 1..close)?;
    let mut fields = inside.split('/');
    let first = fields.next()?;
    match fields.next() {
        Some(pc) => hex(pc),
        None => hex(first),
    }
}

/// Streams a QEMU log into executed (prefixes of) translations, applying the icount
/// corrections: an execution is handed out only once the next event shows it was
/// not stopped or rewound.
pub(super) struct TbStream<R> {
    log: R,
    line: String,
    number: u64,
    /// The translations listed so far, their instructions resolved.
    pub(super) translations: Vec<Vec<Resolved>>,
    /// Translation not yet executed, by start pc.
    pending: HashMap<u32, usize>,
    /// (host pointer, pc) to translation.
    bound: HashMap<(u64, u32), usize>,
    /// The last execution, not yet confirmed: translation, host pointer, pc.
    last: Option<(usize, u64, u32)>,
    /// A translation rewound to its start: its executed prefix is known at the next
    /// `Trace` line.
    rewound: Option<usize>,
    /// An `IN:` listing being read.
    block: Option<Vec<Resolved>>,
    /// Executions of a translation never listed.
    pub(super) untraced: u64,
    /// Executions stopped or rewound before they completed.
    pub(super) abandoned: u64,
    /// Events ready to hand out, oldest first.
    ready: VecDeque<Event>,
    done: bool,
}

impl<R: BufRead> TbStream<R> {
    pub(super) fn new(log: R) -> Self {
        TbStream {
            log,
            line: String::new(),
            number: 0,
            translations: Vec::new(),
            pending: HashMap::new(),
            bound: HashMap::new(),
            last: None,
            rewound: None,
            block: None,
            untraced: 0,
            abandoned: 0,
            ready: VecDeque::new(),
            done: false,
        }
    }

    fn position(&self, tb: usize, pc: u32) -> Option<usize> {
        self.translations
            .get(tb)?
            .iter()
            .position(|i| i.address == pc)
    }

    fn close_listing(&mut self) {
        if let Some(insns) = self.block.take() {
            if let Some(first) = insns.first() {
                self.pending.insert(first.address, self.translations.len());
                self.translations.push(insns);
            }
        }
    }

    /// The next event; `resolve` maps an instruction address to the program.
    pub(super) fn next_event(
        &mut self,
        resolve: impl Fn(u32) -> Resolved,
    ) -> Result<Option<Event>, WcetError> {
        loop {
            if let Some(e) = self.ready.pop_front() {
                return Ok(Some(e));
            }
            if self.done {
                return Ok(None);
            }
            self.line.clear();
            let n = self
                .log
                .read_line(&mut self.line)
                .map_err(|source| WcetError::Io {
                    path: "QEMU log".into(),
                    source,
                })?;
            if n == 0 {
                self.done = true;
                self.close_listing();
                if let Some((tb, _, _)) = self.last.take() {
                    let count = self.translations.get(tb).map_or(0, Vec::len);
                    self.ready.push_back(Event::Executed { tb, count });
                }
                continue;
            }
            self.number += 1;
            let text = self.line.trim_end().to_string();
            if self.block.is_some() {
                if text.starts_with("0x") {
                    if let Some(address) = text.split_once(':').and_then(|(a, _)| hex(a)) {
                        if let Some(b) = self.block.as_mut() {
                            b.push(resolve(address));
                        }
                        continue;
                    }
                }
                self.close_listing();
            }
            if text.starts_with("Trace ") {
                let format_error = |message: &str| WcetError::LogFormat {
                    line: self.number,
                    message: message.to_string(),
                    text: text.chars().take(120).collect(),
                };
                let pc = bracket_pc(&text)
                    .ok_or_else(|| format_error("no [cs_base/pc/flags/cflags] in a Trace line"))?;
                let host = host_pointer(&text)
                    .ok_or_else(|| format_error("no TB host pointer in a Trace line"))?;
                self.trace(host, pc);
            } else if text.starts_with("IN:") {
                self.block = Some(Vec::new());
            } else if let Some(rest) = text.strip_prefix("Stopped execution of TB chain before") {
                if let Some(pc) = bracket_pc(rest) {
                    let host = host_pointer(rest);
                    if let Some((_, h, start)) = self.last {
                        if start == pc && host.is_none_or(|x| x == h) {
                            self.last = None;
                            self.abandoned += 1;
                        }
                    }
                }
            } else if let Some(rest) =
                text.strip_prefix("cpu_io_recompile: rewound execution of TB to")
            {
                if let (Some(pc), Some((tb, _, _))) = (hex(rest), self.last) {
                    if let Some(done) = self.position(tb, pc) {
                        self.last = None;
                        self.abandoned += 1;
                        if done > 0 {
                            self.ready.push_back(Event::Executed { tb, count: done });
                        } else {
                            self.rewound = Some(tb);
                        }
                    }
                }
            }
        }
    }

    fn trace(&mut self, host: u64, pc: u32) {
        if let Some(tb) = self.rewound.take() {
            if let Some(done) = self.position(tb, pc).filter(|&d| d > 0) {
                self.ready.push_back(Event::Executed { tb, count: done });
            }
        }
        if let Some((tb, _, _)) = self.last.take() {
            let count = self.translations.get(tb).map_or(0, Vec::len);
            self.ready.push_back(Event::Executed { tb, count });
        }
        if let Some(tb) = self.pending.remove(&pc) {
            self.bound.insert((host, pc), tb);
        }
        match self.bound.get(&(host, pc)).copied() {
            Some(tb) => self.last = Some((tb, host, pc)),
            None => {
                self.untraced += 1;
                self.ready.push_back(Event::Untraced);
            }
        }
    }
}
