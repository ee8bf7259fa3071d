//! Reading bags: rosbag2 MCAP (CDR), ROS 1 profile MCAP and ROS 1 `.bag` files, through one API
//! that delivers every message in log-time order with its topic, type, schema and encoding.

use crate::BagError;
use crate::guard;
use crate::message::{BagMessage, Bytes, Filter, ReadOrder, ReadReport, TopicInfo};
use crate::ros1::read::Ros1Bag;
use mcap::sans_io::indexed_reader::{IndexedReadEvent, IndexedReader, IndexedReaderOptions};
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::Arc;

struct File {
    path: PathBuf,
    map: Bytes,
    summary: Option<mcap::Summary>,
    summary_error: Option<String>,
}

/// An open bag: one `.mcap` file (rosbag2, or the ROS 1 profile), a rosbag2 directory of split
/// `.mcap` files, or a ROS 1 `.bag` file.
pub struct Bag {
    files: Vec<File>,
    ros1: Option<Box<Ros1Bag>>,
}

impl std::fmt::Debug for Bag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bag")
            .field(
                "files",
                &self
                    .files
                    .iter()
                    .map(|f| &f.path)
                    .chain(self.ros1.as_ref().map(|b| &b.path))
                    .collect::<Vec<_>>(),
            )
            .finish()
    }
}

/// Reads the Header record that follows the magic bytes (its lengths checked first) and returns
/// the profile (`ros2`, `ros1`, ...).
fn read_header(map: &[u8], path: &Path) -> Result<String, BagError> {
    let damaged = |reason: String| BagError::NotMcap {
        path: path.to_path_buf(),
        reason,
    };
    let rest = &map[8..];
    if rest.is_empty() {
        return Err(damaged(
            "the file ends right after the magic bytes: truncated, no Header record and no message (damaged)"
                .into(),
        ));
    }
    let records = guard::mcap_records_prefix(rest, 8, map.len() as u64, 1)
        .map_err(|e| damaged(format!("damaged at the start: {e}")))?;
    let Some(&(opcode, body, _)) = records.first() else {
        return Err(damaged("no Header record after the magic bytes".into()));
    };
    match mcap::read::parse_record(opcode, body) {
        Ok(mcap::records::Record::Header(h)) => Ok(h.profile),
        Ok(_) => Err(damaged(format!(
            "the first record (opcode 0x{opcode:02x}) is not a Header record"
        ))),
        Err(e) => Err(damaged(format!("the Header record is unreadable: {e}"))),
    }
}

/// Checks the lengths of every record of the summary section (the footer says where it is) and
/// of every chunk the summary's index points to, so `mcap::Summary::read` and the indexed reader
/// only ever see lengths that fit the file. `Ok(())` also for a file without footer or summary
/// (the summary reader then says what is missing).
fn check_summary(map: &[u8]) -> Result<(), String> {
    const FOOTER_RECORD: usize = 9 + 20;
    let len = map.len();
    if len < 8 + FOOTER_RECORD + 8 || &map[len - 8..] != mcap::MAGIC {
        return Ok(());
    }
    let footer_at = len - 8 - FOOTER_RECORD;
    let footer = &map[footer_at..len - 8];
    if footer[0] != 0x02 || footer[1..9] != 20u64.to_le_bytes() {
        // The `mcap` crate reads the footer's fields at their fixed place whatever its record
        // header says (found by fuzzing: a footer of length 96 sent it into unchecked records).
        return Err(format!(
            "the Footer record at byte {footer_at} is damaged (opcode 0x{:02x}, length {}; expected 0x02 and 20)",
            footer[0],
            u64::from_le_bytes(footer[1..9].try_into().expect("8 bytes"))
        ));
    }
    let summary_start = u64::from_le_bytes(footer[9..17].try_into().expect("8 bytes"));
    if summary_start == 0 {
        return Ok(());
    }
    if summary_start < 8 || summary_start > footer_at as u64 {
        return Err(format!(
            "the footer puts the summary at byte {summary_start}, outside the file's {footer_at} bytes before the footer"
        ));
    }
    guard::mcap_records(
        &map[summary_start as usize..footer_at],
        summary_start,
        len as u64,
    )
    .map(|_| ())
}

/// Checks that every chunk the summary indexes lies inside the file.
fn check_chunk_indexes(summary: &mcap::Summary, file_len: u64) -> Result<(), String> {
    for (i, ci) in summary.chunk_indexes.iter().enumerate() {
        let end = ci.chunk_start_offset.checked_add(ci.chunk_length);
        if end.is_none_or(|e| e > file_len) {
            return Err(format!(
                "chunk index {i} points at bytes {}..+{} past the end of the file ({file_len} bytes): truncated",
                ci.chunk_start_offset, ci.chunk_length
            ));
        }
        guard::check_decompressed(
            &format!("chunk index {i}"),
            ci.chunk_start_offset,
            ci.uncompressed_size,
            file_len,
        )?;
    }
    Ok(())
}

// A memory-mapped bag file.
#[allow(unsafe_code)]
fn map_file(path: &Path) -> Result<memmap2::Mmap, BagError> {
    let io = |source| BagError::Io {
        path: path.to_path_buf(),
        source,
    };
    let f = std::fs::File::open(path).map_err(io)?;
    // SAFETY: the map is read-only and the bag is not expected to change while it is read; a
    // concurrent truncation by another process would be a user error this crate cannot prevent.
    unsafe { memmap2::Mmap::map(&f) }.map_err(io)
}

fn open_file(path: &Path, map: memmap2::Mmap) -> Result<File, BagError> {
    file_from_bytes(path, Bytes::Map(map))
}

/// Checks a file's bytes and reads its header (whose lengths are checked first, so a damaged
/// start is reported, not read as an empty bag) and its summary.
fn file_from_bytes(path: &Path, map: Bytes) -> Result<File, BagError> {
    if map.len() < 8 || &map[..8] != mcap::MAGIC {
        return Err(BagError::NotMcap {
            path: path.to_path_buf(),
            reason: "the file does not start with the MCAP magic bytes nor `#ROSBAG V2.0`".into(),
        });
    }
    // The Header record (rosbag2 or ROS 1 profile alike) must be there and whole.
    read_header(&map, path)?;
    let file_len = map.len() as u64;
    let summary = check_summary(&map).and_then(|()| {
        mcap::Summary::read(&map).map_err(|e| format!("the summary is unreadable ({e})"))
    });
    let (summary, summary_error) = match summary {
        Ok(Some(s))
            if !s.chunk_indexes.is_empty()
                || s.stats.as_ref().is_some_and(|st| st.message_count == 0) =>
        {
            match check_chunk_indexes(&s, file_len) {
                Ok(()) => (Some(s), None),
                Err(e) => (None, Some(format!("the summary is unusable: {e}"))),
            }
        }
        Ok(Some(_)) => (None, Some("the summary has no chunk index".to_string())),
        Ok(None) => (None, Some("the file has no summary section".to_string())),
        Err(e) if e.starts_with("the summary") => (None, Some(e)),
        Err(e) => (None, Some(format!("the summary is damaged: {e}"))),
    };
    Ok(File {
        path: path.to_path_buf(),
        map,
        summary,
        summary_error,
    })
}

impl Bag {
    /// Opens an `.mcap` file, a rosbag2 directory holding `.mcap` files (read in name order,
    /// which is recording order for split bags) or a ROS 1 `.bag` file; the format is told by the
    /// file's first bytes.
    pub fn open(path: &Path) -> Result<Bag, BagError> {
        if !path.is_dir() {
            let map = map_file(path)?;
            if Ros1Bag::sniff(&map) {
                return Ok(Bag {
                    files: Vec::new(),
                    ros1: Some(Box::new(Ros1Bag::open(path, Bytes::Map(map))?)),
                });
            }
        }
        let paths = if path.is_dir() {
            let rd = std::fs::read_dir(path).map_err(|source| BagError::Io {
                path: path.to_path_buf(),
                source,
            })?;
            let mut v: Vec<PathBuf> = rd
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
                .collect();
            v.sort();
            if v.is_empty() {
                // A directory holding one ROS 1 bag (as `perturb apply` and `perturb batch`
                // write them).
                let bags: Vec<PathBuf> = std::fs::read_dir(path)
                    .map_err(|source| BagError::Io {
                        path: path.to_path_buf(),
                        source,
                    })?
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| p.extension().is_some_and(|x| x == "bag"))
                    .collect();
                if let [one] = &bags[..] {
                    return Bag::open(one);
                }
            }
            if v.is_empty() {
                return Err(BagError::NotMcap {
                    path: path.to_path_buf(),
                    reason: "the directory holds no .mcap file nor one .bag file (sqlite3 rosbag2 storage is not supported; re-record with `--storage mcap` or convert with `ros2 bag convert`)".into(),
                });
            }
            v
        } else {
            vec![path.to_path_buf()]
        };
        let files = paths
            .iter()
            .map(|p| open_file(p, map_file(p)?))
            .collect::<Result<_, _>>()?;
        Ok(Bag { files, ros1: None })
    }

    /// A one-file bag held in memory (MCAP or a ROS 1 `.bag`, told by its first bytes); `name`
    /// stands for its path in messages.
    pub fn from_bytes(name: &Path, bytes: Vec<u8>) -> Result<Bag, BagError> {
        if Ros1Bag::sniff(&bytes) {
            return Ok(Bag {
                files: Vec::new(),
                ros1: Some(Box::new(Ros1Bag::open(name, Bytes::Owned(bytes))?)),
            });
        }
        Ok(Bag {
            files: vec![file_from_bytes(name, Bytes::Owned(bytes))?],
            ros1: None,
        })
    }

    /// The files of the bag.
    pub fn paths(&self) -> Vec<&Path> {
        self.files
            .iter()
            .map(|f| f.path.as_path())
            .chain(self.ros1.as_ref().map(|b| b.path.as_path()))
            .collect()
    }

    /// True for a ROS 1 `.bag` file (its messages are in ROS 1 serialization, as are those of
    /// ROS 1 profile MCAP files: see [`BagMessage::is_ros1`]).
    pub fn is_ros1_bag(&self) -> bool {
        self.ros1.is_some()
    }

    /// What kind of bag it is: `ROS 1 bag (format 2.0)`, `MCAP (ROS 1 profile)` or
    /// `rosbag2 MCAP`.
    pub fn format_name(&self) -> &'static str {
        if self.ros1.is_some() {
            "ROS 1 bag (format 2.0)"
        } else if self.files.iter().any(|f| {
            f.summary
                .as_ref()
                .is_some_and(|s| s.channels.values().any(|c| c.message_encoding == "ros1"))
        }) {
            "MCAP (ROS 1 profile)"
        } else {
            "rosbag2 MCAP"
        }
    }

    /// True if every file has a usable index (messages come in log-time order).
    pub fn is_indexed(&self) -> bool {
        match &self.ros1 {
            Some(b) => b.is_indexed(),
            None => self.files.iter().all(|f| f.summary.is_some()),
        }
    }

    /// Why the bag is read in file order, if it is.
    pub fn index_problem(&self) -> Option<String> {
        match &self.ros1 {
            Some(b) => b
                .index_error()
                .map(|e| format!("{}: {e}", b.path.display())),
            None => self.files.iter().find_map(|f| {
                f.summary_error
                    .as_ref()
                    .map(|e| format!("{}: {e}", f.path.display()))
            }),
        }
    }

    /// The topics of the bag with their types and, where the bag has statistics, message counts.
    /// For a bag without a summary the topics are collected by scanning it.
    pub fn topics(&self) -> Result<Vec<TopicInfo>, BagError> {
        if let Some(b) = &self.ros1 {
            return b.topics();
        }
        let mut by_topic: BTreeMap<String, TopicInfo> = BTreeMap::new();
        for f in &self.files {
            let mut add = |ch: &mcap::Channel<'_>, count: Option<u64>| {
                let (type_name, enc, schema) = ch
                    .schema
                    .as_ref()
                    .map(|s| (s.name.clone(), s.encoding.clone(), s.data.to_vec()))
                    .unwrap_or_default();
                let e = by_topic
                    .entry(ch.topic.clone())
                    .or_insert_with(|| TopicInfo {
                        topic: ch.topic.clone(),
                        type_name,
                        schema_encoding: enc,
                        schema,
                        message_encoding: ch.message_encoding.clone(),
                        metadata: ch.metadata.clone(),
                        message_count: Some(0),
                    });
                e.message_count = match (e.message_count, count) {
                    (Some(a), Some(b)) => Some(a + b),
                    _ => None,
                };
            };
            match &f.summary {
                Some(s) => {
                    for (id, ch) in &s.channels {
                        let count = s
                            .stats
                            .as_ref()
                            .and_then(|st| st.channel_message_counts.get(id).copied());
                        add(ch, count);
                    }
                }
                None => {
                    let mut counts: BTreeMap<String, (Arc<mcap::Channel<'static>>, u64)> =
                        BTreeMap::new();
                    // Damage ends the count; reading the bag reports it.
                    let _ = scan_linear(f, |ch, _, _| {
                        counts.entry(ch.topic.clone()).or_insert((ch.clone(), 0)).1 += 1;
                        Ok(ControlFlow::Continue(()))
                    })?;
                    for (_, (ch, n)) in counts {
                        add(&ch, Some(n));
                    }
                }
            }
        }
        Ok(by_topic.into_values().collect())
    }

    /// Calls `f` for every message passing `filter`, in log-time order (file order for a bag
    /// without a usable index). `f` returns `Break` to stop early. Damage found part-way is
    /// reported in the [`ReadReport`], after the messages before it were delivered.
    pub fn for_each<F>(&self, filter: &Filter, mut f: F) -> Result<ReadReport, BagError>
    where
        F: FnMut(BagMessage<'_>) -> Result<ControlFlow<()>, BagError>,
    {
        let mut report = ReadReport {
            delivered: 0,
            order: if self.is_indexed() {
                ReadOrder::LogTime
            } else {
                ReadOrder::FileOrder
            },
            damage: None,
            notes: Vec::new(),
        };
        if let Some(b) = &self.ros1 {
            let _ = b.for_each(filter, &mut f, &mut report)?;
            return Ok(report);
        }
        for file in &self.files {
            let flow = match &file.summary {
                Some(s) => read_indexed(file, s, filter, &mut f, &mut report)?,
                None => read_linear(file, filter, &mut f, &mut report)?,
            };
            if flow.is_break() || report.damage.is_some() {
                break;
            }
        }
        Ok(report)
    }
}

fn read_indexed<F>(
    file: &File,
    summary: &mcap::Summary,
    filter: &Filter,
    f: &mut F,
    report: &mut ReadReport,
) -> Result<ControlFlow<()>, BagError>
where
    F: FnMut(BagMessage<'_>) -> Result<ControlFlow<()>, BagError>,
{
    let file_len = file.map.len() as u64;
    let mut opts = IndexedReaderOptions::new().with_record_length_limit(
        usize::try_from(guard::decompressed_bound(file_len)).unwrap_or(usize::MAX),
    );
    if !filter.topics.is_empty() {
        opts = opts.include_topics(filter.topics.clone());
    }
    if let Some(s) = filter.start {
        opts = opts.starting_at(s);
    }
    if let Some(e) = filter.end {
        opts = opts.ending_before(e);
    }
    let mut reader =
        IndexedReader::new_with_options(summary, opts).map_err(|e| BagError::NotMcap {
            path: file.path.clone(),
            reason: e.to_string(),
        })?;
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(e) => {
                report.damage = Some(format!("{}: {e}", file.path.display()));
                return Ok(ControlFlow::Continue(()));
            }
        };
        match event {
            IndexedReadEvent::ReadChunkRequest { offset, length } => {
                let start = offset as usize;
                let Some(end) = start.checked_add(length).filter(|&e| e <= file.map.len()) else {
                    report.damage = Some(format!(
                        "{}: chunk at byte {start} ({length} bytes) runs past the end of the file ({} bytes): truncated",
                        file.path.display(),
                        file.map.len()
                    ));
                    return Ok(ControlFlow::Continue(()));
                };
                // The compressed records of a chunk; its sizes were checked against the file
                // and the decompressed bound when the bag was opened.
                if let Err(e) = reader.insert_chunk_record_data(offset, &file.map[start..end]) {
                    report.damage = Some(format!(
                        "{}: chunk at byte {start}: {e}",
                        file.path.display()
                    ));
                    return Ok(ControlFlow::Continue(()));
                }
            }
            IndexedReadEvent::Message { header, data } => {
                let Some(ch) = summary.channels.get(&header.channel_id) else {
                    report.damage = Some(format!(
                        "{}: message on unknown channel {}",
                        file.path.display(),
                        header.channel_id
                    ));
                    return Ok(ControlFlow::Continue(()));
                };
                report.delivered += 1;
                let flow = f(mcap_message(
                    ch,
                    &file.path,
                    header.log_time,
                    header.publish_time,
                    header.sequence,
                    data,
                ))?;
                if flow.is_break() {
                    return Ok(flow);
                }
            }
        }
    }
    Ok(ControlFlow::Continue(()))
}

/// The records of a chunk, decompressed here (not by the `mcap` crate, so every inner length
/// goes through the guard too): `body` is the Chunk record's body, checked by
/// [`guard::check_mcap_record`] (its compressed size fits, its decompressed size is bounded).
fn chunk_records(body: &[u8], at: u64, file_len: u64) -> Result<Vec<u8>, String> {
    let Ok(mcap::records::Record::Chunk { header, data }) = mcap::read::parse_record(0x06, body)
    else {
        return Err(format!("Chunk record at byte {at} is unreadable"));
    };
    let size = usize::try_from(header.uncompressed_size)
        .map_err(|_| format!("Chunk record at byte {at}: size not addressable"))?;
    let out = match header.compression.as_str() {
        "" => data.to_vec(),
        "zstd" => zstd::bulk::decompress(&data, size)
            .map_err(|e| format!("Chunk record at byte {at}: zstd: {e}"))?,
        "lz4" => {
            use std::io::Read;
            let mut out = Vec::new();
            lz4::Decoder::new(&data[..])
                .map_err(|e| format!("Chunk record at byte {at}: lz4: {e}"))?
                .take(size as u64 + 1)
                .read_to_end(&mut out)
                .map_err(|e| format!("Chunk record at byte {at}: lz4: {e}"))?;
            out
        }
        other => {
            return Err(format!(
                "Chunk record at byte {at}: compression `{other}` is not supported (zstd, lz4, none)"
            ));
        }
    };
    if out.len() != size {
        return Err(format!(
            "Chunk record at byte {at} holds {} bytes once decompressed, its header says {size}",
            out.len()
        ));
    }
    let _ = file_len;
    Ok(out)
}

/// Reads a file record by record in file order (no index needed), checking every length before
/// the `mcap` crate parses a record (chunks are unpacked here, their records checked the same
/// way), and calls `on_message` for each message with its channel. Returns how the callback left
/// the read and the damage found, if any: an unreadable record, or a file that ends without its
/// Data End record (a recording that was cut short).
fn scan_linear<F>(
    file: &File,
    mut on_message: F,
) -> Result<(ControlFlow<()>, Option<String>), BagError>
where
    F: FnMut(
        &Arc<mcap::Channel<'static>>,
        &mcap::records::MessageHeader,
        &[u8],
    ) -> Result<ControlFlow<()>, BagError>,
{
    let map: &[u8] = &file.map;
    let file_len = map.len() as u64;
    let mut channels = mcap::read::ChannelAccumulator::default();
    let mut handle = |opcode: u8, data: &[u8], near: u64| -> Result<Step, ScanError> {
        let record = guard::check_mcap_record(opcode, data, near, file_len)
            .and_then(|()| {
                mcap::read::parse_record(opcode, data)
                    .map_err(|e| format!("record 0x{opcode:02x} near byte {near}: {e}"))
            })
            .map_err(Ok)?;
        use mcap::records::Record;
        let added = match record {
            Record::Schema { header, data } => channels.add_schema_from_slice(header, &data),
            Record::Channel(c) => channels.add_channel(c),
            Record::Message { header, data } => {
                let Some(ch) = channels.get(header.channel_id) else {
                    return Err(Ok(format!(
                        "near byte {near}: message on channel {} that no Channel record defined",
                        header.channel_id
                    )));
                };
                return match on_message(&ch, &header, &data) {
                    Ok(flow) if flow.is_break() => Ok(Step::Stop),
                    Ok(_) => Ok(Step::Go),
                    Err(e) => Err(Err(e)),
                };
            }
            // The data section ends here: what follows is the summary, read separately.
            Record::DataEnd(_) | Record::Footer(_) => return Ok(Step::End),
            _ => Ok(()),
        };
        added
            .map(|()| Step::Go)
            .map_err(|e| Ok(format!("near byte {near}: {e}")))
    };
    let mut ended = false;
    // Top-level records are walked here, each length checked against the file; a chunk is
    // unpacked by `chunk_records` and its records walked the same way.
    let mut pos = 8usize;
    while pos < map.len() && !ended {
        match next_records(map, &mut pos, &mut handle) {
            Ok(v) => {
                if v.iter().any(|s| matches!(s, Step::Stop)) {
                    return Ok((ControlFlow::Break(()), None));
                }
                if v.iter().any(|s| matches!(s, Step::End)) {
                    ended = true;
                }
            }
            Err(Ok(damage)) => return Ok((ControlFlow::Continue(()), Some(damage))),
            Err(Err(e)) => return Err(e),
        }
    }
    let damage = (!ended).then(|| {
        format!("the file ends at byte {file_len} without its Data End record and footer: truncated (a recording that was cut short?)")
    });
    Ok((ControlFlow::Continue(()), damage))
}

/// What one record did to a linear scan.
enum Step {
    Go,
    Stop,
    End,
}

/// Why a linear scan ends early: damage (`Ok`, described; the records before it were delivered)
/// or the caller's error (`Err`).
type ScanError = Result<String, BagError>;

/// A record handler of [`scan_linear`]: (opcode, body, the byte it is near).
type Handle<'h> = dyn FnMut(u8, &[u8], u64) -> Result<Step, ScanError> + 'h;

/// Walks the top-level record at `*pos` of `map` (moving `pos` past it): a chunk's records, or the
/// record itself. A record cut by the end of the file is damage, after the whole records of an
/// uncompressed chunk before the cut.
fn next_records(
    map: &[u8],
    pos: &mut usize,
    handle: &mut Handle<'_>,
) -> Result<Vec<Step>, ScanError> {
    let file_len = map.len() as u64;
    let rest = &map[*pos..];
    let at = *pos as u64;
    if rest.len() < 9 {
        return Err(Ok(format!(
            "the file ends inside the record header at byte {at}: truncated"
        )));
    }
    let opcode = rest[0];
    let len = u64::from_le_bytes(rest[1..9].try_into().expect("8 bytes"));
    let avail = (rest.len() - 9) as u64;
    if len > avail {
        return truncated_record(rest, at, file_len, (opcode, len, avail), handle);
    }
    let body = &rest[9..9 + len as usize];
    *pos += 9 + len as usize;
    if opcode != 0x06 {
        return handle(opcode, body, at).map(|s| vec![s]);
    }
    let recs = guard::check_mcap_record(0x06, body, at, file_len)
        .and_then(|()| chunk_records(body, at, file_len))
        .and_then(|inner| {
            let recs = guard::mcap_records(&inner, 0, file_len)
                .map_err(|e| format!("in the chunk at byte {at} (offset within it): {e}"))?;
            Ok(recs
                .iter()
                .map(|&(op, body, _)| (op, body.to_vec()))
                .collect::<Vec<_>>())
        })
        .map_err(Ok)?;
    let mut v = Vec::new();
    for (op, body) in recs {
        let st = handle(op, &body, at)?;
        let stop = !matches!(st, Step::Go);
        v.push(st);
        if stop {
            break;
        }
    }
    Ok(v)
}

/// A record that claims more bytes than remain. From an uncompressed chunk, the whole records
/// before the cut are still delivered; the result is the damage unless one of them stopped the
/// scan.
fn truncated_record(
    rest: &[u8],
    at: u64,
    file_len: u64,
    (opcode, len, avail): (u8, u64, u64),
    handle: &mut Handle<'_>,
) -> Result<Vec<Step>, ScanError> {
    let mut v = Vec::new();
    let mut why = format!(
        "record 0x{opcode:02x} at byte {at} claims {len} bytes but only {avail} remain: truncated"
    );
    if opcode == 0x06 && rest.len() >= 9 + 32 {
        let clen = u32::from_le_bytes(rest[37..41].try_into().expect("4 bytes")) as usize;
        let start = 9 + 32 + clen + 8;
        if clen == 0 && rest.len() >= start {
            let (recs, _) = guard::mcap_records_salvage(&rest[start..], at, file_len);
            for (op, body, _) in recs {
                match handle(op, body, at) {
                    Ok(st) => {
                        let stop = !matches!(st, Step::Go);
                        v.push(st);
                        if stop {
                            break;
                        }
                    }
                    Err(Ok(d)) => {
                        why = d;
                        break;
                    }
                    Err(Err(e)) => return Err(Err(e)),
                }
            }
        }
    }
    if v.iter().any(|s| matches!(s, Step::Stop)) {
        return Ok(v);
    }
    Err(Ok(why))
}

fn read_linear<F>(
    file: &File,
    filter: &Filter,
    f: &mut F,
    report: &mut ReadReport,
) -> Result<ControlFlow<()>, BagError>
where
    F: FnMut(BagMessage<'_>) -> Result<ControlFlow<()>, BagError>,
{
    let (flow, damage) = scan_linear(file, |ch, header, data| {
        if !filter.accepts(&ch.topic, header.log_time) {
            return Ok(ControlFlow::Continue(()));
        }
        report.delivered += 1;
        f(mcap_message(
            ch,
            &file.path,
            header.log_time,
            header.publish_time,
            header.sequence,
            data,
        ))
    })?;
    if flow.is_break() {
        return Ok(flow);
    }
    if let Some(e) = damage {
        report.damage = Some(format!(
            "{}: {} ({}; read in file order because {})",
            file.path.display(),
            e,
            if report.delivered == 0 {
                "no message before it"
            } else {
                "messages before it were read"
            },
            file.summary_error
                .as_deref()
                .unwrap_or("the index is unusable")
        ));
        return Ok(ControlFlow::Continue(()));
    }
    if let Some(why) = &file.summary_error {
        report.notes.push(format!(
            "{}: {why}; messages were read in file order",
            file.path.display()
        ));
    }
    Ok(ControlFlow::Continue(()))
}

/// A message of an MCAP channel.
fn mcap_message<'a>(
    ch: &'a mcap::Channel<'_>,
    path: &'a Path,
    log_time: u64,
    publish_time: u64,
    sequence: u32,
    data: &'a [u8],
) -> BagMessage<'a> {
    let (type_name, schema_encoding, schema) = ch.schema.as_ref().map_or(("", "", &[][..]), |s| {
        (s.name.as_str(), s.encoding.as_str(), &s.data[..])
    });
    BagMessage {
        topic: &ch.topic,
        type_name,
        encoding: &ch.message_encoding,
        schema_encoding,
        schema,
        log_time,
        publish_time,
        sequence,
        data,
        path,
    }
}
