//! Length checks on untrusted bag bytes, before anything is allocated from them.
//!
//! A bag's records carry their own lengths (a record length, a string length, a chunk's
//! compressed and decompressed sizes). A damaged or hostile file can put any number there, and a
//! reader that allocates what it is told asks for gigabytes (one flipped byte in an MCAP Header
//! record's string length made the `mcap` crate allocate 4 GiB). Every length read from a bag is
//! checked here against what is actually there (the rest of the record, the rest of the file)
//! before a reader is allowed to act on it; decompressed sizes, which the file cannot vouch for,
//! are held to [`decompressed_bound`].
//!
//! [`check_len`] and [`decompressed_bound`] are format-neutral (the ROS 1 bag reader uses them
//! too); [`check_mcap_record`] walks every variable-length field of an MCAP record body as the
//! MCAP specification lays it out.

/// Decompressed sizes up to this are accepted whatever the file size (a chunk holding a few
/// uncompressed 4K camera frames or a large organised cloud).
pub const MIN_DECOMPRESSED_BOUND: u64 = 256 << 20;

/// How many times the file size a decompressed block may be beyond [`MIN_DECOMPRESSED_BOUND`].
pub const DECOMPRESSED_PER_FILE_BYTE: u64 = 4;

/// The largest decompressed block (chunk, record) a reader accepts from a file of `file_len`
/// bytes: `max(256 MiB, 4 x file size)`. Larger claims are reported as damage instead of being
/// allocated.
pub fn decompressed_bound(file_len: u64) -> u64 {
    MIN_DECOMPRESSED_BOUND.max(file_len.saturating_mul(DECOMPRESSED_PER_FILE_BYTE))
}

/// Checks that `len` bytes of `what`, starting at byte `at`, fit in the `available` bytes that
/// are there; returns `len` as a `usize`. The error names the field, where it is and both sizes.
pub fn check_len(what: &str, at: u64, len: u64, available: u64) -> Result<usize, String> {
    if len > available {
        return Err(format!(
            "{what} at byte {at} claims {len} bytes but only {available} remain"
        ));
    }
    usize::try_from(len).map_err(|_| format!("{what} at byte {at}: {len} bytes is not addressable"))
}

/// Checks a claimed decompressed size against [`decompressed_bound`] for a file of `file_len`
/// bytes.
pub fn check_decompressed(what: &str, at: u64, size: u64, file_len: u64) -> Result<(), String> {
    let bound = decompressed_bound(file_len);
    if size > bound {
        return Err(format!(
            "{what} at byte {at} claims {size} bytes once decompressed, more than the {bound} a {file_len}-byte file can sanely hold"
        ));
    }
    Ok(())
}

/// A cursor over one record body that checks every length before using it.
struct Body<'a> {
    data: &'a [u8],
    pos: usize,
    /// File offset of `data[0]`, for messages.
    base: u64,
    what: &'static str,
}

impl<'a> Body<'a> {
    fn at(&self) -> u64 {
        self.base + self.pos as u64
    }

    fn remaining(&self) -> u64 {
        (self.data.len() - self.pos) as u64
    }

    fn take(&mut self, n: u64, field: &str) -> Result<&'a [u8], String> {
        let n = check_len(
            &format!("{} {field}", self.what),
            self.at(),
            n,
            self.remaining(),
        )?;
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn u16(&mut self, field: &str) -> Result<u16, String> {
        let b = self.take(2, field)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self, field: &str) -> Result<u32, String> {
        let b = self.take(4, field)?;
        Ok(u32::from_le_bytes(b.try_into().expect("4 bytes")))
    }

    fn u64(&mut self, field: &str) -> Result<u64, String> {
        let b = self.take(8, field)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }

    /// A u32-length-prefixed string or byte array.
    fn string(&mut self, field: &str) -> Result<(), String> {
        let at = self.at();
        let n = self.u32(field)?;
        let n = check_len(
            &format!("{} {field}", self.what),
            at,
            n as u64,
            self.remaining(),
        )?;
        self.pos += n;
        Ok(())
    }

    /// A map whose u32 prefix is its length in bytes; `entry` walks one entry inside it.
    fn map(
        &mut self,
        field: &str,
        mut entry: impl FnMut(&mut Body<'a>) -> Result<(), String>,
    ) -> Result<(), String> {
        let at = self.at();
        let n = self.u32(field)?;
        let start = self.pos;
        let n = check_len(
            &format!("{} {field}", self.what),
            at,
            n as u64,
            self.remaining(),
        )?;
        let bytes = &self.data[self.pos..self.pos + n];
        self.pos += n;
        let mut inner = Body {
            data: bytes,
            pos: 0,
            base: self.base + start as u64,
            what: self.what,
        };
        while inner.remaining() > 0 {
            entry(&mut inner)?;
        }
        Ok(())
    }
}

/// MCAP opcodes (MCAP specification, "Records").
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const ATTACHMENT: u8 = 0x09;
    pub const ATTACHMENT_INDEX: u8 = 0x0A;
    pub const STATISTICS: u8 = 0x0B;
    pub const METADATA: u8 = 0x0C;
    pub const METADATA_INDEX: u8 = 0x0D;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// The record's name, for messages.
fn record_name(opcode: u8) -> &'static str {
    match opcode {
        op::HEADER => "Header record",
        op::FOOTER => "Footer record",
        op::SCHEMA => "Schema record",
        op::CHANNEL => "Channel record",
        op::MESSAGE => "Message record",
        op::CHUNK => "Chunk record",
        op::MESSAGE_INDEX => "Message Index record",
        op::CHUNK_INDEX => "Chunk Index record",
        op::ATTACHMENT => "Attachment record",
        op::ATTACHMENT_INDEX => "Attachment Index record",
        op::STATISTICS => "Statistics record",
        op::METADATA => "Metadata record",
        op::METADATA_INDEX => "Metadata Index record",
        op::SUMMARY_OFFSET => "Summary Offset record",
        op::DATA_END => "Data End record",
        _ => "record",
    }
}

/// Checks that every length inside the body of an MCAP record (opcode `opcode`, body starting at
/// file offset `at`) stays inside the body, and that a chunk's decompressed size is within
/// [`decompressed_bound`] for a file of `file_len` bytes. Unknown opcodes pass (their body is
/// skipped whole, as the specification asks). Call it before `mcap::parse_record`, which
/// allocates string lengths as read.
pub fn check_mcap_record(opcode: u8, body: &[u8], at: u64, file_len: u64) -> Result<(), String> {
    let mut b = Body {
        data: body,
        pos: 0,
        base: at,
        what: record_name(opcode),
    };
    let string_pair = |m: &mut Body<'_>| -> Result<(), String> {
        m.string("map key")?;
        m.string("map value")
    };
    match opcode {
        op::HEADER => {
            b.string("profile")?;
            b.string("library")?;
        }
        op::FOOTER => {
            b.take(20, "fields")?;
        }
        op::SCHEMA => {
            b.u16("id")?;
            b.string("name")?;
            b.string("encoding")?;
            b.string("data")?;
        }
        op::CHANNEL => {
            b.u16("id")?;
            b.u16("schema_id")?;
            b.string("topic")?;
            b.string("message_encoding")?;
            b.map("metadata", string_pair)?;
        }
        op::MESSAGE => {
            b.take(2 + 4 + 8 + 8, "header")?;
        }
        op::CHUNK => {
            b.take(8 + 8, "message times")?;
            let uncompressed = b.u64("uncompressed_size")?;
            b.u32("uncompressed_crc")?;
            b.string("compression")?;
            let compressed = b.u64("compressed_size")?;
            b.take(compressed, "records")?;
            check_decompressed("Chunk record", at, uncompressed, file_len)?;
        }
        op::MESSAGE_INDEX => {
            b.u16("channel_id")?;
            b.map("records", |m| m.take(16, "entry").map(|_| ()))?;
        }
        op::CHUNK_INDEX => {
            b.take(8 + 8, "message times")?;
            b.u64("chunk_start_offset")?;
            b.u64("chunk_length")?;
            b.map("message_index_offsets", |m| m.take(10, "entry").map(|_| ()))?;
            b.u64("message_index_length")?;
            b.string("compression")?;
            b.u64("compressed_size")?;
            let uncompressed = b.u64("uncompressed_size")?;
            check_decompressed("Chunk Index record", at, uncompressed, file_len)?;
        }
        op::ATTACHMENT => {
            b.take(8 + 8, "times")?;
            b.string("name")?;
            b.string("media_type")?;
            let n = b.u64("data_size")?;
            b.take(n, "data")?;
            b.u32("crc")?;
        }
        op::ATTACHMENT_INDEX => {
            b.take(8 * 5, "fields")?;
            b.string("name")?;
            b.string("media_type")?;
        }
        op::STATISTICS => {
            b.take(8 + 2 + 4 * 4 + 8 + 8, "counts")?;
            b.map("channel_message_counts", |m| {
                m.take(10, "entry").map(|_| ())
            })?;
        }
        op::METADATA => {
            b.string("name")?;
            b.map("metadata", string_pair)?;
        }
        op::METADATA_INDEX => {
            b.take(8 + 8, "offset and length")?;
            b.string("name")?;
        }
        op::SUMMARY_OFFSET => {
            b.take(1 + 8 + 8, "fields")?;
        }
        op::DATA_END => {
            b.u32("data_section_crc")?;
        }
        _ => {}
    }
    Ok(())
}

/// One MCAP record found by [`mcap_records`]: opcode, body and the body's file offset.
pub type RawRecord<'a> = (u8, &'a [u8], u64);

/// Splits `region` (which starts at file offset `base`) into MCAP records, checking every record
/// length against what is left of the region and every record body with
/// [`check_mcap_record`].
pub fn mcap_records(region: &[u8], base: u64, file_len: u64) -> Result<Vec<RawRecord<'_>>, String> {
    mcap_records_prefix(region, base, file_len, usize::MAX)
}

/// The whole records at the start of `region` (each checked as in [`mcap_records`]) and what
/// stopped the walk, if it did not reach the end: for salvaging a truncated chunk.
pub fn mcap_records_salvage(
    region: &[u8],
    base: u64,
    file_len: u64,
) -> (Vec<RawRecord<'_>>, Option<String>) {
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < region.len() {
        match mcap_records_prefix(&region[pos..], base + pos as u64, file_len, 1) {
            Ok(r) => {
                let (op, body, at) = r[0];
                out.push((op, body, at));
                pos += 9 + body.len();
            }
            Err(e) => return (out, Some(e)),
        }
    }
    (out, None)
}

/// [`mcap_records`] for the first `max` records of `region` only (the rest is not looked at).
pub fn mcap_records_prefix(
    region: &[u8],
    base: u64,
    file_len: u64,
    max: usize,
) -> Result<Vec<RawRecord<'_>>, String> {
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < region.len() && out.len() < max {
        let at = base + pos as u64;
        let rest = &region[pos..];
        if rest.len() < 9 {
            return Err(format!(
                "record at byte {at}: {} bytes left, a record header needs 9",
                rest.len()
            ));
        }
        let opcode = rest[0];
        let len = u64::from_le_bytes(rest[1..9].try_into().expect("8 bytes"));
        let n = check_len(record_name(opcode), at, len, (rest.len() - 9) as u64)?;
        let body = &rest[9..9 + n];
        check_mcap_record(opcode, body, at + 9, file_len)?;
        out.push((opcode, body, at + 9));
        pos += 9 + n;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn string(s: &[u8]) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s);
        v
    }

    #[test]
    fn a_string_longer_than_its_record_is_refused_before_allocation() {
        let mut body = string(b"ros2");
        body.extend(string(b"lib"));
        assert!(check_mcap_record(op::HEADER, &body, 17, 1000).is_ok());
        body[0..4].copy_from_slice(&4_294_967_054u32.to_le_bytes());
        let e = check_mcap_record(op::HEADER, &body, 17, 1000).unwrap_err();
        assert!(
            e.contains("Header record profile") && e.contains("4294967054") && e.contains("17"),
            "{e}"
        );
    }

    #[test]
    fn map_entries_are_checked_one_by_one() {
        let mut body = 1u16.to_le_bytes().to_vec();
        body.extend(0u16.to_le_bytes());
        body.extend(string(b"/t"));
        body.extend(string(b"cdr"));
        let mut map = string(b"k");
        map.extend(string(b"v"));
        body.extend(string(&map));
        assert!(check_mcap_record(op::CHANNEL, &body, 0, 100).is_ok());
        // The value's length inside the map claims more than the map holds.
        let v_len_at = body.len() - 5;
        body[v_len_at..v_len_at + 4].copy_from_slice(&1000u32.to_le_bytes());
        let e = check_mcap_record(op::CHANNEL, &body, 0, 100).unwrap_err();
        assert!(e.contains("map value"), "{e}");
    }

    #[test]
    fn a_chunk_that_decompresses_beyond_the_bound_is_refused() {
        let mut body = vec![0u8; 16];
        body.extend(u64::MAX.to_le_bytes());
        body.extend(0u32.to_le_bytes());
        body.extend(string(b"zstd"));
        body.extend(0u64.to_le_bytes());
        let e = check_mcap_record(op::CHUNK, &body, 0, 4096).unwrap_err();
        assert!(e.contains("decompressed"), "{e}");
        assert_eq!(decompressed_bound(1), MIN_DECOMPRESSED_BOUND);
        assert_eq!(decompressed_bound(1 << 30), 4 << 30);
    }

    #[test]
    fn record_lengths_are_checked_against_the_region() {
        let mut region = vec![op::DATA_END];
        region.extend(4u64.to_le_bytes());
        region.extend(0u32.to_le_bytes());
        assert_eq!(mcap_records(&region, 8, 100).unwrap().len(), 1);
        region[1..9].copy_from_slice(&(u32::MAX as u64).to_le_bytes());
        let e = mcap_records(&region, 8, 100).unwrap_err();
        assert!(e.contains("Data End record at byte 8"), "{e}");
    }
}
