//! Faults injected on the link to the ECU (`host-sim pil --link-fault`): from the
//! fault's start, `N` consecutive frames of one channel are replaced by forged,
//! replayed or corrupted ones, each of which the ECU must refuse and count by its
//! reason ([`firmware::link::Refusal`]) and never act on, and the lap goes on.
//!
//! | fault | the frame the ECU receives instead | refused as |
//! |---|---|---|
//! | `forge[:N]` | the frame, fresh, its tag computed under another key than the link's (a forger without the key) | `auth` |
//! | `replay[:N]` | a frame of the same channel sent, and accepted, before the fault (oldest first), bit for bit | `replay` |
//! | `corrupt[:N]` | the frame with one bit flipped on the way (never into a 0x00, which would split the frame) | `corrupt` |
//! | `mix[:N]` | forge, replay, corrupt, in turn | each by its own |
//! | `noise[:N]` | the frame itself, after a run of line noise as long as the longest sensor frame, without a delimiter (a line that glitched) | the run `corrupt`; the frame after it taken |
//!
//! Plain, the fault replaces the sensor frames of `N` control periods. The
//! in-process run that `host-sim pil` compares with models those periods as a
//! `dropout-nan` ([`LinkFault::dropout`]): the ECU runs a period whose frame it
//! refused on no estimate, as that fault delivers, and learns of the route frames
//! announced in a refused frame from the next one it accepts. Noise replaces no
//! frame: the ECU skips the run, counts it, and acts on the frame after it, so
//! the in-process run has no dropout there. It is a fault of the sensor frames
//! only.
//!
//! With the prefix `route-` it replaces the next `N` frames of the road sent on
//! the route channel (one per plan release, [`crate::world::route`]). The ECU
//! refuses each and stages nothing from it; the window it belonged to can no
//! longer complete (its later chunks come out of order, and are refused as
//! such), so the car plans on the window it holds until the next one arrives.
//! The in-process run drops the same frames ([`LinkFault::route_frames`]).

use std::fmt;
use std::str::FromStr;

use firmware::link::{Refusal, RefusalCounts};
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
    /// The frame itself after a run of nonzero bytes as long as the longest
    /// sensor frame ([`NOISE_BYTES`]): not a replaced frame, the run is refused
    /// and the frame after it taken.
    Noise,
}

/// Bytes of a run of line noise ([`LinkFaultKind::Noise`]): as many as the
/// longest frame the ECU reads as a sensor frame, so that it gives the run up at
/// its end and reads the frame after it whole. (A longer run would leave its
/// tail before the frame, and the ECU would refuse the frame as corrupt too: a
/// dropout.)
pub const NOISE_BYTES: usize = firmware::link::MAX_DRIVING_DOWN_FRAME_BYTES;

/// The bytes of a run of line noise: [`NOISE_BYTES`] nonzero bytes (no delimiter).
pub fn noise_run() -> Vec<u8> {
    (0..NOISE_BYTES)
        .map(|i| 0x55 ^ (i as u8).wrapping_mul(29) | 1)
        .collect()
}

impl LinkFaultKind {
    /// The kinds that replace a frame, in a mix's order.
    pub const ALL: [LinkFaultKind; 3] = [
        LinkFaultKind::Forge,
        LinkFaultKind::Replay,
        LinkFaultKind::Corrupt,
    ];

    /// Whether the ECU must refuse the frame itself (every kind but noise, whose
    /// frame it takes after refusing the run before it).
    pub fn replaces_frame(self) -> bool {
        self != LinkFaultKind::Noise
    }

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            LinkFaultKind::Forge => "forge",
            LinkFaultKind::Replay => "replay",
            LinkFaultKind::Corrupt => "corrupt",
            LinkFaultKind::Noise => "noise",
        }
    }

    /// The reason the ECU must refuse such a frame for.
    pub fn refusal(self) -> Refusal {
        match self {
            LinkFaultKind::Forge => Refusal::Auth,
            LinkFaultKind::Replay => Refusal::Replay,
            LinkFaultKind::Corrupt | LinkFaultKind::Noise => Refusal::Corrupt,
        }
    }
}

/// The kinds a link fault gives the frames it replaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultKinds {
    /// Every frame the same.
    One(LinkFaultKind),
    /// Forge, replay, corrupt, in turn from the first.
    Mix,
}

impl FaultKinds {
    /// What the `k`-th replaced frame of a run (from 0) gets.
    pub fn nth(self, k: u32) -> LinkFaultKind {
        match self {
            FaultKinds::One(kind) => kind,
            FaultKinds::Mix => LinkFaultKind::ALL[k as usize % LinkFaultKind::ALL.len()],
        }
    }

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            FaultKinds::One(kind) => kind.name(),
            FaultKinds::Mix => "mix",
        }
    }

    /// What the ECU must refuse `frames` such frames for, by reason.
    pub fn refusals(self, frames: u32) -> RefusalCounts {
        let mut c = RefusalCounts::new();
        for k in 0..frames {
            c.count(self.nth(k).refusal());
        }
        c
    }
}

/// The frames a link fault replaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkChannel {
    /// The sensor frames, one per control period.
    Sensor,
    /// The frames of the road on the route channel, one per plan release at most.
    Route,
}

/// A link fault on the command line: `[route-]KIND[:N]` (module docs), its start
/// apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkFaultSpec {
    /// The channel whose frames are replaced.
    pub channel: LinkChannel,
    /// What is done to the frames.
    pub kinds: FaultKinds,
    /// Consecutive frames replaced, frames (≥ 1).
    pub frames: u32,
}

impl LinkChannel {
    /// Its frames' name in messages: `sensor` or `route`.
    pub fn name(self) -> &'static str {
        match self {
            LinkChannel::Sensor => "sensor",
            LinkChannel::Route => "route",
        }
    }
}

/// The `route-` prefix of a route channel's fault on the command line.
const ROUTE_PREFIX: &str = "route-";

impl FromStr for LinkFaultSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (channel, rest) = match s.strip_prefix(ROUTE_PREFIX) {
            Some(rest) => (LinkChannel::Route, rest),
            None => (LinkChannel::Sensor, s),
        };
        let (name, n) = match rest.split_once(':') {
            Some((name, n)) => (name, Some(n)),
            None => (rest, None),
        };
        let noise = LinkFaultKind::Noise;
        let kinds = match LinkFaultKind::ALL.into_iter().find(|k| k.name() == name) {
            Some(kind) => FaultKinds::One(kind),
            None if name == FaultKinds::Mix.name() => FaultKinds::Mix,
            None if name == noise.name() && channel == LinkChannel::Sensor => {
                FaultKinds::One(noise)
            }
            None if name == noise.name() => {
                return Err(format!(
                    "link fault {s:?}: noise is a fault of the sensor frames only (the route channel reads each frame up to its delimiter, whatever its length): use noise[:N]"
                ))
            }
            None => {
                return Err(format!(
                    "unknown link fault {s:?}: forge, replay, corrupt, mix or noise, each with an optional :N (frames, default {DEFAULT_LINK_FAULT_FRAMES}), and the prefix {ROUTE_PREFIX} for the route channel's frames (not noise)"
                ))
            }
        };
        let frames = match n {
            None => DEFAULT_LINK_FAULT_FRAMES,
            Some(n) => match n.parse::<u32>() {
                Ok(n) if n >= 1 => n,
                _ => {
                    return Err(format!(
                        "link fault {s:?}: N must be a whole number of frames, at least 1"
                    ))
                }
            },
        };
        Ok(Self {
            channel,
            kinds,
            frames,
        })
    }
}

impl fmt::Display for LinkFaultSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let prefix = match self.channel {
            LinkChannel::Sensor => "",
            LinkChannel::Route => ROUTE_PREFIX,
        };
        write!(f, "{prefix}{}:{}", self.kinds.name(), self.frames)
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
    /// Whether the fault acts on the sensor frame of the control instant `t_us`
    /// (µs): replaces it, or sends noise before it.
    pub fn covers(&self, t_us: u64) -> bool {
        self.spec.channel == LinkChannel::Sensor && t_us >= self.start_us && t_us < self.end_us()
    }

    /// For a fault that replaces sensor frames, the same periods as a dropout
    /// with no estimate (`dropout-nan`), the in-process run's model of the
    /// refused frames; `None` for the route channel's, and for noise (the ECU
    /// acts on the frame after it).
    pub fn dropout(&self) -> Option<Dropout> {
        let replaces = match self.spec.kinds {
            FaultKinds::One(kind) => kind.replaces_frame(),
            FaultKinds::Mix => true,
        };
        (self.spec.channel == LinkChannel::Sensor && replaces).then_some(Dropout {
            start_us: self.start_us,
            periods: self.spec.frames,
            kind: DropoutKind::Nan,
            withholds_route: true,
        })
    }

    /// For a fault of the route channel, the frames it replaces: the first
    /// `frames` sent at or after `start_us` (µs); `None` for the sensor frames'.
    pub fn route_frames(&self) -> Option<RouteFault> {
        (self.spec.channel == LinkChannel::Route).then_some(RouteFault {
            start_us: self.start_us,
            frames: self.spec.frames,
        })
    }

    /// The instant after the last replaced sensor frame, µs (for the route
    /// channel, the instant the fault starts).
    pub fn end_us(&self) -> u64 {
        match self.spec.channel {
            LinkChannel::Sensor => self.start_us + u64::from(self.spec.frames) * CONTROL_PERIOD_US,
            LinkChannel::Route => self.start_us,
        }
    }
}

/// The route channel's frames a link fault replaces: the first `frames` sent at
/// or after `start_us`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RouteFault {
    /// The first instant whose route frame may be replaced, µs.
    pub start_us: u64,
    /// Frames replaced.
    pub frames: u32,
}

impl RouteFault {
    /// Whether the route frame sent at `t_us` (µs), with `replaced` frames
    /// replaced before it, is replaced.
    pub fn replaces(&self, t_us: u64, replaced: u32) -> bool {
        t_us >= self.start_us && replaced < self.frames
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
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn link_faults_parse_with_their_default_and_print_back() {
        assert_eq!(
            "forge".parse::<LinkFaultSpec>(),
            Ok(LinkFaultSpec {
                channel: LinkChannel::Sensor,
                kinds: FaultKinds::One(LinkFaultKind::Forge),
                frames: DEFAULT_LINK_FAULT_FRAMES
            })
        );
        assert_eq!(
            "route-mix:4".parse::<LinkFaultSpec>(),
            Ok(LinkFaultSpec {
                channel: LinkChannel::Route,
                kinds: FaultKinds::Mix,
                frames: 4
            })
        );
        for s in [
            "forge:3",
            "replay:1",
            "corrupt:40",
            "mix:2",
            "route-forge:1",
            "route-corrupt:7",
            "noise:4",
        ] {
            let f = s.parse::<LinkFaultSpec>();
            assert_eq!(f.map(|f| f.to_string()), Ok(s.to_string()));
        }
        for bad in [
            "forge:0",
            "replay:-1",
            "corrupt:2.5",
            "jam",
            "forge:x",
            "route-",
            "route-jam:2",
            "sensor-forge",
            "route-noise:1",
        ] {
            assert!(bad.parse::<LinkFaultSpec>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_mix_gives_the_three_kinds_in_turn() {
        let kinds: Vec<LinkFaultKind> = (0..7).map(|k| FaultKinds::Mix.nth(k)).collect();
        use LinkFaultKind::*;
        assert_eq!(
            kinds,
            vec![Forge, Replay, Corrupt, Forge, Replay, Corrupt, Forge]
        );
        let c = FaultKinds::Mix.refusals(7);
        assert_eq!(
            (
                c.of(Refusal::Auth),
                c.of(Refusal::Replay),
                c.of(Refusal::Corrupt)
            ),
            (3, 2, 2)
        );
        assert_eq!(FaultKinds::One(Replay).refusals(3).of(Refusal::Replay), 3);
    }

    #[test]
    fn a_link_fault_covers_its_frames_only() {
        let f = LinkFault {
            spec: LinkFaultSpec {
                channel: LinkChannel::Sensor,
                kinds: FaultKinds::One(LinkFaultKind::Replay),
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
        assert!(f.route_frames().is_none());
    }

    #[test]
    fn noise_covers_its_frames_replaces_none_and_is_a_corrupt_run_each() {
        let f = LinkFault {
            spec: "noise:2".parse().unwrap(),
            start_us: 1_000_000,
        };
        let covered: Vec<u64> = (90..110)
            .map(|k| k * CONTROL_PERIOD_US)
            .filter(|&t| f.covers(t))
            .collect();
        assert_eq!(covered, vec![1_000_000, 1_010_000]);
        assert!(f.dropout().is_none());
        assert_eq!(f.spec.kinds.refusals(2).of(Refusal::Corrupt), 2);
        let run = noise_run();
        assert_eq!(run.len(), firmware::link::MAX_DRIVING_DOWN_FRAME_BYTES);
        assert!(run.iter().all(|&b| b != 0));
        let err = "route-noise".parse::<LinkFaultSpec>().unwrap_err();
        assert!(err.contains("sensor frames only"), "{err}");
    }

    #[test]
    fn a_route_fault_replaces_route_frames_and_no_sensor_frame() {
        let f = LinkFault {
            spec: "route-forge:2".parse().unwrap(),
            start_us: 1_000_000,
        };
        assert!(f.dropout().is_none());
        assert!((90..110).all(|k| !f.covers(k * CONTROL_PERIOD_US)));
        let r = f.route_frames().unwrap();
        assert!(!r.replaces(900_000, 0));
        assert!(r.replaces(1_000_000, 0));
        assert!(r.replaces(1_500_000, 1));
        assert!(!r.replaces(1_600_000, 2));
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
