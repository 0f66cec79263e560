//! A frame on the wire (see [`super`]'s *Wire format*): [`encode`] and
//! [`decode`] of one authenticated frame ([`secoc`]), the stream's splitting into
//! frames ([`FrameReader`]), the sequence check and the counts of refused frames.

use super::*;
/// Why a frame was refused (each counted by the receiver, never a panic), or
/// could not be encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// [`decode`] was given no bytes.
    Empty,
    /// More bytes than fit arrived before a delimiter ([`FrameReader`]), or a frame
    /// longer than `MAX_FRAME_BYTES − 1` ([`decode`]).
    TooLong,
    /// The COBS encoding is invalid (a 0x00 inside, or a block past the end).
    Cobs,
    /// The decoded frame is shorter than a version byte, a freshness value, a tag
    /// and a CRC.
    TooShort,
    /// The frame is of another version of this format.
    Version {
        /// The version byte received.
        got: u8,
    },
    /// The CRC does not match.
    Checksum,
    /// The tag does not verify: the frame was not sent under the receiver's key
    /// on this stream ([`secoc`]).
    Authentication,
    /// The frame is authentic but its freshness is not newer than the last one
    /// the receiver accepted on this stream: a replay ([`secoc`]).
    Replay {
        /// The frame's freshness value.
        freshness: u32,
        /// The last freshness value accepted.
        last: u32,
    },
    /// postcard could not decode the message, or bytes trail it.
    Malformed,
    /// [`encode`]'s output buffer is too small (see [`MAX_FRAME_BYTES`]).
    BufferTooSmall,
    /// [`encode`]: the stream's freshness counter is at `u32::MAX`; a new key
    /// (and counters) is needed to send more.
    FreshnessExhausted,
}

impl FrameError {
    /// The variant's name, for logs.
    pub const fn name(self) -> &'static str {
        match self {
            FrameError::Empty => "Empty",
            FrameError::TooLong => "TooLong",
            FrameError::Cobs => "Cobs",
            FrameError::TooShort => "TooShort",
            FrameError::Version { .. } => "Version",
            FrameError::Checksum => "Checksum",
            FrameError::Authentication => "Authentication",
            FrameError::Replay { .. } => "Replay",
            FrameError::Malformed => "Malformed",
            FrameError::BufferTooSmall => "BufferTooSmall",
            FrameError::FreshnessExhausted => "FreshnessExhausted",
        }
    }

    /// The reason a receiver counts this refusal under: [`Refusal::Auth`] for
    /// [`FrameError::Authentication`], [`Refusal::Replay`] for
    /// [`FrameError::Replay`], [`Refusal::Corrupt`] for the others (the frame was
    /// not a well-formed frame of this version; [`encode`]'s own two errors, which
    /// no receiver sees, are sorted there too).
    pub const fn refusal(self) -> Refusal {
        match self {
            FrameError::Authentication => Refusal::Auth,
            FrameError::Replay { .. } => Refusal::Replay,
            _ => Refusal::Corrupt,
        }
    }
}

/// Encodes `msg` as one whole frame (see the module docs) into `out`, the 0x00
/// delimiter included, authenticated on `tx`'s stream with `mac` and the stream's
/// next freshness value (taken only when the frame is encoded); returns the
/// frame's length, bytes. A buffer of [`MAX_FRAME_BYTES`] holds any [`Down`] or
/// [`Up`]. In three passes over `out`, no other buffer: postcard writes the
/// version byte and the message a little way into it (past the room COBS adds,
/// [`cobs_lead`]), the freshness value follows, then the tag of those bytes
/// (the MAC takes them a block at a time) and the CRC of all of them; COBS then
/// encodes them forward in place ([`cobs_encode_in_place`]). Each pass is one
/// short loop over the bytes, where a flavour chain would take each byte
/// through every stage in turn. Not inlined: one function in every build, whose
/// loops the timing analysis bounds by the ECU's largest frame (it sends only
/// `Up` frames).
#[inline(never)]
pub fn encode<M: Serialize + ?Sized>(
    msg: &M,
    mac: &mut LinkMac,
    tx: &mut Authenticator,
    out: &mut [u8],
) -> Result<usize, FrameError> {
    let freshness = tx.next()?;
    let lead = cobs_lead(out.len());
    let body = out.get_mut(lead..).ok_or(FrameError::BufferTooSmall)?;
    // postcard writes a `u8` as its one byte: the tuple is the version byte, then
    // the message.
    let n = match postcard::serialize_with_flavor(&(LINK_VERSION, msg), Plain::new(body)) {
        Ok(n) => n,
        Err(postcard::Error::SerializeBufferFull) => return Err(FrameError::BufferTooSmall),
        Err(_) => return Err(FrameError::Malformed),
    };
    let raw_len = n + SECURED_BYTES + CRC_BYTES;
    let raw = body.get_mut(..raw_len).ok_or(FrameError::BufferTooSmall)?;
    // No slicing or copy that can panic: the panic path sends through here.
    let (body, check) = raw
        .split_at_mut_checked(n + SECURED_BYTES)
        .ok_or(FrameError::BufferTooSmall)?;
    let (input, tag) = body
        .split_at_mut_checked(n + FRESHNESS_BYTES)
        .ok_or(FrameError::BufferTooSmall)?;
    for (d, s) in input.iter_mut().skip(n).zip(freshness.to_le_bytes()) {
        *d = s;
    }
    for (d, s) in tag.iter_mut().zip(mac.tag(tx.stream(), input)) {
        *d = s;
    }
    let mut crc = CRC32_INIT;
    // The version, the message, the freshness value and the tag (what
    // `decode` checks the CRC over): at most a frame's bytes, and the control
    // task encodes one frame (an `Up`) per activation; the plan task encodes
    // none.
    // wcet-bound: MAX_UP_FRAME_BYTES per activation
    crc32_update!(crc, body.iter());
    for (d, s) in check.iter_mut().zip((!crc).to_le_bytes()) {
        *d = s;
    }
    let len = cobs_encode_in_place(out, lead, raw_len)?;
    tx.commit(freshness);
    Ok(len)
}

/// Bytes ahead of the raw frame in a buffer of `buf_len` bytes from which
/// [`cobs_encode_in_place`] encodes it forward: COBS writes one code byte
/// before the data and one more per 254 bytes of data without a zero, so the
/// output is never more than that many bytes ahead of the input (one, and one
/// per 254 bytes of a raw frame shorter than the buffer).
pub const fn cobs_lead(buf_len: usize) -> usize {
    1 + buf_len.saturating_sub(1) / 254
}

// The largest frames fit with their lead: the raw frame of the largest payload
// and its lead within the frame's size.
const _: () = {
    let up_raw = 1 + MAX_UP_PAYLOAD_BYTES + SECURED_BYTES + CRC_BYTES;
    assert!(cobs_lead(MAX_UP_FRAME_BYTES) + up_raw <= MAX_UP_FRAME_BYTES);
    let down_raw = 1 + MAX_DOWN_PAYLOAD_BYTES + SECURED_BYTES + CRC_BYTES;
    assert!(cobs_lead(MAX_DOWN_FRAME_BYTES) + down_raw <= MAX_DOWN_FRAME_BYTES);
};

/// COBS-encodes the `len` bytes at `buf[lead..]` into `buf` from its start, the
/// delimiter appended (the `cobs` crate's encoder state, as postcard's `Cobs`
/// flavour drives it: the same bytes); returns the frame's length with the
/// delimiter, bytes. With `lead` from [`cobs_lead`] the output never overtakes
/// the input: each byte is read before its place is written.
fn cobs_encode_in_place(buf: &mut [u8], lead: usize, len: usize) -> Result<usize, FrameError> {
    use cobs::PushResult;
    let mut state = cobs::EncoderState::default();
    // Index 0 holds the first block's code byte, written when the block ends.
    let mut write = 1;
    // A byte of the frame per pass, at most a frame's, one frame per
    // activation of the control task (as `encode`'s CRC).
    // wcet-bound: MAX_UP_FRAME_BYTES per activation
    for read in lead..lead.saturating_add(len) {
        let byte = *buf.get(read).ok_or(FrameError::BufferTooSmall)?;
        let (at, code, data) = match state.push(byte) {
            PushResult::AddSingle(b) => (None, 0, Some(b)),
            PushResult::ModifyFromStartAndSkip((i, code)) => (Some(i), code, None),
            PushResult::ModifyFromStartAndPushAndSkip((i, code, b)) => (Some(i), code, Some(b)),
        };
        if let Some(i) = at {
            *buf.get_mut(i).ok_or(FrameError::BufferTooSmall)? = code;
        }
        if let Some(b) = data {
            *buf.get_mut(write).ok_or(FrameError::BufferTooSmall)? = b;
            write += 1;
        }
        // A block ended: the next block's code byte is the next place.
        write += usize::from(at.is_some());
    }
    let (i, code) = state.finalize();
    *buf.get_mut(i).ok_or(FrameError::BufferTooSmall)? = code;
    *buf.get_mut(write).ok_or(FrameError::BufferTooSmall)? = 0;
    Ok(write + 1)
}

/// The output of [`encode`]'s first pass: postcard's bytes into a fixed buffer,
/// a push past its end refused. Its `try_extend` copies a byte per pass, so the
/// timing analysis bounds the bytes of every slice postcard hands over together.
struct Plain<'a> {
    /// The frame's bytes.
    buf: &'a mut [u8],
    /// Bytes written.
    len: usize,
}

impl<'a> Plain<'a> {
    fn new(buf: &'a mut [u8]) -> Self {
        Self { buf, len: 0 }
    }
}

impl postcard::ser_flavors::Flavor for Plain<'_> {
    /// The bytes written.
    type Output = usize;

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        let slot = self
            .buf
            .get_mut(self.len)
            .ok_or(postcard::Error::SerializeBufferFull)?;
        *slot = data;
        self.len += 1;
        Ok(())
    }

    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        // The bytes of every slice of the frame: at most a frame's, one frame
        // per activation of the control task (as `encode`'s CRC), summed over
        // the copies of this loop in postcard's field writers (one counter). A
        // push per byte, not a block copy of a length the analysis cannot see.
        // wcet-bound: MAX_UP_FRAME_BYTES per activation, counted in frame_slices
        for &b in data {
            self.try_push(b)?;
        }
        Ok(())
    }

    fn finalize(self) -> postcard::Result<usize> {
        Ok(self.len)
    }
}

/// Decodes COBS in place with the `cobs` crate's decoder, one byte at a time (its
/// step is constant: the loop is the only one); returns the decoded length, bytes.
/// The output never overtakes the input: each byte read gives at most one byte.
fn cobs_decode_in_place(buf: &mut [u8]) -> Result<usize, FrameError> {
    let mut state = cobs::DecoderState::Idle;
    let mut write = 0;
    // len < MAX_FRAME_BYTES: decode, the only caller, refuses longer frames. The
    // ECU's tasks decode what their frame readers return: the control task's sensor
    // frames, in its handler (`in control`), at most MAX_DRIVING_DOWN_FRAME_BYTES (its
    // `Link::receive_sensor` stops a frame there); the plan task's window, in
    // `RouteLink::receive`, at most MAX_DOWN_FRAME_BYTES (its reader's size).
    // wcet-bound: MAX_FRAME_BYTES
    // wcet-bound in control: MAX_DRIVING_DOWN_FRAME_BYTES
    // wcet-bound in receive: MAX_DOWN_FRAME_BYTES
    for read in 0..buf.len() {
        let byte = match buf.get(read) {
            Some(&b) if b != 0 => b,
            _ => return Err(FrameError::Cobs),
        };
        match state.feed(byte) {
            Ok(cobs::DecodeResult::DataContinue(out)) => {
                match buf.get_mut(write) {
                    Some(slot) => *slot = out,
                    None => return Err(FrameError::Cobs),
                }
                write += 1;
            }
            Ok(cobs::DecodeResult::NoData) => {}
            Ok(cobs::DecodeResult::DataComplete) | Err(_) => return Err(FrameError::Cobs),
        }
    }
    // The delimiter ends the frame: complete only where the last block ends.
    match state.feed(0) {
        Ok(cobs::DecodeResult::DataComplete) => Ok(write),
        _ => Err(FrameError::Cobs),
    }
}

/// Decodes one frame: `frame` is the bytes between two delimiters (no 0x00).
/// Undoes COBS in place (so `frame` is overwritten), then checks the length, the
/// version, the CRC, the tag (with `mac` on `rx`'s stream), the freshness (newer
/// than the last `rx` accepted), and that postcard consumes the payload exactly;
/// `rx` takes the frame's freshness only when all hold. Always inlined: each of
/// the ECU's callers has its own largest frame, which bounds the loops in the
/// timing analysis (the `wcet-bound in` annotations below).
#[inline(always)]
pub fn decode<'a, M: Deserialize<'a>>(
    frame: &'a mut [u8],
    mac: &mut LinkMac,
    rx: &mut Verifier,
) -> Result<M, FrameError> {
    if frame.is_empty() {
        return Err(FrameError::Empty);
    }
    if frame.len() >= MAX_FRAME_BYTES {
        return Err(FrameError::TooLong);
    }
    let n = cobs_decode_in_place(frame)?;
    let frame: &'a [u8] = frame;
    let raw = frame.get(..n).ok_or(FrameError::Cobs)?;
    if raw.len() < 1 + SECURED_BYTES + CRC_BYTES {
        return Err(FrameError::TooShort);
    }
    let (body, crc) = raw
        .split_at_checked(raw.len() - CRC_BYTES)
        .ok_or(FrameError::TooShort)?;
    let version = *body.first().ok_or(FrameError::TooShort)?;
    if version != LINK_VERSION {
        return Err(FrameError::Version { got: version });
    }
    let crc: [u8; CRC_BYTES] = crc.try_into().map_err(|_| FrameError::TooShort)?;
    let mut register = CRC32_INIT;
    // The CRC's loop takes a byte of `body` (< MAX_FRAME_BYTES, and in the ECU's
    // tasks at most what `cobs_decode_in_place` states) per iteration.
    // wcet-bound: MAX_FRAME_BYTES
    // wcet-bound in control: MAX_DRIVING_DOWN_FRAME_BYTES
    // wcet-bound in receive: MAX_DOWN_FRAME_BYTES
    crc32_update!(register, body);
    if !register != u32::from_le_bytes(crc) {
        return Err(FrameError::Checksum);
    }
    // body = version ++ payload ++ freshness ++ tag; the MAC input is all but the tag.
    let (input, tag) = body
        .split_at_checked(body.len() - MAC_BYTES)
        .ok_or(FrameError::TooShort)?;
    let tag: &[u8; MAC_BYTES] = tag.try_into().map_err(|_| FrameError::TooShort)?;
    if !mac.verify(rx.stream(), input, tag) {
        return Err(FrameError::Authentication);
    }
    let (versioned, freshness) = input
        .split_at_checked(input.len() - FRESHNESS_BYTES)
        .ok_or(FrameError::TooShort)?;
    let freshness: [u8; FRESHNESS_BYTES] =
        freshness.try_into().map_err(|_| FrameError::TooShort)?;
    let freshness = u32::from_le_bytes(freshness);
    rx.check(freshness)?;
    let payload = versioned.get(1..).ok_or(FrameError::TooShort)?;
    match postcard::take_from_bytes::<M>(payload) {
        Ok((msg, [])) => {
            rx.commit(freshness);
            Ok(msg)
        }
        _ => Err(FrameError::Malformed),
    }
}

// ---------------------------------------------------------------------------
// Stream framing and bookkeeping
// ---------------------------------------------------------------------------

/// Splits a byte stream into frames at 0x00 delimiters with a fixed buffer of `N`
/// bytes (use `N = MAX_FRAME_BYTES`); over-long frames are dropped (and reported
/// as [`FrameError::TooLong`] once their delimiter arrives). Empty frames (two
/// delimiters in a row) yield nothing.
pub struct FrameReader<const N: usize> {
    /// The frame being received (COBS-encoded, without the delimiter).
    buf: [u8; N],
    /// Bytes of `buf` in use.
    len: usize,
    /// The current frame overflowed `buf`; it is skipped until its delimiter.
    overflowed: bool,
}

impl<const N: usize> FrameReader<N> {
    /// An empty reader (a valid `const` initialiser).
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflowed: false,
        }
    }

    /// Feeds one byte; at a delimiter returns the frame's bytes (for [`decode`],
    /// which decodes them in place) or `TooLong`; otherwise `None`.
    pub fn push(&mut self, byte: u8) -> Option<Result<&mut [u8], FrameError>> {
        if byte == 0 {
            let len = core::mem::replace(&mut self.len, 0);
            if core::mem::replace(&mut self.overflowed, false) {
                return Some(Err(FrameError::TooLong));
            }
            if len == 0 {
                return None;
            }
            return Some(self.buf.get_mut(..len).ok_or(FrameError::TooLong));
        }
        if !self.overflowed {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => {
                    self.overflowed = true;
                    self.len = 0;
                }
            }
        }
        None
    }

    /// Bytes of the frame being received, bytes (0 while skipping an over-long one).
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Drops the frame being received (e.g. after a link reset).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// A [`FrameReader`] that keeps the newest whole frame for a reader that takes
/// one frame per period from a stream that may hold several (a real-time link:
/// a frame late for its period and the next one's, both whole at the next
/// release). Two buffers of `N` bytes: one holds the newest whole frame while
/// the other receives the next, so no byte is copied. Work per byte is
/// constant.
pub struct NewestFrameReader<const N: usize> {
    /// The two buffers.
    readers: [FrameReader<N>; 2],
    /// The one receiving the next frame (0 or 1).
    cur: usize,
    /// The newest whole frame not taken yet: its buffer and length, bytes.
    newest: Option<(usize, usize)>,
}

impl<const N: usize> NewestFrameReader<N> {
    /// An empty reader (a valid `const` initialiser).
    pub const fn new() -> Self {
        Self {
            readers: [FrameReader::new(), FrameReader::new()],
            cur: 0,
            newest: None,
        }
    }

    /// Feeds one byte. At a delimiter that ends a whole frame, that frame is now
    /// the newest (one older, not taken, is dropped) and `Some(Ok(()))`; at one
    /// that ends an over-long frame, `Some(Err(TooLong))` and no frame is the
    /// newest (the newest is that refused one); otherwise `None` (inside a frame,
    /// or two delimiters in a row).
    pub fn push(&mut self, byte: u8) -> Option<Result<(), FrameError>> {
        let cur = self.cur & 1;
        let ended = match self.readers.get_mut(cur)?.push(byte)? {
            Ok(frame) => Ok(frame.len()),
            Err(e) => Err(e),
        };
        match ended {
            Ok(len) => {
                self.newest = Some((cur, len));
                // The other buffer receives the next frame (what it held, an older
                // frame, is superseded).
                self.cur = cur ^ 1;
                if let Some(next) = self.readers.get_mut(self.cur) {
                    next.reset();
                }
                Some(Ok(()))
            }
            Err(e) => {
                self.newest = None;
                Some(Err(e))
            }
        }
    }

    /// The newest whole frame pushed since the last call, its bytes for
    /// [`decode`] (which decodes them in place); `None` when none ended since.
    /// A frame still arriving is kept for the next call.
    pub fn take_newest(&mut self) -> Option<&mut [u8]> {
        let (i, len) = self.newest.take()?;
        self.readers.get_mut(i)?.buf.get_mut(..len)
    }

    /// Drops everything received, whole or not.
    pub fn reset(&mut self) {
        let [a, b] = &mut self.readers;
        a.reset();
        b.reset();
        self.newest = None;
    }
}

impl<const N: usize> Default for NewestFrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// Why [`SequenceCheck::accept`] refused a sequence number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SequenceError {
    /// `seq ≤ last`: a duplicate or an older frame.
    Stale,
}

/// Detects stale (duplicate or older) and skipped sequence numbers. Sequence
/// numbers do not wrap (a `u32` at 100 Hz lasts 497 days).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SequenceCheck {
    /// The last accepted sequence number, if any.
    last: Option<u32>,
}

impl SequenceCheck {
    /// A check that accepts any first sequence number.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// Accepts `seq` when newer than the last accepted one; `Ok(missed)` counts the
    /// sequence numbers skipped (0 in order, > 0 for a gap, which is accepted).
    pub fn accept(&mut self, seq: u32) -> Result<u32, SequenceError> {
        let missed = match self.last {
            None => 0,
            Some(last) if seq <= last => return Err(SequenceError::Stale),
            Some(last) => seq - last - 1,
        };
        self.last = Some(seq);
        Ok(missed)
    }

    /// The last accepted sequence number, if any.
    pub const fn last(&self) -> Option<u32> {
        self.last
    }

    /// Forgets the last sequence number (a new run accepts any first number).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// Counts of a receiver's frames (all saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Frames decoded, frames.
    pub accepted: u32,
    /// Frames refused (any [`FrameError`]), frames.
    pub rejected: u32,
    /// Decoded frames refused as stale (duplicate or older `seq`), frames.
    pub stale: u32,
    /// Gaps in the sequence (each jump counts once, whatever its size), gaps.
    pub gaps: u32,
    /// The refused frames by reason ([`FrameError::refusal`]), frames.
    pub refused: RefusalCounts,
    /// The last refusal, if any.
    pub last_error: Option<FrameError>,
}

impl LinkStats {
    /// All zero.
    pub const fn new() -> Self {
        Self {
            accepted: 0,
            rejected: 0,
            stale: 0,
            gaps: 0,
            refused: RefusalCounts::new(),
            last_error: None,
        }
    }

    /// Counts a frame's outcome ([`decode`]'s or [`FrameReader::push`]'s result).
    pub fn record<T>(&mut self, r: &Result<T, FrameError>) {
        match r {
            Ok(_) => self.accepted = self.accepted.saturating_add(1),
            Err(e) => {
                self.rejected = self.rejected.saturating_add(1);
                self.refused.count(e.refusal());
                self.last_error = Some(*e);
            }
        }
    }

    /// Counts a [`SequenceCheck::accept`] outcome: a stale frame or a gap.
    pub fn record_sequence(&mut self, r: &Result<u32, SequenceError>) {
        match r {
            Err(SequenceError::Stale) => self.stale = self.stale.saturating_add(1),
            Ok(0) => {}
            Ok(_) => self.gaps = self.gaps.saturating_add(1),
        }
    }
}
