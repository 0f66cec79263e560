//! Authenticated frames, in the manner of AUTOSAR SecOC: every frame carries a
//! freshness value and a truncated MAC, which [`super::encode`] appends and
//! [`super::decode`] checks (see [`super`]'s *Wire format*).
//!
//! # What is authenticated
//!
//! ```text
//! MAC input = data_id ++ version ++ postcard(message) ++ freshness
//!             1 byte     1 byte     n bytes             4 bytes, little-endian
//! tag       = BLAKE2s(key, MAC input), keyed, output length MAC_BYTES (RFC 7693)
//! ```
//!
//! * **Data ID** ([`Stream::data_id`], not sent): which stream the frame belongs
//!   to, as SecOC's Data ID names a PDU. A frame of one stream does not verify on
//!   another: an ECU frame sent back down, or a frame of the control channel
//!   written to the route channel, is refused as forged rather than read as
//!   fresh by another counter.
//! * **Freshness** ([`FRESHNESS_BYTES`] = 4): a counter per stream, 1 for the first
//!   frame sent and +1 for each, sent whole (no truncation: the receiver needs no
//!   synchronisation to rebuild it). A receiver accepts a frame only if its
//!   freshness is newer than the last one it accepted on that stream (gaps are
//!   accepted: a refused frame uses up a value). 32 bits at a stream's 100
//!   frames a second while driving last 497 days; the sender refuses to send
//!   past `u32::MAX` ([`FrameError::FreshnessExhausted`]) rather than wrap.
//! * **Tag** ([`MAC_BYTES`] = 8): keyed BLAKE2s whose output length, a parameter
//!   of the hash, is 64 bits: one forged frame in 2⁶⁴ verifies, the length NIST
//!   SP 800-38B advises as the least without a limit on verification attempts.
//!   On this link (up to [`super::MAX_FRAME_BYTES`]-byte frames) the 8 bytes cost
//!   little; SecOC's shorter tags are for 8-byte CAN frames.
//!
//! # Why BLAKE2s, not AES-128-CMAC
//!
//! SecOC leaves the MAC to the crypto stack; AES-128-CMAC is its usual profile,
//! done by a crypto unit. The STM32F405 has none (the F415 has), and in software
//! the constant-time AES (the aes crate's fixsliced one) bounded at about 8,400
//! model cycles per 16 bytes of MAC input in the ECU's static timing analysis:
//! most of the control task's bound and 11 ms of the plan task's response time.
//! Keyed BLAKE2s is a PRF made for 32-bit cores (additions, rotations and XORs,
//! constant time by construction) and, like CMAC, needs no nonce: a freshness
//! counter that restarts under one key allows replays, which the freshness check
//! refuses, never a forgery. Its bound is about 3,550 model cycles per 64 bytes
//! (docs/timing.md, *The flashed build*, gives the measurements). A vehicle whose
//! gateway speaks CMAC would compute it in its crypto unit instead.
//!
//! # Order of the checks
//!
//! [`super::decode`] checks the framing, the version and the CRC first (a frame
//! that fails them is *corrupt*: [`Refusal::Corrupt`]), then the tag (a frame
//! whose CRC holds but whose tag does not verify is *forged*:
//! [`Refusal::Auth`]), then the freshness (an authentic frame that is not newer
//! is *replayed*: [`Refusal::Replay`]), then the message. The receiver's
//! freshness moves only when the whole frame is accepted. The tags are compared
//! in constant time.
//!
//! # The key
//!
//! [`LINK_KEY`] is set at build time by `ECU_LINK_KEY` (32 hexadecimal digits),
//! else the development key `DEV-ONLY-SIM-KEY` (ASCII), for the simulator only
//! (the firmware's `build.rs`; docs/pil-and-hil.md says how a vehicle's key would be
//! provisioned instead).
//!
//! # Cost
//!
//! [`LinkMac`] holds BLAKE2s's state after the key's block (compressed once per
//! link, not per frame) and the running state of a tag. A tag costs one
//! compression per 64 bytes of MAC input.

use blake2::digest::core_api::{Buffer, UpdateCore, VariableOutputCore};
use blake2::digest::Output;
use blake2::Blake2sVarCore;
use serde::{Deserialize, Serialize};
use subtle::ConstantTimeEq;

use super::FrameError;

/// Bytes of a link key (BLAKE2s accepts 1 to 32; the link uses 16).
pub const KEY_BYTES: usize = 16;
/// Bytes of the freshness value in a frame (a `u32`, little-endian).
pub const FRESHNESS_BYTES: usize = 4;
/// Bytes of the tag in a frame (BLAKE2s's output length).
pub const MAC_BYTES: usize = 8;
/// Bytes the authentication adds to a raw frame: freshness and tag.
pub const SECURED_BYTES: usize = FRESHNESS_BYTES + MAC_BYTES;

/// A link key: the key of the keyed BLAKE2s, bytes.
pub type LinkKey = [u8; KEY_BYTES];

// `LINK_KEY` and `LINK_KEY_FROM_ENV`, written by build.rs.
include!(concat!(env!("OUT_DIR"), "/link_key.rs"));

/// One stream of frames: one direction of one channel, with its own freshness
/// counter and its Data ID in the MAC input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// Host → ECU on the control channel (`ecu.down`): the set-up, the sensor
    /// frames, `Stop`.
    Down,
    /// Host → ECU on the route channel (`ecu.route`): the windows of the road.
    Route,
    /// ECU → host (`ecu.up`): `Ready`, the actuation frames, `Done`, the safe
    /// stop's frame.
    Up,
}

impl Stream {
    /// The stream's Data ID, the first byte of the MAC input (not sent).
    pub const fn data_id(self) -> u8 {
        match self {
            Stream::Down => 0x01,
            Stream::Route => 0x02,
            Stream::Up => 0x03,
        }
    }
}

/// Bytes of a BLAKE2s block: the MAC's unit of work, one compression.
const MAC_BLOCK_BYTES: usize = 64;

/// The MAC engine: keyed BLAKE2s (RFC 7693) with an 8-byte output, its state
/// after the key's block kept, and the running state of a tag (the blake2
/// crate's block-level BLAKE2s, fed a block at a time from the bytes kept
/// here). One serves every stream of a side of the link that runs in one task
/// (a tag is computed from start to end within a call).
#[derive(Clone)]
pub struct LinkMac {
    /// BLAKE2s after its first block, the key padded with zeros (RFC 7693
    /// §3.3): every tag starts from it. A MAC input is never empty (it starts
    /// with the Data ID), so the key's block is never the last one.
    keyed: Blake2sVarCore,
    /// The tag under way: the chaining state and the byte counter.
    core: Blake2sVarCore,
    /// Bytes of the MAC input not yet compressed: the last block is kept until
    /// the input ends or another byte follows, as BLAKE2 flags the last block.
    block: [u8; MAC_BLOCK_BYTES],
    /// Bytes of `block` in use, `0..=64`.
    len: u8,
}

impl LinkMac {
    /// The engine for `key` (compresses the key's block, once).
    pub fn new(key: &LinkKey) -> Self {
        let mut keyed = Blake2sVarCore::new_with_params(&[], &[], KEY_BYTES, MAC_BYTES);
        let mut key_block = [0u8; MAC_BLOCK_BYTES];
        for (k, &b) in key_block.iter_mut().zip(key.iter()) {
            *k = b;
        }
        keyed.update_blocks(core::slice::from_ref(&key_block.into()));
        Self {
            core: keyed.clone(),
            keyed,
            block: [0; MAC_BLOCK_BYTES],
            len: 0,
        }
    }

    /// Starts a tag on `stream`: the state reset (whatever an interrupted tag
    /// left), then the stream's Data ID.
    pub(super) fn begin(&mut self, stream: Stream) {
        self.core = self.keyed.clone();
        self.block[0] = stream.data_id();
        self.len = 1;
    }

    /// Compresses the kept (full) block. Not inlined: each caller's line is
    /// where the timing analysis counts its blocks.
    #[inline(never)]
    fn process_block(&mut self) {
        self.core
            .update_blocks(core::slice::from_ref(&self.block.into()));
        self.len = 0;
    }

    /// Adds `bytes` to the MAC input ([`super::decode`] and [`super::encode`]:
    /// the frame is whole), a block per pass. Always inlined: the bound on its loop is the caller's
    /// frame (`decode`'s, inlined in turn).
    #[inline(always)]
    pub(super) fn update(&mut self, mut bytes: &[u8]) {
        loop {
            let free = self
                .block
                .get_mut(usize::from(self.len)..)
                .unwrap_or_default();
            let take = free.len().min(bytes.len());
            let (now, later) = bytes.split_at(take);
            // At most a block's bytes.
            // wcet-bound: 64
            for (slot, &b) in free.iter_mut().zip(now) {
                *slot = b;
            }
            self.len += take as u8;
            bytes = later;
            if bytes.is_empty() {
                // The last block waits for `finish` (BLAKE2 flags it).
                break;
            }
            // More bytes follow the full block: it is compressed, and the next
            // pass fills the next one. With the Data ID held from `begin`, the
            // first pass fills the block and each next one takes 64 bytes, so a
            // MAC input of M bytes compresses here (M − 1) / 64 times, and the
            // binary's back edge is on this line. Frames below MAX_FRAME_BYTES,
            // and in the ECU's tasks at most theirs (decode's and encode's
            // bounds).
            // wcet-bound: (MAX_FRAME_BYTES - 1) / 64
            // wcet-bound in control: (MAX_DRIVING_DOWN_MAC_INPUT_BYTES - 1) / 64
            // wcet-bound in receive: (MAX_DOWN_MAC_INPUT_BYTES - 1) / 64
            // wcet-bound in encode: (MAX_UP_MAC_INPUT_BYTES - 1) / 64
            self.process_block();
        }
    }

    /// The tag of what was added since [`Self::begin`]; the state is reset.
    pub(super) fn finish(&mut self) -> [u8; MAC_BYTES] {
        let mut last = Buffer::<Blake2sVarCore>::default();
        last.set(
            self.block.into(),
            usize::from(self.len).min(MAC_BLOCK_BYTES),
        );
        let mut full = Output::<Blake2sVarCore>::default();
        // The last block padded: at most a block's bytes zeroed.
        // wcet-bound: 64 bytes
        self.core.finalize_variable_core(&mut last, &mut full);
        self.core = self.keyed.clone();
        self.len = 0;
        // The output size is in BLAKE2's parameter block (8 bytes): the tag is
        // the first 8 bytes of the state (RFC 7693 §3.3, the leftmost `nn`).
        let mut tag = [0u8; MAC_BYTES];
        for (t, f) in tag.iter_mut().zip(full.iter()) {
            *t = *f;
        }
        tag
    }

    /// The tag of `input` (the MAC input after the Data ID: version, payload,
    /// freshness) on `stream`.
    #[inline(always)]
    pub fn tag(&mut self, stream: Stream, input: &[u8]) -> [u8; MAC_BYTES] {
        self.begin(stream);
        self.update(input);
        self.finish()
    }

    /// Whether `tag` is the tag of `input` on `stream`, compared in constant
    /// time.
    #[inline(always)]
    pub fn verify(&mut self, stream: Stream, input: &[u8], tag: &[u8; MAC_BYTES]) -> bool {
        let expected = self.tag(stream, input);
        bool::from(u64::from_le_bytes(expected).ct_eq(&u64::from_le_bytes(*tag)))
    }
}

impl core::fmt::Debug for LinkMac {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // Never the key schedule.
        f.write_str("LinkMac { .. }")
    }
}

/// The sending side of a stream: its freshness counter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Authenticator {
    /// The stream it sends on.
    stream: Stream,
    /// Freshness of the last frame sent, 0 before the first.
    sent: u32,
}

impl Authenticator {
    /// A sender on `stream` that has sent nothing (its first frame's freshness
    /// is 1); a valid `const` initialiser.
    pub const fn new(stream: Stream) -> Self {
        Self { stream, sent: 0 }
    }

    /// A sender on `stream` that resumes after the freshness `last_sent` (a
    /// counter kept across restarts under one key, as a vehicle's would be).
    pub const fn resumed(stream: Stream, last_sent: u32) -> Self {
        Self {
            stream,
            sent: last_sent,
        }
    }

    /// The stream it sends on.
    pub const fn stream(&self) -> Stream {
        self.stream
    }

    /// Freshness of the last frame sent, 0 before the first.
    pub const fn last_sent(&self) -> u32 {
        self.sent
    }

    /// The freshness of the next frame, or [`FrameError::FreshnessExhausted`]
    /// past `u32::MAX`; taken by [`Self::commit`] once the frame is encoded.
    pub(super) const fn next(&self) -> Result<u32, FrameError> {
        match self.sent.checked_add(1) {
            Some(f) => Ok(f),
            None => Err(FrameError::FreshnessExhausted),
        }
    }

    /// Records that the frame of freshness `f` was encoded.
    pub(super) fn commit(&mut self, f: u32) {
        self.sent = f;
    }
}

/// The receiving side of a stream: the freshness of the last frame accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Verifier {
    /// The stream it receives.
    stream: Stream,
    /// Freshness of the last frame accepted, 0 before the first.
    accepted: u32,
}

impl Verifier {
    /// A receiver on `stream` that has accepted nothing (any freshness from 1 is
    /// newer); a valid `const` initialiser.
    pub const fn new(stream: Stream) -> Self {
        Self {
            stream,
            accepted: 0,
        }
    }

    /// A receiver on `stream` that resumes after the freshness `last_accepted`
    /// (kept across restarts under one key).
    pub const fn resumed(stream: Stream, last_accepted: u32) -> Self {
        Self {
            stream,
            accepted: last_accepted,
        }
    }

    /// The stream it receives.
    pub const fn stream(&self) -> Stream {
        self.stream
    }

    /// Freshness of the last frame accepted, 0 before the first.
    pub const fn last_accepted(&self) -> u32 {
        self.accepted
    }

    /// Refuses a freshness that is not newer than the last accepted one.
    pub(super) const fn check(&self, f: u32) -> Result<(), FrameError> {
        if f > self.accepted {
            Ok(())
        } else {
            Err(FrameError::Replay {
                freshness: f,
                last: self.accepted,
            })
        }
    }

    /// Records that the frame of freshness `f` was accepted.
    pub(super) fn commit(&mut self, f: u32) {
        self.accepted = f;
    }
}

/// Why a receiver refused a frame, as counted and reported: the three reasons
/// of the link's security ([`FrameError::refusal`] sorts the errors).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "ecu", derive(defmt::Format))]
pub enum Refusal {
    /// The frame's CRC held but its tag did not verify: forged (or sent under
    /// another key).
    Auth,
    /// An authentic frame whose freshness was not newer than the last accepted
    /// one: replayed.
    Replay,
    /// Not a well-formed frame of this version: COBS, length, version, CRC, or
    /// a message postcard cannot read (bits flipped on the way, a lost byte).
    Corrupt,
}

impl Refusal {
    /// Every reason, in code order.
    pub const ALL: [Refusal; 3] = [Refusal::Auth, Refusal::Replay, Refusal::Corrupt];

    /// The reason's wire code ([`super::ActuationFrame::sensor`]): `Auth` 1,
    /// `Replay` 2, `Corrupt` 3 (0 is "accepted").
    pub const fn code(self) -> u8 {
        match self {
            Refusal::Auth => 1,
            Refusal::Replay => 2,
            Refusal::Corrupt => 3,
        }
    }

    /// The reason of a wire code; `None` for 0 and unknown codes.
    pub const fn from_code(code: u8) -> Option<Refusal> {
        match code {
            1 => Some(Refusal::Auth),
            2 => Some(Refusal::Replay),
            3 => Some(Refusal::Corrupt),
            _ => None,
        }
    }

    /// The reason's name, for logs and reports (`auth`, `replay`, `corrupt`).
    pub const fn name(self) -> &'static str {
        match self {
            Refusal::Auth => "auth",
            Refusal::Replay => "replay",
            Refusal::Corrupt => "corrupt",
        }
    }
}

/// Frames a receiver refused, by [`Refusal`] (each saturating), frames; sent by
/// the ECU in its actuation and `Done` frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RefusalCounts {
    /// Frames whose tag did not verify, frames.
    pub auth: u32,
    /// Authentic frames not newer than the last accepted one, frames.
    pub replay: u32,
    /// Frames that were not well-formed frames of this version, frames.
    pub corrupt: u32,
}

impl RefusalCounts {
    /// All zero (a valid `const` initialiser).
    pub const fn new() -> Self {
        Self {
            auth: 0,
            replay: 0,
            corrupt: 0,
        }
    }

    /// Counts one refusal for `reason`.
    pub fn count(&mut self, reason: Refusal) {
        let n = match reason {
            Refusal::Auth => &mut self.auth,
            Refusal::Replay => &mut self.replay,
            Refusal::Corrupt => &mut self.corrupt,
        };
        *n = n.saturating_add(1);
    }

    /// The count for `reason`, frames.
    pub const fn of(&self, reason: Refusal) -> u32 {
        match reason {
            Refusal::Auth => self.auth,
            Refusal::Replay => self.replay,
            Refusal::Corrupt => self.corrupt,
        }
    }

    /// The sum of two counts, reason by reason (saturating), frames.
    pub const fn plus(self, other: RefusalCounts) -> RefusalCounts {
        RefusalCounts {
            auth: self.auth.saturating_add(other.auth),
            replay: self.replay.saturating_add(other.replay),
            corrupt: self.corrupt.saturating_add(other.corrupt),
        }
    }

    /// All reasons together, frames.
    pub const fn total(&self) -> u32 {
        self.auth
            .saturating_add(self.replay)
            .saturating_add(self.corrupt)
    }
}
