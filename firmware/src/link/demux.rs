//! One byte stream, two readers: the frames of a link shared by both tasks (one
//! USART) sorted, byte by byte as they arrive, into the control task's channel
//! (sensor, stop and set-up frames) and the plan task's route channel (the
//! windows of the road: `PathChunk` and `Window` frames).
//!
//! A frame is told by its first three bytes: the COBS code byte, the version byte
//! and the message's tag (the postcard variant index of [`Down`]), which COBS
//! leaves in place when neither is zero (a code byte of 2 says the tag is zero:
//! `Config`; of 1, that the version is zero: no valid frame, given to the control
//! channel, whose reader refuses it). Its bytes then go to one channel up to its
//! delimiter, which goes with them. The work per byte is constant, so an
//! interrupt handler can run it.

use super::Down;

/// Where a frame's bytes go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    /// The control task's: sensor frames, `Stop`, the set-up's frames.
    Control,
    /// The plan task's: the windows of the road (`PathChunk`, `Window`).
    Route,
}

/// Postcard tag of [`Down::PathChunk`] (its variant index).
pub const PATH_CHUNK_TAG: u8 = 1;
/// Postcard tag of [`Down::Window`] (its variant index).
pub const WINDOW_TAG: u8 = 6;

/// The channel of a frame whose first bytes are `head` (code, version, tag).
fn channel_of(head: [u8; 3]) -> Channel {
    let tag = match head[0] {
        // A zero right after the version: the tag is 0 (`Config`).
        2 => 0,
        // The version is zero, or the frame is empty: no valid frame.
        0 | 1 => return Channel::Control,
        _ => head[2],
    };
    if tag == PATH_CHUNK_TAG || tag == WINDOW_TAG {
        Channel::Route
    } else {
        Channel::Control
    }
}

/// Bytes to hand to one channel after a byte was pushed: at most three (a frame's
/// head of three when its third byte arrives, or a short frame's head of at most
/// two and its delimiter); `bytes` has room for four.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Emit {
    /// Their channel.
    pub channel: Channel,
    /// The bytes, `bytes[..len]`.
    pub bytes: [u8; 4],
    /// How many.
    pub len: usize,
}

impl Emit {
    /// The bytes to hand over.
    pub fn bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }
}

/// The sorter's state between two bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Demux {
    /// The current frame's first bytes while it is not yet told.
    head: [u8; 3],
    /// How many of them arrived.
    head_len: usize,
    /// The current frame's channel, once told.
    channel: Option<Channel>,
}

impl Default for Demux {
    fn default() -> Self {
        Self::new()
    }
}

impl Demux {
    /// Between frames (a valid `const` initialiser).
    pub const fn new() -> Self {
        Self {
            head: [0; 3],
            head_len: 0,
            channel: None,
        }
    }

    /// Feeds one byte of the stream: the bytes to hand to a channel now, if any.
    pub fn push(&mut self, byte: u8) -> Option<Emit> {
        let one = |channel, b| Emit {
            channel,
            bytes: [b, 0, 0, 0],
            len: 1,
        };
        if let Some(channel) = self.channel {
            if byte == 0 {
                *self = Self::new();
            }
            return Some(one(channel, byte));
        }
        if byte == 0 {
            // A frame shorter than its head (or idle delimiters): the bytes so
            // far and the delimiter to the control channel, whose reader refuses
            // a frame this short and skips an empty one.
            let mut bytes = [0u8; 4];
            let mut len = 0;
            for (slot, &b) in bytes.iter_mut().zip(self.head.iter().take(self.head_len)) {
                *slot = b;
                len += 1;
            }
            *self = Self::new();
            // The delimiter: `bytes[len]` is already 0.
            return Some(Emit {
                channel: Channel::Control,
                bytes,
                len: len + 1,
            });
        }
        if let Some(slot) = self.head.get_mut(self.head_len) {
            *slot = byte;
            self.head_len += 1;
        }
        if self.head_len < 3 {
            return None;
        }
        let channel = channel_of(self.head);
        self.channel = Some(channel);
        Some(Emit {
            channel,
            bytes: [self.head[0], self.head[1], self.head[2], 0],
            len: 3,
        })
    }
}

/// A [`Demux`] that hands over one byte per byte pushed, at most: the bytes it
/// gives at once (a frame's head when its channel is told, a short frame and its
/// delimiter) wait and leave one per push, and [`Sorter::take_held`] hands over
/// what still waits (at most [`Sorter::MAX_HELD_AFTER_PUSH`]) once a batch of
/// bytes is pushed. Each channel gets the same bytes in the same order as from
/// the [`Demux`] alone, only in the batch's last steps rather than at once, so
/// that the work per byte is one hand-over (the flashed ECU's sorting loop,
/// whose timing bound is then one queue push per byte, not a head's three).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sorter {
    /// Where the frames' bytes are told.
    demux: Demux,
    /// The bytes told and waiting, the next in the low byte: at most three
    /// (a head of three is told with nothing waiting; a short frame of `h`
    /// head bytes and its delimiter, with at most `2 − h` waiting).
    held: u32,
    /// Bit `k` set: the `k`-th waiting byte is the route channel's.
    route: u32,
    /// How many wait, `0..=3`.
    len: u32,
}

impl Default for Sorter {
    fn default() -> Self {
        Self::new()
    }
}

impl Sorter {
    /// Bytes waiting after a push at most: each push adds a byte to the head or
    /// to the waiting ones and, when some were waiting, hands one over, so the
    /// two hold two at most together (a head of three is told at once, with
    /// nothing waiting: the two bytes before the tag were the head).
    pub const MAX_HELD_AFTER_PUSH: usize = 2;

    /// Nothing held (a valid `const` initialiser).
    pub const fn new() -> Self {
        Self {
            demux: Demux::new(),
            held: 0,
            route: 0,
            len: 0,
        }
    }

    /// Feeds one byte of the stream: the next byte to hand to a channel, if any.
    /// Branch-free bookkeeping: the told bytes join the waiting ones as a word.
    pub fn push(&mut self, byte: u8) -> Option<(Channel, u8)> {
        if let Some(e) = self.demux.push(byte) {
            // At most three bytes, and at most three wait with them (the
            // invariant above): the shifts stay within the word.
            let n = e.len.min(3) as u32;
            let at = self.len.min(3);
            let mask = (1u32 << (8 * n)) - 1;
            self.held |= (u32::from_le_bytes(e.bytes) & mask) << (8 * at);
            let to_route = u32::from(e.channel == Channel::Route);
            self.route |= (((1u32 << n) - 1) * to_route) << at;
            self.len += n;
        }
        self.take_held()
    }

    /// The next byte told and not yet handed over, if any: after a batch of
    /// pushes, call it until `None` (at most [`Self::MAX_HELD_AFTER_PUSH`]
    /// times) to hand over every byte whose channel is told.
    pub fn take_held(&mut self) -> Option<(Channel, u8)> {
        if self.len == 0 {
            return None;
        }
        let b = self.held as u8;
        let channel = if self.route & 1 == 1 {
            Channel::Route
        } else {
            Channel::Control
        };
        self.held >>= 8;
        self.route >>= 1;
        self.len -= 1;
        Some((channel, b))
    }
}

/// The channel [`Demux`] gives a frame of `msg` (its route frames to the plan
/// task, the others to the control task).
pub fn channel_of_message(msg: &Down) -> Channel {
    match msg {
        Down::PathChunk(_) | Down::Window(_) => Channel::Route,
        _ => Channel::Control,
    }
}
