//! The capture wire format: how the firmware sends a recorded run (r, y, u and flags at the
//! full loop rate) to the host, and how the host decodes it.
//!
//! This module is the single definition of the format: the firmware encodes with
//! [`encode`], the host's `piezo record` decodes with [`decode`]. Both are allocation-free
//! and never panic on any input.
//!
//! # Frame layout (all integers little-endian)
//! ```text
//!  offset  size  field
//!  0       2     sync: 0xA5 0x5A
//!  2       1     kind: 1 = Start, 2 = Data, 3 = End
//!  3       2     seq: frame sequence number, u16, wraps (Start is 0 of its stream)
//!  5       1     len: payload length in bytes, 0..=MAX_PAYLOAD
//!  6       len   payload
//!  6+len   4     CRC-32 (IEEE 802.3, reflected, init and xorout 0xFFFFFFFF) over bytes 2..6+len
//! ```
//! Payloads:
//! * **Start** (12 bytes): `rate_hz: u32`, `samples: u32` (records in the whole capture),
//!   `first: u32` (index of the first record this stream will send; 0 unless the host asked
//!   for a part).
//! * **Data** (4 + 8 k bytes, 1 <= k <= [`MAX_RECORDS`]): `first_index: u32`, then k
//!   [`Record`]s of 8 bytes: `r: i16`, `y: i16` (16-bit ADC codes over +-10 V), `u: i16`
//!   (14-bit DAC code over +-10 V), `flags: u8` (`limits::Flags`), `faults: u8` (latched faults).
//! * **End** (8 bytes): `samples_sent: u32`, `data_frames: u32` (how many Data frames this
//!   stream carried), so the host can tell a lost tail from a finished stream.
//!
//! # Why this shape
//! * The sync word lets the decoder find frames in a byte stream that also carries text
//!   replies and possibly garbage; the CRC-32 decides. A false sync inside a payload costs one
//!   failed check, after which the decoder skips one byte and hunts again, so one corrupted
//!   frame never takes its neighbours with it.
//! * Each Data frame carries the absolute index of its first record: the host places records
//!   by index, so a lost, duplicated or reordered frame is detected exactly (a gap in the
//!   indices), independently of the sequence number. The sequence number counts frames, so
//!   the host can also report *how many frames* were lost.
//! * 8 bytes per record: 50 000 records (1 s at 50 kHz) are 400 kB; with the 14 bytes of
//!   framing per 30-record frame (5.8 %) that is 423 kB, about 4.6 s at 921 600 baud.
//! * CRC-32 rather than CRC-16: it misses a random corruption with probability 2^-32 (about
//!   1e-10 per frame), and costs nothing that matters at serial speeds. The 1 KiB table is
//!   computed at compile time.

/// First sync byte.
pub const SYNC0: u8 = 0xA5;
/// Second sync byte.
pub const SYNC1: u8 = 0x5A;
/// Bytes before the payload: sync (2), kind (1), seq (2), len (1).
pub const HEADER_LEN: usize = 6;
/// Bytes after the payload: the CRC-32.
pub const CRC_LEN: usize = 4;
/// Records in one Data frame at most.
pub const MAX_RECORDS: usize = 30;
/// Bytes in one record.
pub const RECORD_LEN: usize = 8;
/// Largest payload: a full Data frame (244 bytes).
pub const MAX_PAYLOAD: usize = 4 + MAX_RECORDS * RECORD_LEN;
/// Largest frame on the wire (254 bytes).
pub const MAX_FRAME: usize = HEADER_LEN + MAX_PAYLOAD + CRC_LEN;

const KIND_START: u8 = 1;
const KIND_DATA: u8 = 2;
const KIND_END: u8 = 3;
const START_LEN: usize = 12;
const END_LEN: usize = 8;

/// One captured sample: reference, measurement, command and flags, as converter codes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Record {
    /// Reference, as a 16-bit ADC code over +-10 V (sensor volts).
    pub r: i16,
    /// Measured sensor monitor, the 16-bit ADC code.
    pub y: i16,
    /// Command sent to the amplifier, the 14-bit DAC code over +-10 V.
    pub u: i16,
    /// Per-step conditions (`limits::Flags` bits).
    pub flags: u8,
    /// Latched faults at this step (the controller's fault bits).
    pub faults: u8,
}

impl Record {
    /// The 8 wire bytes.
    pub fn to_bytes(self) -> [u8; RECORD_LEN] {
        let r = self.r.to_le_bytes();
        let y = self.y.to_le_bytes();
        let u = self.u.to_le_bytes();
        [r[0], r[1], y[0], y[1], u[0], u[1], self.flags, self.faults]
    }

    /// The record from its 8 wire bytes.
    pub fn from_bytes(b: [u8; RECORD_LEN]) -> Self {
        Self {
            r: i16::from_le_bytes([b[0], b[1]]),
            y: i16::from_le_bytes([b[2], b[3]]),
            u: i16::from_le_bytes([b[4], b[5]]),
            flags: b[6],
            faults: b[7],
        }
    }
}

/// A decoded Data frame's records, held inline (no allocation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Records {
    buf: [Record; MAX_RECORDS],
    len: u8,
}

impl Records {
    /// The records, in order.
    pub fn as_slice(&self) -> &[Record] {
        self.buf.get(..self.len as usize).unwrap_or(&[])
    }
}

/// What a frame says.
// No allocator: a Data frame's records are held inline on purpose (248 bytes).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// A stream begins.
    Start {
        /// Loop rate the capture was taken at, Hz.
        rate_hz: u32,
        /// Records in the whole capture.
        samples: u32,
        /// Index of the first record this stream sends.
        first: u32,
    },
    /// Records `first_index ..` of the capture.
    Data {
        /// Index of the first record in this frame.
        first_index: u32,
        /// The records.
        records: Records,
    },
    /// A stream ends.
    End {
        /// Records sent in this stream.
        samples_sent: u32,
        /// Data frames sent in this stream.
        data_frames: u32,
    },
}

/// A frame as the encoder takes it (records borrowed).
#[derive(Clone, Copy, Debug)]
pub enum FrameRef<'a> {
    /// See [`Frame::Start`].
    Start {
        /// Loop rate, Hz.
        rate_hz: u32,
        /// Records in the whole capture.
        samples: u32,
        /// First record this stream sends.
        first: u32,
    },
    /// See [`Frame::Data`]; at most [`MAX_RECORDS`] records, at least one.
    Data {
        /// Index of the first record.
        first_index: u32,
        /// The records.
        records: &'a [Record],
    },
    /// See [`Frame::End`].
    End {
        /// Records sent in this stream.
        samples_sent: u32,
        /// Data frames sent in this stream.
        data_frames: u32,
    },
}

/// Why a frame could not be encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncodeError {
    /// The output buffer is shorter than the frame.
    BufferTooSmall,
    /// A Data frame with no records or more than [`MAX_RECORDS`].
    BadRecordCount,
}

/// Why bytes were skipped while decoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// Bytes before a sync word (text, noise or the rest of a broken frame).
    NoSync,
    /// The length byte exceeds [`MAX_PAYLOAD`].
    BadLength,
    /// The CRC did not match: the frame was corrupted.
    BadCrc,
    /// The CRC matched but the kind is unknown or the payload length does not fit the kind.
    BadPayload,
}

/// The result of one [`decode`] call.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoded {
    /// The input holds the start of a frame (or nothing): read more bytes and call again.
    /// At the end of the stream, a non-empty remainder is a truncated frame.
    NeedMore,
    /// A frame was decoded from the first `consumed` bytes.
    Frame {
        /// The frame.
        frame: Frame,
        /// Its sequence number.
        seq: u16,
        /// Bytes to drop from the front of the input.
        consumed: usize,
    },
    /// The first `consumed` bytes are not a frame (`consumed >= 1`): drop them and call again.
    Skip {
        /// Why.
        error: DecodeError,
        /// Bytes to drop from the front of the input.
        consumed: usize,
    },
}

const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// CRC-32 (IEEE 802.3) of `bytes`; `crc32(b"123456789") == 0xCBF43926`.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c = CRC_TABLE[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    c ^ 0xFFFF_FFFF
}

/// Encodes `frame` with sequence number `seq` into `out`; returns the number of bytes
/// written.
///
/// ```
/// use model_core::frame::{decode, encode, Decoded, Frame, FrameRef, Record, MAX_FRAME};
/// let recs = [Record { r: 1, y: -2, u: 3, flags: 4, faults: 0 }];
/// let mut buf = [0u8; MAX_FRAME];
/// let n = encode(&FrameRef::Data { first_index: 7, records: &recs }, 9, &mut buf).unwrap();
/// match decode(&buf[..n]) {
///     Decoded::Frame { frame: Frame::Data { first_index, records }, seq, consumed } => {
///         assert_eq!((first_index, seq, consumed), (7, 9, n));
///         assert_eq!(records.as_slice(), &recs);
///     }
///     other => panic!("{other:?}"),
/// }
/// ```
pub fn encode(frame: &FrameRef<'_>, seq: u16, out: &mut [u8]) -> Result<usize, EncodeError> {
    let (kind, payload_len) = match frame {
        FrameRef::Start { .. } => (KIND_START, START_LEN),
        FrameRef::Data { records, .. } => {
            if records.is_empty() || records.len() > MAX_RECORDS {
                return Err(EncodeError::BadRecordCount);
            }
            (KIND_DATA, 4 + records.len() * RECORD_LEN)
        }
        FrameRef::End { .. } => (KIND_END, END_LEN),
    };
    let total = HEADER_LEN + payload_len + CRC_LEN;
    let out = out.get_mut(..total).ok_or(EncodeError::BufferTooSmall)?;
    let (head, rest) = out.split_at_mut(HEADER_LEN);
    let (payload, crc_out) = rest.split_at_mut(payload_len);
    let s = seq.to_le_bytes();
    head.copy_from_slice(&[SYNC0, SYNC1, kind, s[0], s[1], payload_len as u8]);
    match frame {
        FrameRef::Start {
            rate_hz,
            samples,
            first,
        } => {
            put_u32s(payload, &[*rate_hz, *samples, *first]);
        }
        FrameRef::Data {
            first_index,
            records,
        } => {
            let (idx, body) = payload.split_at_mut(4);
            idx.copy_from_slice(&first_index.to_le_bytes());
            for (chunk, rec) in body.chunks_exact_mut(RECORD_LEN).zip(records.iter()) {
                chunk.copy_from_slice(&rec.to_bytes());
            }
        }
        FrameRef::End {
            samples_sent,
            data_frames,
        } => {
            put_u32s(payload, &[*samples_sent, *data_frames]);
        }
    }
    // The CRC covers kind, seq, len and the payload.
    let mut c = 0xFFFF_FFFFu32;
    for &b in head[2..].iter().chain(payload.iter()) {
        c = CRC_TABLE[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    crc_out.copy_from_slice(&(c ^ 0xFFFF_FFFF).to_le_bytes());
    Ok(total)
}

fn put_u32s(out: &mut [u8], values: &[u32]) {
    for (chunk, v) in out.chunks_exact_mut(4).zip(values) {
        chunk.copy_from_slice(&v.to_le_bytes());
    }
}

fn get_u32(b: &[u8], at: usize) -> u32 {
    match b.get(at..at + 4) {
        Some(&[a, b1, c, d]) => u32::from_le_bytes([a, b1, c, d]),
        _ => 0,
    }
}

/// Decodes the frame at the front of `input`, or says how many bytes to skip, or asks for
/// more. Call it in a loop, dropping `consumed` bytes each time, until [`Decoded::NeedMore`].
///
/// Never panics and never consumes more than `input.len()` bytes. `NeedMore` is returned only
/// when `input` is empty, is a lone `SYNC0`, or begins with a sync word and is shorter than
/// the frame its header announces; so at most [`MAX_FRAME`] - 1 bytes are ever held back.
pub fn decode(input: &[u8]) -> Decoded {
    // Hunt for the sync word.
    let Some(start) = input.windows(2).position(|w| w == [SYNC0, SYNC1]) else {
        // Keep a trailing SYNC0: it may be the first half of a sync word.
        let keep = usize::from(input.last() == Some(&SYNC0));
        let drop = input.len() - keep;
        return if drop == 0 {
            Decoded::NeedMore
        } else {
            Decoded::Skip {
                error: DecodeError::NoSync,
                consumed: drop,
            }
        };
    };
    if start > 0 {
        return Decoded::Skip {
            error: DecodeError::NoSync,
            consumed: start,
        };
    }
    let Some(header) = input.get(..HEADER_LEN) else {
        return Decoded::NeedMore;
    };
    let kind = header[2];
    let seq = u16::from_le_bytes([header[3], header[4]]);
    let len = header[5] as usize;
    if len > MAX_PAYLOAD {
        // Skip the first sync byte only: a real frame may start inside these bytes.
        return Decoded::Skip {
            error: DecodeError::BadLength,
            consumed: 1,
        };
    }
    let total = HEADER_LEN + len + CRC_LEN;
    let Some(frame_bytes) = input.get(..total) else {
        return Decoded::NeedMore;
    };
    let body = &frame_bytes[2..HEADER_LEN + len];
    let crc = get_u32(frame_bytes, HEADER_LEN + len);
    if crc32(body) != crc {
        return Decoded::Skip {
            error: DecodeError::BadCrc,
            consumed: 1,
        };
    }
    let payload = &frame_bytes[HEADER_LEN..HEADER_LEN + len];
    let frame = match (kind, len) {
        (KIND_START, START_LEN) => Frame::Start {
            rate_hz: get_u32(payload, 0),
            samples: get_u32(payload, 4),
            first: get_u32(payload, 8),
        },
        (KIND_END, END_LEN) => Frame::End {
            samples_sent: get_u32(payload, 0),
            data_frames: get_u32(payload, 4),
        },
        (KIND_DATA, l) if l > 4 && (l - 4) % RECORD_LEN == 0 => {
            let mut records = Records {
                buf: [Record::default(); MAX_RECORDS],
                len: 0,
            };
            for (slot, chunk) in records
                .buf
                .iter_mut()
                .zip(payload[4..].chunks_exact(RECORD_LEN))
            {
                let mut b = [0u8; RECORD_LEN];
                b.copy_from_slice(chunk);
                *slot = Record::from_bytes(b);
                records.len += 1;
            }
            Frame::Data {
                first_index: get_u32(payload, 0),
                records,
            }
        }
        _ => {
            return Decoded::Skip {
                error: DecodeError::BadPayload,
                consumed: total,
            };
        }
    };
    Decoded::Frame {
        frame,
        seq,
        consumed: total,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn sizes() {
        assert_eq!(MAX_PAYLOAD, 244);
        assert_eq!(MAX_FRAME, 254);
        assert!(MAX_PAYLOAD <= u8::MAX as usize);
    }

    #[test]
    fn encode_refuses_bad_input() {
        let mut buf = [0u8; MAX_FRAME];
        let recs = [Record::default(); MAX_RECORDS + 1];
        assert_eq!(
            encode(
                &FrameRef::Data {
                    first_index: 0,
                    records: &recs
                },
                0,
                &mut buf
            ),
            Err(EncodeError::BadRecordCount)
        );
        assert_eq!(
            encode(
                &FrameRef::Data {
                    first_index: 0,
                    records: &[]
                },
                0,
                &mut buf
            ),
            Err(EncodeError::BadRecordCount)
        );
        let mut small = [0u8; 10];
        assert_eq!(
            encode(
                &FrameRef::End {
                    samples_sent: 1,
                    data_frames: 1
                },
                0,
                &mut small
            ),
            Err(EncodeError::BufferTooSmall)
        );
    }

    #[test]
    fn start_and_end_round_trip() {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(
            &FrameRef::Start {
                rate_hz: 50_000,
                samples: 123,
                first: 4,
            },
            0,
            &mut buf,
        )
        .unwrap();
        assert_eq!(n, HEADER_LEN + START_LEN + CRC_LEN);
        assert_eq!(
            decode(&buf[..n]),
            Decoded::Frame {
                frame: Frame::Start {
                    rate_hz: 50_000,
                    samples: 123,
                    first: 4
                },
                seq: 0,
                consumed: n
            }
        );
        // Truncated: every strict prefix asks for more.
        for k in 0..n {
            assert_eq!(decode(&buf[..k]), Decoded::NeedMore, "prefix {k}");
        }
        let n = encode(
            &FrameRef::End {
                samples_sent: 5,
                data_frames: 1,
            },
            65535,
            &mut buf,
        )
        .unwrap();
        assert!(matches!(
            decode(&buf[..n]),
            Decoded::Frame {
                frame: Frame::End {
                    samples_sent: 5,
                    data_frames: 1
                },
                seq: 65535,
                ..
            }
        ));
    }
}
