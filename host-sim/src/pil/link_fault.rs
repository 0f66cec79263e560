//! Faults injected on the link to the ECU (`host-sim pil --link-fault`): from the
//! fault's start, `N` consecutive sensor frames are replaced by forged, replayed
//! or corrupted ones, each of which the ECU must refuse and count by its reason
//! ([`firmware::link::Refusal`]) and never act on: each such period runs as a
//! dropout (the safe actuation), and the lap goes on.
//!
//! | fault | the frame the ECU receives instead of the period's sensor frame | refused as |
//! |---|---|---|
//! | `forge[:N]` | the period's sensor frame, fresh, its tag computed under another key than the link's (a forger without the key) | `auth` |
//! | `replay[:N]` | a sensor frame sent, and accepted, before the fault (the last second's, oldest first), bit for bit | `replay` |
//! | `corrupt[:N]` | the period's sensor frame with one bit flipped on the way (never into a 0x00, which would split the frame) | `corrupt` |
//!
//! The in-process run that `host-sim pil` compares with models the same periods
//! as a `dropout-nan` ([`LinkFault::dropout`]): the ECU runs a period whose
//! frame it refused on no estimate, as that fault delivers, and learns of the
//! route frames announced in a refused frame from the next one it accepts.

use std::fmt;
use std::str::FromStr;

use firmware::link::Refusal;
use firmware::tasks::CONTROL_PERIOD_US;

use crate::world::disturbance::{Dropout, DropoutKind};

/// Sensor frames a link fault replaces when no `N` is given, frames.
pub const DEFAULT_LINK_FAULT_FRAMES: u32 = 20;

/// What a link fault does to a sensor frame (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkFaultKind {
    /// A frame whose tag was computed under another key.
    Forge,
    /// A frame sent before, again.
    Replay,
    /// A frame with one bit flipped.
    Corrupt,
}

impl LinkFaultKind {
    /// Every kind.
    pub const ALL: [LinkFaultKind; 3] = [
        LinkFaultKind::Forge,
        LinkFaultKind::Replay,
        LinkFaultKind::Corrupt,
    ];

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            LinkFaultKind::Forge => "forge",
            LinkFaultKind::Replay => "replay",
            LinkFaultKind::Corrupt => "corrupt",
        }
    }

    /// The reason the ECU must refuse such a frame for.
    pub fn refusal(self) -> Refusal {
        match self {
            LinkFaultKind::Forge => Refusal::Auth,
            LinkFaultKind::Replay => Refusal::Replay,
            LinkFaultKind::Corrupt => Refusal::Corrupt,
        }
    }
}

/// A link fault on the command line: `KIND[:N]` (module docs), its start apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkFaultSpec {
    /// What is done to the frames.
    pub kind: LinkFaultKind,
    /// Consecutive sensor frames replaced, frames (≥ 1).
    pub frames: u32,
}

impl FromStr for LinkFaultSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (name, n) = match s.split_once(':') {
            Some((name, n)) => (name, Some(n)),
            None => (s, None),
        };
        let Some(kind) = LinkFaultKind::ALL.into_iter().find(|k| k.name() == name) else {
            return Err(format!(
                "unknown link fault {s:?}: forge, replay or corrupt, each with an optional :N (sensor frames, default {DEFAULT_LINK_FAULT_FRAMES})"
            ));
        };
        let frames = match n {
            None => DEFAULT_LINK_FAULT_FRAMES,
            Some(n) => match n.parse::<u32>() {
                Ok(n) if n >= 1 => n,
                _ => {
                    return Err(format!(
                        "link fault {s:?}: N must be a whole number of sensor frames, at least 1"
                    ))
                }
            },
        };
        Ok(Self { kind, frames })
    }
}

impl fmt::Display for LinkFaultSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.kind.name(), self.frames)
    }
}

/// A link fault of a run: what, how many frames, from when.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkFault {
    /// What is done to the frames, and how many.
    pub spec: LinkFaultSpec,
    /// The first control instant whose sensor frame is replaced, µs.
    pub start_us: u64,
}

impl LinkFault {
    /// Whether the sensor frame of the control instant `t_us` (µs) is replaced.
    pub fn covers(&self, t_us: u64) -> bool {
        self.dropout().covers(t_us)
    }

    /// The same periods as a dropout with no estimate (`dropout-nan`), the
    /// in-process run's model of the refused frames.
    pub fn dropout(&self) -> Dropout {
        Dropout {
            start_us: self.start_us,
            periods: self.spec.frames,
            kind: DropoutKind::Nan,
            withholds_route: true,
        }
    }

    /// The instant after the last replaced sensor frame, µs.
    pub fn end_us(&self) -> u64 {
        self.start_us + u64::from(self.spec.frames) * CONTROL_PERIOD_US
    }
}

/// Flips one bit of the encoded frame `frame` (its 0x00 delimiter last), the
/// `k`-th flip of a run: a byte before the delimiter, spread over the frame by
/// `k`, and a bit of it chosen so that the byte does not become 0x00 (which would
/// end the frame there and make two of it). The frame keeps its length and its
/// one delimiter: a frame damaged on the way, not lost.
pub fn flip_bit(frame: &mut [u8], k: u32) {
    let Some(body) = frame.len().checked_sub(1).filter(|&n| n > 0) else {
        return;
    };
    let i = (k as usize).wrapping_mul(37).wrapping_add(body / 2) % body;
    let b = frame[i];
    let bit = (0..8u32)
        .map(|j| (k + j) % 8)
        .find(|&j| b ^ (1 << j) != 0)
        .unwrap_or(0);
    frame[i] = b ^ (1 << bit);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_faults_parse_with_their_default_and_print_back() {
        assert_eq!(
            "forge".parse::<LinkFaultSpec>(),
            Ok(LinkFaultSpec {
                kind: LinkFaultKind::Forge,
                frames: DEFAULT_LINK_FAULT_FRAMES
            })
        );
        for s in ["forge:3", "replay:1", "corrupt:40"] {
            let f = s.parse::<LinkFaultSpec>();
            assert_eq!(f.map(|f| f.to_string()), Ok(s.to_string()));
        }
        for bad in ["forge:0", "replay:-1", "corrupt:2.5", "jam", "forge:x"] {
            assert!(bad.parse::<LinkFaultSpec>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_link_fault_covers_its_frames_only() {
        let f = LinkFault {
            spec: LinkFaultSpec {
                kind: LinkFaultKind::Replay,
                frames: 3,
            },
            start_us: 1_000_000,
        };
        let covered: Vec<u64> = (90..110)
            .map(|k| k * CONTROL_PERIOD_US)
            .filter(|&t| f.covers(t))
            .collect();
        assert_eq!(covered, vec![1_000_000, 1_010_000, 1_020_000]);
        assert_eq!(f.end_us(), 1_030_000);
    }

    #[test]
    fn a_flipped_bit_changes_one_bit_and_never_makes_a_delimiter() {
        for len in 2..40usize {
            for k in 0..50 {
                // Bytes that are powers of two: flipping their one set bit would
                // give 0x00.
                let frame: Vec<u8> = (0..len)
                    .map(|i| if i + 1 == len { 0 } else { 1 << (i % 8) })
                    .collect();
                let mut flipped = frame.clone();
                flip_bit(&mut flipped, k);
                let bits: u32 = frame
                    .iter()
                    .zip(&flipped)
                    .map(|(a, b)| (a ^ b).count_ones())
                    .sum();
                assert_eq!(bits, 1, "len {len}, k {k}");
                assert_eq!(flipped.iter().filter(|&&b| b == 0).count(), 1);
                assert_eq!(flipped.last(), Some(&0));
            }
        }
    }
}
