//! Reading ROS 1 bags: the index (connections, chunk infos, the index data after each chunk)
//! gives every message's log time and place, the messages are delivered in log-time order, and
//! each chunk is decompressed once, when its first message is due, and dropped after its last.
//! A bag without a usable index (a recorder that was killed leaves `index_pos` 0) is read in file
//! order up to the damage, like a damaged MCAP file.

use super::{
    Connection, MAGIC, OP_BAG_HEADER, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION, OP_INDEX_DATA,
    OP_MSG_DATA, Record, record_at, time_ns,
};
use crate::BagError;
use crate::guard;
use crate::message::{BagMessage, Bytes, Filter, ReadReport, TopicInfo};
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// One CHUNK_INFO record.
#[derive(Clone, Debug)]
struct ChunkInfo {
    pos: usize,
    start: u64,
    end: u64,
    counts: Vec<(u32, u32)>,
}

/// An open ROS 1 bag.
pub(crate) struct Ros1Bag {
    pub(crate) path: PathBuf,
    map: Bytes,
    /// Offset of the first record after the bag header.
    first_record: usize,
    conns: BTreeMap<u32, Connection>,
    chunks: Vec<ChunkInfo>,
    /// Why the index cannot be used (the bag is then read in file order).
    index_error: Option<String>,
}

/// What a file-order scan calls for each message: connection, log time, data.
type MessageFn<'f> = dyn FnMut(&Connection, u64, &[u8]) -> Result<ControlFlow<()>, BagError> + 'f;

/// One message's place: log time, chunk (index into `chunks`), offset in the chunk, connection.
type Entry = (u64, usize, u32, u32);

impl Ros1Bag {
    /// True if `head` starts like a ROS 1 bag of any version.
    pub(crate) fn sniff(head: &[u8]) -> bool {
        head.starts_with(b"#ROSBAG V")
    }

    /// Opens a file (mapped or in memory) that [`Self::sniff`] recognised.
    pub(crate) fn open(path: &Path, map: Bytes) -> Result<Self, BagError> {
        let not = |reason: String| BagError::NotMcap {
            path: path.to_path_buf(),
            reason,
        };
        if !map.starts_with(MAGIC) {
            let version = map
                .iter()
                .take(16)
                .take_while(|&&b| b != b'\n')
                .map(|&b| b as char)
                .collect::<String>();
            return Err(not(format!(
                "`{version}` is not supported: only ROS bag format 2.0 is read (convert older bags with `rosbag fix`)"
            )));
        }
        let header = record_at(&map, MAGIC.len())
            .map_err(|e| not(format!("the bag header is unreadable: {e}")))?;
        if header.op() != Ok(OP_BAG_HEADER) {
            return Err(not("the first record is not a bag header (op 0x03)".into()));
        }
        let index_pos = header
            .u64("index_pos")
            .map_err(|e| not(format!("bag header: {e}")))?;
        let conn_count = header
            .u32("conn_count")
            .map_err(|e| not(format!("bag header: {e}")))?;
        let chunk_count = header
            .u32("chunk_count")
            .map_err(|e| not(format!("bag header: {e}")))?;
        let mut bag = Ros1Bag {
            path: path.to_path_buf(),
            first_record: header.end,
            map,
            conns: BTreeMap::new(),
            chunks: Vec::new(),
            index_error: None,
        };
        if index_pos == 0 {
            bag.index_error = Some(
                "the bag is unindexed (its recorder did not close it; `rosbag reindex` rebuilds the index)"
                    .into(),
            );
        } else if let Err(e) = bag.read_index(index_pos as usize, conn_count, chunk_count) {
            bag.conns.clear();
            bag.chunks.clear();
            bag.index_error = Some(format!("the index at byte {index_pos} is unusable ({e})"));
        }
        Ok(bag)
    }

    fn read_index(&mut self, mut pos: usize, conns: u32, chunks: u32) -> Result<(), String> {
        for _ in 0..conns {
            let r = record_at(&self.map, pos)?;
            if r.op()? != OP_CONNECTION {
                return Err(format!("expected a connection record at byte {pos}"));
            }
            let c = Connection::from_record(&r)?;
            self.conns.insert(c.id, c);
            pos = r.end;
        }
        for _ in 0..chunks {
            let r = record_at(&self.map, pos)?;
            if r.op()? != OP_CHUNK_INFO {
                return Err(format!("expected a chunk info record at byte {pos}"));
            }
            let n = r.u32("count")? as usize;
            if r.data.len() < n * 8 {
                return Err(format!(
                    "chunk info at byte {pos} lists {n} connections but holds {} bytes",
                    r.data.len()
                ));
            }
            let counts = r.data[..n * 8]
                .chunks_exact(8)
                .map(|c| {
                    (
                        u32::from_le_bytes(c[..4].try_into().expect("4")),
                        u32::from_le_bytes(c[4..].try_into().expect("4")),
                    )
                })
                .collect();
            self.chunks.push(ChunkInfo {
                pos: r.u64("chunk_pos")? as usize,
                start: r.time("start_time")?,
                end: r.time("end_time")?,
                counts,
            });
            pos = r.end;
        }
        self.chunks.sort_by_key(|c| c.pos);
        Ok(())
    }

    pub(crate) fn is_indexed(&self) -> bool {
        self.index_error.is_none()
    }

    /// Why the bag is read in file order, if it is.
    pub(crate) fn index_error(&self) -> Option<&str> {
        self.index_error.as_deref()
    }

    fn damage(&self, what: impl std::fmt::Display) -> String {
        format!("{}: {what}", self.path.display())
    }

    /// The topics, their types and message counts.
    pub(crate) fn topics(&self) -> Result<Vec<TopicInfo>, BagError> {
        let mut counts: BTreeMap<u32, u64> = BTreeMap::new();
        let mut conns = self.conns.clone();
        if self.is_indexed() {
            for c in &self.chunks {
                for (conn, n) in &c.counts {
                    *counts.entry(*conn).or_default() += *n as u64;
                }
            }
        } else {
            let _ = self.scan(&Filter::default(), &mut |conn, _, _| {
                *counts.entry(conn.id).or_default() += 1;
                conns.entry(conn.id).or_insert_with(|| conn.clone());
                Ok(ControlFlow::Continue(()))
            })?;
        }
        let mut by_topic: BTreeMap<String, TopicInfo> = BTreeMap::new();
        for c in conns.values() {
            let n = counts.get(&c.id).copied().unwrap_or(0);
            let t = by_topic.entry(c.topic.clone()).or_insert_with(|| {
                let mut metadata = BTreeMap::new();
                metadata.insert("md5sum".to_string(), c.md5sum.clone());
                if let Some(id) = &c.callerid {
                    metadata.insert("callerid".to_string(), id.clone());
                }
                metadata.insert(
                    "latching".to_string(),
                    if c.latching { "1" } else { "0" }.into(),
                );
                TopicInfo {
                    topic: c.topic.clone(),
                    type_name: c.type_name.clone(),
                    schema_encoding: "ros1msg".into(),
                    schema: c.definition.as_bytes().to_vec(),
                    message_encoding: "ros1".into(),
                    metadata,
                    message_count: Some(0),
                }
            });
            t.message_count = t.message_count.map(|m| m + n);
        }
        Ok(by_topic.into_values().collect())
    }

    /// Delivers the messages passing `filter` in log-time order (file order without an index).
    pub(crate) fn for_each<F>(
        &self,
        filter: &Filter,
        f: &mut F,
        report: &mut ReadReport,
    ) -> Result<ControlFlow<()>, BagError>
    where
        F: FnMut(BagMessage<'_>) -> Result<ControlFlow<()>, BagError>,
    {
        if !self.is_indexed() {
            let mut seqs: HashMap<u32, u32> = HashMap::new();
            let (flow, damage) = self.scan(filter, &mut |conn, time, data| {
                let seq = seqs.entry(conn.id).or_default();
                *seq += 1;
                report.delivered += 1;
                f(message(conn, time, data, *seq, &self.path))
            })?;
            if let Some(d) = damage {
                report.damage = Some(d);
            } else if let Some(why) = &self.index_error {
                report
                    .notes
                    .push(self.damage(format!("{why}; messages were read in file order")));
            }
            return Ok(flow);
        }
        let (entries, damage) = self.entries(filter);
        let mut remaining: HashMap<usize, usize> = HashMap::new();
        for e in &entries {
            *remaining.entry(e.1).or_default() += 1;
        }
        let mut open: HashMap<usize, Cow<'_, [u8]>> = HashMap::new();
        let mut seqs: HashMap<u32, u32> = HashMap::new();
        for (time, ci, offset, conn_id) in entries {
            if let std::collections::hash_map::Entry::Vacant(slot) = open.entry(ci) {
                match self.chunk_data(self.chunks[ci].pos) {
                    Ok((data, _)) => {
                        slot.insert(data);
                    }
                    Err(e) => {
                        report.damage = Some(self.damage(e));
                        return Ok(ControlFlow::Continue(()));
                    }
                }
            }
            let data = &open[&ci];
            let r = match record_at(data, offset as usize) {
                Ok(r) if r.op() == Ok(OP_MSG_DATA) && r.u32("conn") == Ok(conn_id) => r,
                Ok(_) => {
                    report.damage = Some(self.damage(format!(
                        "the index points at byte {offset} of the chunk at byte {}, which is not a message of connection {conn_id}",
                        self.chunks[ci].pos
                    )));
                    return Ok(ControlFlow::Continue(()));
                }
                Err(e) => {
                    report.damage =
                        Some(self.damage(format!("chunk at byte {}: {e}", self.chunks[ci].pos)));
                    return Ok(ControlFlow::Continue(()));
                }
            };
            let Some(conn) = self.conns.get(&conn_id) else {
                report.damage =
                    Some(self.damage(format!("message of unknown connection {conn_id}")));
                return Ok(ControlFlow::Continue(()));
            };
            let seq = seqs.entry(conn_id).or_default();
            *seq += 1;
            report.delivered += 1;
            let flow = f(message(conn, time, r.data, *seq, &self.path))?;
            if flow.is_break() {
                return Ok(flow);
            }
            let left = remaining.get_mut(&ci).expect("counted");
            *left -= 1;
            if *left == 0 {
                open.remove(&ci);
            }
        }
        if let Some(d) = damage {
            report.damage = Some(d);
        }
        Ok(ControlFlow::Continue(()))
    }

    /// The selected messages' places in log-time order (ties in file order), and the damage
    /// that stopped the collection, if any (the places before it are returned).
    fn entries(&self, filter: &Filter) -> (Vec<Entry>, Option<String>) {
        let selected: Vec<u32> = self
            .conns
            .values()
            .filter(|c| filter.topics.is_empty() || filter.topics.contains(&c.topic))
            .map(|c| c.id)
            .collect();
        let mut entries: Vec<Entry> = Vec::new();
        let mut damage = None;
        for (ci, chunk) in self.chunks.iter().enumerate() {
            let wanted = chunk
                .counts
                .iter()
                .any(|(c, n)| *n > 0 && selected.contains(c));
            let in_time = filter.start.is_none_or(|s| chunk.end >= s)
                && filter.end.is_none_or(|e| chunk.start < e);
            if !wanted || !in_time {
                continue;
            }
            let mut add = |time: u64, offset: u32, conn: u32| {
                if selected.contains(&conn) && filter.accepts_time(time) {
                    entries.push((time, ci, offset, conn));
                }
            };
            match self.chunk_index(chunk) {
                Ok(list) => list.into_iter().for_each(|(t, o, c)| add(t, o, c)),
                Err(index_err) => {
                    // No usable INDEX_DATA after the chunk: find its messages by walking it.
                    match self.walk_chunk(chunk.pos, &mut |t, o, c| add(t, o, c)) {
                        Ok(()) => {}
                        Err(e) => {
                            damage = Some(self.damage(format!(
                                "chunk at byte {}: {e} (and its index data: {index_err})",
                                chunk.pos
                            )));
                            break;
                        }
                    }
                }
            }
        }
        entries.sort_by_key(|e| (e.0, e.1, e.2));
        (entries, damage)
    }

    /// The INDEX_DATA records after the chunk at `chunk.pos`: (time, offset, conn).
    fn chunk_index(&self, chunk: &ChunkInfo) -> Result<Vec<(u64, u32, u32)>, String> {
        let r = record_at(&self.map, chunk.pos)?;
        if r.op()? != OP_CHUNK {
            return Err(format!("no chunk record at byte {}", chunk.pos));
        }
        let mut pos = r.end;
        let mut out = Vec::new();
        for _ in 0..chunk.counts.len() {
            let r = record_at(&self.map, pos)?;
            if r.op()? != OP_INDEX_DATA {
                return Err(format!("expected index data at byte {pos}"));
            }
            let conn = r.u32("conn")?;
            let n = r.u32("count")? as usize;
            if r.data.len() < n * 12 {
                return Err(format!("index data at byte {pos} is short"));
            }
            for e in r.data[..n * 12].chunks_exact(12) {
                out.push((
                    time_ns(&e[..8]),
                    u32::from_le_bytes(e[8..].try_into().expect("4")),
                    conn,
                ));
            }
            pos = r.end;
        }
        Ok(out)
    }

    /// Calls `f(time, offset, conn)` for every message record inside the chunk at `pos`.
    fn walk_chunk(&self, pos: usize, f: &mut dyn FnMut(u64, u32, u32)) -> Result<(), String> {
        let (data, _) = self.chunk_data(pos)?;
        let mut at = 0;
        while at < data.len() {
            let r = record_at(&data, at)?;
            if r.op()? == OP_MSG_DATA {
                f(r.time("time")?, at as u32, r.u32("conn")?);
            }
            at = r.end;
        }
        Ok(())
    }

    /// The decompressed records of the chunk at `pos` and the chunk record's end.
    fn chunk_data(&self, pos: usize) -> Result<(Cow<'_, [u8]>, usize), String> {
        let r = record_at(&self.map, pos)?;
        if r.op()? != OP_CHUNK {
            return Err(format!("no chunk record at byte {pos}"));
        }
        Ok((decompress(&r, pos, self.map.len() as u64)?, r.end))
    }

    /// Reads every record in file order, calling `f(connection, time, data)` for each message
    /// passing `filter`. Returns the flow and the damage that stopped the scan, if any.
    fn scan(
        &self,
        filter: &Filter,
        f: &mut MessageFn<'_>,
    ) -> Result<(ControlFlow<()>, Option<String>), BagError> {
        let mut conns: BTreeMap<u32, Connection> = BTreeMap::new();
        let mut deliver = |r: &Record<'_>| -> Result<ControlFlow<()>, Stop> {
            match r.op()? {
                OP_CONNECTION => {
                    let c = Connection::from_record(r)?;
                    conns.entry(c.id).or_insert(c);
                }
                OP_MSG_DATA => {
                    let id = r.u32("conn")?;
                    let time = r.time("time")?;
                    let conn = conns.get(&id).ok_or_else(|| {
                        format!("a message of connection {id} comes before its connection record")
                    })?;
                    if filter.accepts(&conn.topic, time) {
                        return f(conn, time, r.data).map_err(Stop::Callback);
                    }
                }
                _ => {}
            }
            Ok(ControlFlow::Continue(()))
        };
        let mut pos = self.first_record;
        while pos < self.map.len() {
            let outcome = (|| -> Result<(ControlFlow<()>, usize), Stop> {
                let r = match record_at(&self.map, pos) {
                    Ok(r) => r,
                    Err(cut) => {
                        // A chunk cut by the end of the file (a recording cut short, a partial
                        // copy): the whole records before the cut are still delivered.
                        let Some((data, why)) = self.cut_chunk(pos) else {
                            return Err(Stop::Damage(cut));
                        };
                        let mut at = 0;
                        while let Ok(inner) = record_at(&data, at) {
                            if deliver(&inner)?.is_break() {
                                return Ok((ControlFlow::Break(()), self.map.len()));
                            }
                            at = inner.end;
                        }
                        return Err(Stop::Damage(format!(
                            "{cut}: the chunk at byte {pos} is cut off ({why}); its records before the cut were read"
                        )));
                    }
                };
                if r.op()? != OP_CHUNK {
                    return Ok((deliver(&r)?, r.end));
                }
                let data = decompress(&r, pos, self.map.len() as u64)?;
                let mut at = 0;
                while at < data.len() {
                    let inner =
                        record_at(&data, at).map_err(|e| format!("chunk at byte {pos}: {e}"))?;
                    if deliver(&inner)?.is_break() {
                        return Ok((ControlFlow::Break(()), r.end));
                    }
                    at = inner.end;
                }
                Ok((ControlFlow::Continue(()), r.end))
            })();
            match outcome {
                Ok((ControlFlow::Break(()), _)) => return Ok((ControlFlow::Break(()), None)),
                Ok((ControlFlow::Continue(()), end)) => pos = end,
                Err(Stop::Damage(e)) => {
                    return Ok((ControlFlow::Continue(()), Some(self.damage(e))));
                }
                Err(Stop::Callback(e)) => return Err(e),
            }
        }
        Ok((ControlFlow::Continue(()), None))
    }
}

impl Ros1Bag {
    /// The records of a chunk record at `pos` that the end of the file cuts off, as far as they
    /// go: the chunk's header must be whole; its data is what remains of the file (for `none`)
    /// or what the decompressor yields from it before it runs out (`bz2`, `lz4`), at most the
    /// chunk's declared size. None when the record is not such a chunk. Also says what was
    /// kept.
    fn cut_chunk(&self, pos: usize) -> Option<(Cow<'_, [u8]>, String)> {
        let rest = self.map.get(pos..)?;
        let hlen = u32::from_le_bytes(rest.get(..4)?.try_into().ok()?) as usize;
        let header = rest.get(4..4 + hlen)?;
        let fields = super::parse_fields(header).ok()?;
        let r = Record {
            fields,
            data: &[],
            end: 0,
        };
        if r.op().ok()? != OP_CHUNK {
            return None;
        }
        let size = r.u32("size").ok()? as u64;
        guard::check_decompressed("chunk", pos as u64, size, self.map.len() as u64).ok()?;
        let start = 4 + hlen + 4;
        let stored = rest
            .get(4 + hlen..start)
            .map_or(0, |b| u32::from_le_bytes(b.try_into().expect("4 bytes")));
        let avail = rest.get(start..).unwrap_or(&[]);
        let partial = |what: &str, reader: &mut dyn Read| -> (Cow<'_, [u8]>, String) {
            let mut out = Vec::new();
            let mut buf = [0u8; 1 << 14];
            while (out.len() as u64) < size {
                match reader.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => out.extend_from_slice(&buf[..n]),
                }
            }
            out.truncate(size as usize);
            let why = format!(
                "{} of its {stored} {what} bytes remain, {} of {size} bytes decompressed from them",
                avail.len(),
                out.len()
            );
            (Cow::Owned(out), why)
        };
        Some(match r.text("compression").ok()? {
            "none" => {
                let kept = &avail[..avail.len().min(size as usize)];
                (
                    Cow::Borrowed(kept),
                    format!("{} of its {size} bytes remain", kept.len()),
                )
            }
            "bz2" => partial("bz2", &mut bzip2::read::BzDecoder::new(avail)),
            "lz4" => {
                let mut d = lz4::Decoder::new(avail).ok()?;
                partial("lz4", &mut d)
            }
            _ => return None,
        })
    }
}

/// Why a file-order scan stopped: damage in the bag, or the caller's error.
enum Stop {
    Damage(String),
    Callback(BagError),
}

impl From<String> for Stop {
    fn from(s: String) -> Self {
        Stop::Damage(s)
    }
}

fn message<'a>(
    conn: &'a Connection,
    time: u64,
    data: &'a [u8],
    sequence: u32,
    path: &'a Path,
) -> BagMessage<'a> {
    BagMessage {
        topic: &conn.topic,
        type_name: &conn.type_name,
        encoding: "ros1",
        schema_encoding: "ros1msg",
        schema: conn.definition.as_bytes(),
        log_time: time,
        publish_time: time,
        sequence,
        data,
        path,
    }
}

/// The uncompressed data of a chunk record at byte `pos` of a file of `file_len` bytes. The
/// claimed size is held to [`guard::decompressed_bound`] before anything is allocated, and the
/// decompressor is never allowed to produce more than it (a damaged or hostile chunk is damage,
/// not a 4 GiB allocation).
fn decompress<'a>(r: &Record<'a>, pos: usize, file_len: u64) -> Result<Cow<'a, [u8]>, String> {
    let compression = r.text("compression")?;
    let claimed = r.u32("size")?;
    guard::check_decompressed("chunk", pos as u64, claimed as u64, file_len)?;
    let size = claimed as usize;
    let inflate = |what: &str, reader: &mut dyn Read| -> Result<Vec<u8>, String> {
        let mut out = Vec::with_capacity(size);
        reader
            .take(size as u64 + 1)
            .read_to_end(&mut out)
            .map_err(|e| format!("{what} chunk at byte {pos}: {e}"))?;
        Ok(out)
    };
    let out = match compression {
        "none" => Cow::Borrowed(r.data),
        "bz2" => Cow::Owned(inflate("bz2", &mut bzip2::read::BzDecoder::new(r.data))?),
        "lz4" => {
            let mut d =
                lz4::Decoder::new(r.data).map_err(|e| format!("lz4 chunk at byte {pos}: {e}"))?;
            Cow::Owned(inflate("lz4", &mut d)?)
        }
        other => {
            return Err(format!(
                "chunk at byte {pos} uses compression `{other}` (known: none, bz2, lz4)"
            ));
        }
    };
    if out.len() != size {
        return Err(format!(
            "chunk at byte {pos} holds {} bytes, its header says {size}",
            out.len()
        ));
    }
    Ok(out)
}
