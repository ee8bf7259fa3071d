//! Writing rosbag2 MCAP bags: a directory with `<name>_0.mcap` and the `metadata.yaml` that
//! `ros2 bag` and `rosbags` expect.

use crate::BagError;
use crate::schema::{SENSOR_QOS_YAML, ros2msg};
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Chunk compression.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Compression {
    /// Uncompressed chunks.
    None,
    /// zstd (rosbag2's default for MCAP).
    #[default]
    Zstd,
    /// lz4 frames.
    Lz4,
}

impl std::str::FromStr for Compression {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(Compression::None),
            "zstd" => Ok(Compression::Zstd),
            "lz4" => Ok(Compression::Lz4),
            other => Err(format!("unknown compression `{other}` (none, zstd, lz4)")),
        }
    }
}

/// The highest zstd level a bag may be written with (zstd's own range is 1..=22; 20 and up need
/// far more memory for little gain on camera frames).
pub const MAX_ZSTD_LEVEL: u32 = 19;

impl Compression {
    /// Parses a compression as command lines and configurations name it: `none`, `lz4`, `zstd`
    /// (zstd's default level, 3) or `zstd:LEVEL` (1..=19); returns it with its level (0: the
    /// codec's default).
    pub fn parse_spec(s: &str) -> Result<(Compression, u32), String> {
        match s.split_once(':') {
            None => Ok((s.parse()?, 0)),
            Some(("zstd", level)) => {
                let l = level
                    .parse::<u32>()
                    .ok()
                    .filter(|l| (1..=MAX_ZSTD_LEVEL).contains(l))
                    .ok_or_else(|| {
                        format!(
                            "zstd level `{level}` must be a whole number in 1..={MAX_ZSTD_LEVEL}"
                        )
                    })?;
                Ok((Compression::Zstd, l))
            }
            Some((name, _)) => Err(format!(
                "compression `{s}`: only zstd takes a level (zstd:1 .. zstd:{MAX_ZSTD_LEVEL}), `{name}` does not"
            )),
        }
    }
}

/// Options of a [`BagWriter`].
#[derive(Clone, Debug)]
pub struct WriterOptions {
    /// Chunk compression.
    pub compression: Compression,
    /// Compression level: zstd 1..=19; 0 is the codec's default (zstd 3, lz4's fast mode).
    pub level: u32,
    /// Chunk size in bytes before compression.
    pub chunk_size: u64,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            compression: Compression::Zstd,
            level: 0,
            chunk_size: 4 << 20,
        }
    }
}

struct Topic {
    name: String,
    type_name: String,
    qos: String,
    count: u64,
    sequence: u32,
}

/// Writes a rosbag2 bag (MCAP storage, CDR messages).
pub struct BagWriter {
    dir: PathBuf,
    file_name: String,
    writer: Option<mcap::Writer<BufWriter<std::fs::File>>>,
    topics: BTreeMap<u16, Topic>,
    first: Option<u64>,
    last: u64,
    count: u64,
}

impl std::fmt::Debug for BagWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagWriter")
            .field("dir", &self.dir)
            .field("count", &self.count)
            .finish()
    }
}

impl BagWriter {
    /// Creates the bag directory `dir` (it must not exist, or be empty) and its first file.
    pub fn create(dir: &Path, opts: &WriterOptions) -> Result<Self, BagError> {
        let werr = |reason: String| BagError::Write {
            path: dir.to_path_buf(),
            reason,
        };
        if dir.exists() {
            let empty = std::fs::read_dir(dir)
                .map_err(|source| BagError::Io {
                    path: dir.to_path_buf(),
                    source,
                })?
                .next()
                .is_none();
            if !empty {
                return Err(werr("the directory exists and is not empty".into()));
            }
        }
        std::fs::create_dir_all(dir).map_err(|source| BagError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let stem = dir
            .file_name()
            .and_then(|n| n.to_str())
            .filter(|s| !s.is_empty())
            .unwrap_or("bag")
            .to_string();
        let file_name = format!("{stem}_0.mcap");
        let path = dir.join(&file_name);
        let file = std::fs::File::create(&path).map_err(|source| BagError::Io {
            path: path.clone(),
            source,
        })?;
        let compression = match opts.compression {
            Compression::None => None,
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
        };
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("perturb-bag ", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .compression_level(opts.level)
            .chunk_size(Some(opts.chunk_size))
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(|e| werr(e.to_string()))?;
        Ok(BagWriter {
            dir: dir.to_path_buf(),
            file_name,
            writer: Some(writer),
            topics: BTreeMap::new(),
            first: None,
            last: 0,
            count: 0,
        })
    }

    fn werr(&self, reason: impl std::fmt::Display) -> BagError {
        BagError::Write {
            path: self.dir.clone(),
            reason: reason.to_string(),
        }
    }

    /// Adds a topic of a type this crate has a schema for (see [`crate::schema::KNOWN_TYPES`]),
    /// offered with sensor-data QoS; returns its channel id.
    pub fn add_topic(&mut self, topic: &str, type_name: &str) -> Result<u16, BagError> {
        let schema = ros2msg(type_name)
            .ok_or_else(|| self.werr(format!("no schema known for type `{type_name}`")))?;
        let mut meta = BTreeMap::new();
        meta.insert(
            "offered_qos_profiles".to_string(),
            SENSOR_QOS_YAML.to_string(),
        );
        self.add_topic_with_schema(topic, type_name, "ros2msg", schema.as_bytes(), meta)
    }

    /// Adds a topic with an explicit schema and channel metadata (to copy a topic from another
    /// bag); returns its channel id.
    pub fn add_topic_with_schema(
        &mut self,
        topic: &str,
        type_name: &str,
        schema_encoding: &str,
        schema: &[u8],
        metadata: BTreeMap<String, String>,
    ) -> Result<u16, BagError> {
        let w = self.writer.as_mut().ok_or_else(|| BagError::Write {
            path: PathBuf::new(),
            reason: "writer already finished".into(),
        })?;
        let sid = w
            .add_schema(type_name, schema_encoding, schema)
            .map_err(|e| BagError::Write {
                path: PathBuf::new(),
                reason: e.to_string(),
            })?;
        let qos = metadata
            .get("offered_qos_profiles")
            .cloned()
            .unwrap_or_default();
        let cid = w
            .add_channel(sid, topic, "cdr", &metadata)
            .map_err(|e| BagError::Write {
                path: PathBuf::new(),
                reason: e.to_string(),
            })?;
        self.topics.insert(
            cid,
            Topic {
                name: topic.to_string(),
                type_name: type_name.to_string(),
                qos,
                count: 0,
                sequence: 0,
            },
        );
        Ok(cid)
    }

    /// Writes one CDR message on a channel returned by `add_topic*`.
    pub fn write(
        &mut self,
        channel: u16,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), BagError> {
        let dir = self.dir.clone();
        let topic = self
            .topics
            .get_mut(&channel)
            .ok_or_else(|| BagError::Write {
                path: dir.clone(),
                reason: format!("unknown channel {channel}"),
            })?;
        topic.count += 1;
        topic.sequence = topic.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: topic.sequence,
            log_time,
            publish_time,
        };
        let w = self.writer.as_mut().ok_or_else(|| BagError::Write {
            path: dir.clone(),
            reason: "writer already finished".into(),
        })?;
        w.write_to_known_channel(&header, data)
            .map_err(|e| BagError::Write {
                path: dir,
                reason: e.to_string(),
            })?;
        self.first = Some(self.first.map_or(log_time, |f| f.min(log_time)));
        self.last = self.last.max(log_time);
        self.count += 1;
        Ok(())
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.count
    }

    /// Finishes the MCAP file (summary, index) and writes `metadata.yaml`; returns the directory.
    pub fn finish(mut self) -> Result<PathBuf, BagError> {
        self.finish_inner()?;
        Ok(self.dir.clone())
    }

    fn finish_inner(&mut self) -> Result<(), BagError> {
        let Some(mut w) = self.writer.take() else {
            return Ok(());
        };
        w.finish().map_err(|e| self.werr(e))?;
        let yaml = self.metadata_yaml();
        let path = self.dir.join("metadata.yaml");
        std::fs::write(&path, yaml).map_err(|source| BagError::Io { path, source })
    }

    fn metadata_yaml(&self) -> String {
        let start = self.first.unwrap_or(0);
        let duration = self.last.saturating_sub(start);
        // YAML double-quoted scalars keep escaped newlines (single-quoted ones fold them).
        let q = |s: &str| {
            let mut out = String::from("\"");
            for ch in s.chars() {
                match ch {
                    '"' => out.push_str("\\\""),
                    '\\' => out.push_str("\\\\"),
                    '\n' => out.push_str("\\n"),
                    c => out.push(c),
                }
            }
            out.push('"');
            out
        };
        let mut y = String::new();
        y.push_str("rosbag2_bagfile_information:\n");
        y.push_str("  version: 8\n  storage_identifier: mcap\n");
        y.push_str(&format!("  duration:\n    nanoseconds: {duration}\n"));
        y.push_str(&format!(
            "  starting_time:\n    nanoseconds_since_epoch: {start}\n"
        ));
        y.push_str(&format!("  message_count: {}\n", self.count));
        y.push_str("  topics_with_message_count:\n");
        for t in self.topics.values() {
            y.push_str("    - topic_metadata:\n");
            y.push_str(&format!("        name: {}\n", q(&t.name)));
            y.push_str(&format!("        type: {}\n", t.type_name));
            y.push_str("        serialization_format: cdr\n");
            y.push_str(&format!("        offered_qos_profiles: {}\n", q(&t.qos)));
            y.push_str("        type_description_hash: ''\n");
            y.push_str(&format!("      message_count: {}\n", t.count));
        }
        y.push_str("  compression_format: ''\n  compression_mode: ''\n");
        y.push_str(&format!(
            "  relative_file_paths:\n    - {}\n",
            self.file_name
        ));
        y.push_str("  files:\n");
        y.push_str(&format!("    - path: {}\n", self.file_name));
        y.push_str(&format!(
            "      starting_time:\n        nanoseconds_since_epoch: {start}\n"
        ));
        y.push_str(&format!(
            "      duration:\n        nanoseconds: {duration}\n"
        ));
        y.push_str(&format!("      message_count: {}\n", self.count));
        y.push_str("  custom_data: ~\n  ros_distro: ''\n");
        y
    }
}

impl Drop for BagWriter {
    fn drop(&mut self) {
        // A writer dropped without finish (e.g. on an error path) still leaves a readable bag.
        let _ = self.finish_inner();
    }
}
