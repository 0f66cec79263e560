//! Authenticated frames, in the manner of AUTOSAR SecOC: every frame carries a
//! freshness value and a truncated AES-128-CMAC, which [`super::encode`] appends
//! and [`super::decode`] checks (see [`super`]'s *Wire format*).
//!
//! # What is authenticated
//!
//! ```text
//! MAC input = data_id ++ version ++ postcard(message) ++ freshness
//!             1 byte     1 byte     n bytes             4 bytes, little-endian
//! tag       = the first MAC_BYTES of AES-128-CMAC(key, MAC input)
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
//! * **Tag** ([`MAC_BYTES`] = 8): the CMAC truncated to 64 bits, the length NIST
//!   SP 800-38B advises as the least without a limit on verification attempts
//!   (one forged frame in 2⁶⁴ verifies). On this link (up to
//!   [`super::MAX_FRAME_BYTES`]-byte frames) the 8 bytes cost little; SecOC's
//!   shorter tags are for 8-byte CAN frames.
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
//! [`LinkMac`] holds the AES key schedule (fixsliced round keys, 352 bytes) and
//! the CMAC's running state: built once per link, not per frame. A tag costs one
//! AES block per 16 bytes of MAC input, plus one for the CMAC's subkey.

use aes::cipher::consts::U1;
use aes::cipher::inout::InOut;
use aes::cipher::{
    Block, BlockBackend, BlockCipher, BlockClosure, BlockEncrypt, BlockSizeUser, KeyInit,
    ParBlocksSizeUser,
};
use aes::Aes128;
use cmac::digest::core_api::{Buffer, FixedOutputCore, UpdateCore};
use cmac::digest::crypto_common::InnerInit;
use cmac::digest::{Output, Reset};
use cmac::CmacCore;
use serde::{Deserialize, Serialize};
use subtle::ConstantTimeEq;

use super::FrameError;

/// Bytes of a link key (AES-128).
pub const KEY_BYTES: usize = 16;
/// Bytes of the freshness value in a frame (a `u32`, little-endian).
pub const FRESHNESS_BYTES: usize = 4;
/// Bytes of the truncated CMAC in a frame.
pub const MAC_BYTES: usize = 8;
/// Bytes the authentication adds to a raw frame: freshness and tag.
pub const SECURED_BYTES: usize = FRESHNESS_BYTES + MAC_BYTES;

/// A link key: the AES-128 key of the CMAC, bytes.
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

/// AES-128 behind one encryption function, [`Aes::encrypt`]: the CMAC's every
/// block cipher call (its blocks, its subkey, its last block) goes through it,
/// so the aes crate's round loop has one caller, inlined there, where the timing
/// analysis takes its bound. An adapter, not a cipher: the aes crate encrypts.
#[derive(Clone)]
struct Aes(Aes128);

impl Aes {
    /// Encrypts `block` in place with AES-128 (the aes crate's software,
    /// fixsliced implementation). Not inlined: the one place the cipher runs.
    #[inline(never)]
    fn encrypt(&self, block: &mut Block<Aes128>) {
        // The aes crate's fixsliced AES-128 loop, as the ECU builds it (`--cfg
        // aes_compact`, .cargo/config.toml): two rounds a pass (1–2, 3–4, 5–6, 7–8),
        // then round 9 and it leaves (round 10 follows): 5 passes, 4 back edges.
        // Without `aes_compact` it runs four rounds a pass: 2 back edges, within
        // this bound.
        // wcet-bound: 4
        self.0.encrypt_block(block);
    }
}

impl BlockSizeUser for Aes {
    type BlockSize = <Aes128 as BlockSizeUser>::BlockSize;
}

impl BlockCipher for Aes {}

impl BlockEncrypt for Aes {
    fn encrypt_with_backend(&self, f: impl BlockClosure<BlockSize = Self::BlockSize>) {
        f.call(&mut AesBackend(self));
    }
}

/// [`Aes`] as the cipher's backend: one block at a time, through
/// [`Aes::encrypt`].
struct AesBackend<'a>(&'a Aes);

impl BlockSizeUser for AesBackend<'_> {
    type BlockSize = <Aes128 as BlockSizeUser>::BlockSize;
}

impl ParBlocksSizeUser for AesBackend<'_> {
    type ParBlocksSize = U1;
}

impl BlockBackend for AesBackend<'_> {
    fn proc_block(&mut self, mut block: InOut<'_, '_, Block<Self>>) {
        let mut b = block.clone_in();
        self.0.encrypt(&mut b);
        *block.get_out() = b;
    }
}

/// Bytes of an AES block.
const AES_BLOCK_BYTES: usize = 16;

/// The CMAC engine: AES-128's key schedule and the CMAC's running state (the
/// cmac crate's block-level CMAC, fed a block at a time from the bytes kept
/// here). One serves every stream of a side of the link that runs in one task
/// (a tag is computed from start to end within a call).
#[derive(Clone)]
pub struct LinkMac {
    /// CMAC over AES-128 under the link key: the chaining state.
    core: CmacCore<Aes>,
    /// Bytes of the MAC input not yet through the cipher: the last block is
    /// kept until the input ends or another byte follows, as CMAC treats a
    /// whole last block apart.
    block: [u8; AES_BLOCK_BYTES],
    /// Bytes of `block` in use, `0..=16`.
    len: u8,
}

impl LinkMac {
    /// The engine for `key` (computes AES's key schedule).
    pub fn new(key: &LinkKey) -> Self {
        Self {
            // The aes crate's key schedule: loops of 10 rounds (its `0..10` and
            // `1..11`) and of 2 (its `(8..72).step_by(32)`).
            // wcet-bound: 10
            core: CmacCore::inner_init(Aes(Aes128::new(&(*key).into()))),
            block: [0; AES_BLOCK_BYTES],
            len: 0,
        }
    }

    /// Starts a tag on `stream`: the state reset (whatever an interrupted tag
    /// left), then the stream's Data ID.
    pub(super) fn begin(&mut self, stream: Stream) {
        Reset::reset(&mut self.core);
        self.block[0] = stream.data_id();
        self.len = 1;
    }

    /// Runs the kept (full) block through the cipher. Not inlined: each caller's
    /// line is where the timing analysis counts its blocks.
    #[inline(never)]
    fn process_block(&mut self) {
        self.core
            .update_blocks(core::slice::from_ref(&self.block.into()));
        self.len = 0;
    }

    /// Adds one byte to the MAC input ([`super::encode`]: postcard writes a byte
    /// at a time). A full block goes through the cipher once a byte follows it
    /// (CMAC treats a whole last block apart).
    #[inline(always)]
    pub(super) fn push(&mut self, byte: u8) {
        if usize::from(self.len) >= AES_BLOCK_BYTES {
            // A block goes through the cipher when a byte follows 16 held: with the
            // Data ID held from `begin`, at most (M − 1) / 16 times for a MAC input
            // of M bytes (the last block goes in `finish`). The control task
            // encodes one frame (an `Up`) per activation; the plan task encodes
            // none.
            // wcet-bound: (MAX_UP_MAC_INPUT_BYTES - 1) / 16 times per activation
            self.process_block();
        }
        if let Some(slot) = self.block.get_mut(usize::from(self.len)) {
            *slot = byte;
            self.len += 1;
        }
    }

    /// Adds `bytes` to the MAC input ([`super::decode`]: the frame is whole), a
    /// block per pass. Always inlined: the bound on its loop is the caller's
    /// frame (`decode`'s, inlined in turn).
    #[inline(always)]
    pub(super) fn update(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            if usize::from(self.len) >= AES_BLOCK_BYTES {
                self.process_block();
            }
            let free = self
                .block
                .get_mut(usize::from(self.len)..)
                .unwrap_or_default();
            let take = free.len().min(bytes.len());
            let (now, later) = bytes.split_at(take);
            // At most a block's bytes.
            // wcet-bound: 16
            for (slot, &b) in free.iter_mut().zip(now) {
                *slot = b;
            }
            // A pass per block of the MAC input (the binary's back edge is on this
            // line): with the Data ID held from `begin`, the first pass fills the
            // block, each next one takes 16 bytes, so ⌈M / 16⌉ passes for a MAC
            // input of M bytes. Frames below MAX_FRAME_BYTES, and in the ECU's
            // tasks at most theirs (decode's bounds).
            // wcet-bound: MAX_FRAME_BYTES / 16 + 1
            // wcet-bound in control: (MAX_DRIVING_DOWN_MAC_INPUT_BYTES + 15) / 16
            // wcet-bound in receive: (MAX_DOWN_MAC_INPUT_BYTES + 15) / 16
            self.len += take as u8;
            bytes = later;
        }
    }

    /// The truncated tag of what was added since [`Self::begin`]; the state is
    /// reset.
    pub(super) fn finish(&mut self) -> [u8; MAC_BYTES] {
        let mut last = Buffer::<CmacCore<Aes>>::default();
        last.set(
            self.block.into(),
            usize::from(self.len).min(AES_BLOCK_BYTES),
        );
        let mut full = Output::<CmacCore<Aes>>::default();
        // The last block padded: at most a block's bytes zeroed.
        // wcet-bound: 16 bytes
        self.core.finalize_fixed_core(&mut last, &mut full);
        Reset::reset(&mut self.core);
        self.len = 0;
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
