//! Writing ROS 1 bags (format 2.0) that `rosbag info`, `rosbag play`, Python `rosbag` and
//! `rosbags` accept: the bag header padded to 4096 bytes, chunks holding each connection's record
//! before its first message, one INDEX_DATA per connection after every chunk, and at the end the
//! index (every connection again, one CHUNK_INFO per chunk) with the header rewritten to point at
//! it. Like `rosbag record`, the bag is written as `NAME.active` and renamed when it is finished,
//! so a killed recorder leaves an `.active` file that reads in file order.

use super::{
    Connection, MAGIC, OP_BAG_HEADER, OP_CHUNK, OP_CHUNK_INFO, OP_INDEX_DATA, OP_MSG_DATA,
    push_record, time_bytes,
};
use crate::BagError;
use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Chunk compression of a ROS 1 bag.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Ros1Compression {
    /// Uncompressed chunks (`rosbag record`'s default).
    #[default]
    None,
    /// bzip2 (`rosbag record -j`).
    Bz2,
    /// LZ4 frames (`rosbag record --lz4`).
    Lz4,
}

impl std::str::FromStr for Ros1Compression {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(Ros1Compression::None),
            "bz2" => Ok(Ros1Compression::Bz2),
            "lz4" => Ok(Ros1Compression::Lz4),
            other => Err(format!(
                "unknown ROS 1 bag compression `{other}` (none, bz2, lz4)"
            )),
        }
    }
}

impl Ros1Compression {
    fn name(self) -> &'static str {
        match self {
            Ros1Compression::None => "none",
            Ros1Compression::Bz2 => "bz2",
            Ros1Compression::Lz4 => "lz4",
        }
    }
}

/// Options of a [`Ros1Writer`].
#[derive(Clone, Debug)]
pub struct Ros1WriterOptions {
    /// Chunk compression.
    pub compression: Ros1Compression,
    /// Uncompressed chunk size at which a chunk is closed (Python rosbag: 768 KiB).
    pub chunk_size: usize,
}

impl Default for Ros1WriterOptions {
    fn default() -> Self {
        Ros1WriterOptions {
            compression: Ros1Compression::None,
            chunk_size: 768 << 10,
        }
    }
}

struct ChunkInfo {
    pos: u64,
    start: u64,
    end: u64,
    counts: Vec<(u32, u32)>,
}

/// Size of the bag header record (header and data), as rosbag pads it.
const HEADER_SIZE: usize = 4096;

/// Writes a ROS 1 bag.
pub struct Ros1Writer {
    path: PathBuf,
    active: PathBuf,
    file: Option<BufWriter<std::fs::File>>,
    opts: Ros1WriterOptions,
    /// File offset of the next write.
    pos: u64,
    conns: Vec<Connection>,
    /// Connections whose record was already written into a chunk.
    announced: Vec<bool>,
    chunk: Vec<u8>,
    chunk_index: BTreeMap<u32, Vec<u8>>,
    chunk_counts: BTreeMap<u32, u32>,
    chunk_times: Option<(u64, u64)>,
    chunks: Vec<ChunkInfo>,
    count: u64,
}

impl std::fmt::Debug for Ros1Writer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros1Writer")
            .field("path", &self.path)
            .field("count", &self.count)
            .finish()
    }
}

fn bag_header(index_pos: u64, conns: u32, chunks: u32) -> Vec<u8> {
    let mut h = Vec::new();
    super::push_field(&mut h, "index_pos", &index_pos.to_le_bytes());
    super::push_field(&mut h, "conn_count", &conns.to_le_bytes());
    super::push_field(&mut h, "chunk_count", &chunks.to_le_bytes());
    super::push_field(&mut h, "op", &[OP_BAG_HEADER]);
    let mut out = Vec::with_capacity(HEADER_SIZE + 8);
    out.extend_from_slice(&(h.len() as u32).to_le_bytes());
    out.extend_from_slice(&h);
    let pad = HEADER_SIZE - h.len();
    out.extend_from_slice(&(pad as u32).to_le_bytes());
    out.extend(std::iter::repeat_n(b' ', pad));
    out
}

impl Ros1Writer {
    /// Creates the bag `path` (written as `path.active` until [`Self::finish`]); an existing
    /// file is refused.
    pub fn create(path: &Path, opts: &Ros1WriterOptions) -> Result<Self, BagError> {
        if path.exists() {
            return Err(BagError::Write {
                path: path.to_path_buf(),
                reason: "the file exists".into(),
            });
        }
        let mut active = path.as_os_str().to_owned();
        active.push(".active");
        let active = PathBuf::from(active);
        let file = std::fs::File::create(&active).map_err(|source| BagError::Io {
            path: active.clone(),
            source,
        })?;
        let mut w = Ros1Writer {
            path: path.to_path_buf(),
            active,
            file: Some(BufWriter::with_capacity(1 << 20, file)),
            opts: opts.clone(),
            pos: 0,
            conns: Vec::new(),
            announced: Vec::new(),
            chunk: Vec::with_capacity(opts.chunk_size + (64 << 10)),
            chunk_index: BTreeMap::new(),
            chunk_counts: BTreeMap::new(),
            chunk_times: None,
            chunks: Vec::new(),
            count: 0,
        };
        w.put(MAGIC)?;
        w.put(&bag_header(0, 0, 0))?;
        Ok(w)
    }

    fn werr(&self, reason: impl std::fmt::Display) -> BagError {
        BagError::Write {
            path: self.path.clone(),
            reason: reason.to_string(),
        }
    }

    fn put(&mut self, b: &[u8]) -> Result<(), BagError> {
        let file = self.file.as_mut().ok_or_else(|| BagError::Write {
            path: self.path.clone(),
            reason: "writer already finished".into(),
        })?;
        file.write_all(b).map_err(|source| BagError::Io {
            path: self.active.clone(),
            source,
        })?;
        self.pos += b.len() as u64;
        Ok(())
    }

    /// Adds a topic of a type this project serializes (`sensor_msgs/Image` or
    /// `sensor_msgs/msg/Image`, ...; see [`perturb_core::formats::kinds::KINDS`]); returns its
    /// connection id.
    pub fn add_topic(&mut self, topic: &str, type_name: &str) -> Result<u16, BagError> {
        let t = perturb_core::formats::ros1::msg_type(type_name).ok_or_else(|| {
            self.werr(format!("no ROS 1 definition known for type `{type_name}`"))
        })?;
        self.add_connection(topic, t.name, t.md5sum, t.definition, None, false)
    }

    /// Adds a connection with an explicit type, md5sum and definition (to copy a topic from
    /// another bag); returns its id.
    pub fn add_connection(
        &mut self,
        topic: &str,
        type_name: &str,
        md5sum: &str,
        definition: &str,
        callerid: Option<&str>,
        latching: bool,
    ) -> Result<u16, BagError> {
        let id = u16::try_from(self.conns.len())
            .map_err(|_| self.werr("more than 65536 connections"))?;
        self.conns.push(Connection {
            id: id as u32,
            topic: topic.to_string(),
            type_name: type_name.to_string(),
            md5sum: md5sum.to_string(),
            definition: definition.to_string(),
            callerid: callerid.map(str::to_string),
            latching,
        });
        self.announced.push(false);
        Ok(id)
    }

    /// Writes one ROS 1 serialized message with record time `log_time` (ns).
    pub fn write(&mut self, conn: u16, log_time: u64, data: &[u8]) -> Result<(), BagError> {
        let c = conn as usize;
        if c >= self.conns.len() {
            return Err(self.werr(format!("unknown connection {conn}")));
        }
        if !self.announced[c] {
            self.conns[c].to_record(&mut self.chunk);
            self.announced[c] = true;
        }
        let offset = self.chunk.len() as u32;
        push_record(
            &mut self.chunk,
            &[
                ("op", &[OP_MSG_DATA]),
                ("conn", &(conn as u32).to_le_bytes()),
                ("time", &time_bytes(log_time)),
            ],
            data,
        );
        let idx = self.chunk_index.entry(conn as u32).or_default();
        idx.extend_from_slice(&time_bytes(log_time));
        idx.extend_from_slice(&offset.to_le_bytes());
        *self.chunk_counts.entry(conn as u32).or_default() += 1;
        self.chunk_times = Some(match self.chunk_times {
            None => (log_time, log_time),
            Some((a, b)) => (a.min(log_time), b.max(log_time)),
        });
        self.count += 1;
        if self.chunk.len() >= self.opts.chunk_size {
            self.flush_chunk()?;
        }
        Ok(())
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.count
    }

    fn flush_chunk(&mut self) -> Result<(), BagError> {
        let Some((start, end)) = self.chunk_times.take() else {
            return Ok(());
        };
        let size = self.chunk.len() as u32;
        let compressed = match self.opts.compression {
            Ros1Compression::None => None,
            Ros1Compression::Bz2 => {
                let mut e = bzip2::write::BzEncoder::new(
                    Vec::with_capacity(self.chunk.len() / 2),
                    bzip2::Compression::default(),
                );
                e.write_all(&self.chunk)
                    .and_then(|_| e.finish())
                    .map(Some)
                    .map_err(|e| self.werr(format!("bz2: {e}")))?
            }
            Ros1Compression::Lz4 => {
                // roslz4 (Python rosbag, rosbag play) refuses block checksums ("malformed
                // data"); it writes independent 1 MiB blocks with a content checksum, and so
                // does this.
                let mut e = lz4::EncoderBuilder::new()
                    .block_size(lz4::BlockSize::Max1MB)
                    .block_mode(lz4::BlockMode::Independent)
                    .block_checksum(lz4::liblz4::BlockChecksum::NoBlockChecksum)
                    .checksum(lz4::ContentChecksum::ChecksumEnabled)
                    .build(Vec::with_capacity(self.chunk.len() / 2))
                    .map_err(|e| self.werr(format!("lz4: {e}")))?;
                e.write_all(&self.chunk)
                    .map_err(|e| self.werr(format!("lz4: {e}")))?;
                let (v, r) = e.finish();
                r.map_err(|e| self.werr(format!("lz4: {e}")))?;
                Some(v)
            }
        };
        let chunk = std::mem::take(&mut self.chunk);
        let data = compressed.as_deref().unwrap_or(&chunk);
        let pos = self.pos;
        let mut rec = Vec::with_capacity(64);
        let hdr_fields: [(&str, &[u8]); 3] = [
            ("op", &[OP_CHUNK]),
            ("compression", self.opts.compression.name().as_bytes()),
            ("size", &size.to_le_bytes()),
        ];
        let mut h = Vec::new();
        for (n, v) in hdr_fields {
            super::push_field(&mut h, n, v);
        }
        rec.extend_from_slice(&(h.len() as u32).to_le_bytes());
        rec.extend_from_slice(&h);
        rec.extend_from_slice(&(data.len() as u32).to_le_bytes());
        self.put(&rec)?;
        self.put(data)?;
        let mut index = Vec::new();
        for (conn, entries) in std::mem::take(&mut self.chunk_index) {
            let count = (entries.len() / 12) as u32;
            push_record(
                &mut index,
                &[
                    ("op", &[OP_INDEX_DATA]),
                    ("ver", &1u32.to_le_bytes()),
                    ("conn", &conn.to_le_bytes()),
                    ("count", &count.to_le_bytes()),
                ],
                &entries,
            );
        }
        self.put(&index)?;
        self.chunks.push(ChunkInfo {
            pos,
            start,
            end,
            counts: std::mem::take(&mut self.chunk_counts).into_iter().collect(),
        });
        self.chunk = chunk;
        self.chunk.clear();
        Ok(())
    }

    /// Writes the last chunk and the index, and renames the file to its final name; returns it.
    pub fn finish(mut self) -> Result<PathBuf, BagError> {
        self.finish_inner()?;
        Ok(self.path.clone())
    }

    fn finish_inner(&mut self) -> Result<(), BagError> {
        if self.file.is_none() {
            return Ok(());
        }
        self.flush_chunk()?;
        let index_pos = self.pos;
        let mut index = Vec::new();
        for c in &self.conns {
            c.to_record(&mut index);
        }
        for c in &self.chunks {
            let mut data = Vec::with_capacity(c.counts.len() * 8);
            for (conn, n) in &c.counts {
                data.extend_from_slice(&conn.to_le_bytes());
                data.extend_from_slice(&n.to_le_bytes());
            }
            push_record(
                &mut index,
                &[
                    ("op", &[OP_CHUNK_INFO]),
                    ("ver", &1u32.to_le_bytes()),
                    ("chunk_pos", &c.pos.to_le_bytes()),
                    ("start_time", &time_bytes(c.start)),
                    ("end_time", &time_bytes(c.end)),
                    ("count", &(c.counts.len() as u32).to_le_bytes()),
                ],
                &data,
            );
        }
        self.put(&index)?;
        let header = bag_header(index_pos, self.conns.len() as u32, self.chunks.len() as u32);
        let io = |source| BagError::Io {
            path: self.active.clone(),
            source,
        };
        let mut file = self.file.take().expect("checked above");
        file.seek(SeekFrom::Start(MAGIC.len() as u64)).map_err(io)?;
        file.write_all(&header).map_err(io)?;
        let file = file.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(io)?;
        std::fs::rename(&self.active, &self.path).map_err(|source| BagError::Io {
            path: self.path.clone(),
            source,
        })
    }
}

impl Drop for Ros1Writer {
    fn drop(&mut self) {
        // A writer dropped without finish (an error path) still leaves an indexed bag.
        let _ = self.finish_inner();
    }
}
