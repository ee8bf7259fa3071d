//! One writer for both bag formats, so a tool writes its output in the format of its input
//! (`perturb apply`) or in the format the user chose (`perturb-bridge record --format bag1`).

use crate::ros1::{Ros1Compression, Ros1Writer, Ros1WriterOptions};
use crate::{BagError, BagWriter, Compression, TopicInfo, WriterOptions};
use std::path::{Path, PathBuf};

/// A bag format.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BagFormat {
    /// rosbag2 with MCAP storage: a directory with `NAME_0.mcap` and `metadata.yaml`; CDR.
    #[default]
    Rosbag2,
    /// A ROS 1 `.bag` file (format 2.0); ROS 1 serialization.
    Ros1,
}

impl BagFormat {
    /// The format a path asks for: a `.bag` file is ROS 1, anything else rosbag2.
    pub fn of_path(path: &Path) -> Self {
        if path.extension().is_some_and(|e| e == "bag") {
            BagFormat::Ros1
        } else {
            BagFormat::Rosbag2
        }
    }

    /// The message encoding of the format: `cdr` or `ros1`.
    pub fn encoding(self) -> &'static str {
        match self {
            BagFormat::Rosbag2 => "cdr",
            BagFormat::Ros1 => "ros1",
        }
    }
}

impl std::str::FromStr for BagFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "mcap" | "rosbag2" => Ok(BagFormat::Rosbag2),
            "bag1" | "ros1" | "bag" => Ok(BagFormat::Ros1),
            o => Err(format!(
                "unknown bag format `{o}` (mcap: rosbag2 MCAP; bag1: ROS 1 .bag)"
            )),
        }
    }
}

/// Checks a chunk compression as [`AnyWriter::create`] takes it for `format`: for rosbag2
/// `none`, `lz4`, `zstd` or `zstd:LEVEL` (1..=19); for ROS 1 `none`, `bz2` or `lz4`. The error
/// says what is wrong and what is known.
pub fn check_compression(format: BagFormat, spec: &str) -> Result<(), String> {
    match format {
        BagFormat::Rosbag2 => Compression::parse_spec(spec).map(|_| ()),
        BagFormat::Ros1 => spec.parse::<Ros1Compression>().map(|_| ()),
    }
}

/// A bag being written, in either format.
#[derive(Debug)]
pub enum AnyWriter {
    /// rosbag2 MCAP.
    Rosbag2(Box<BagWriter>),
    /// ROS 1 `.bag`, and the directory holding it when the bag was asked for as a directory.
    Ros1(Box<Ros1Writer>, Option<PathBuf>),
}

impl AnyWriter {
    /// Creates a bag at `path` with chunk `compression` (rosbag2: none, zstd, zstd:LEVEL with
    /// LEVEL 1..=19, lz4, default zstd; ROS 1: none, bz2, lz4, default none). A rosbag2 bag is a directory; a ROS 1 bag is the
    /// file `path` when it ends in `.bag`, else the file `NAME.bag` in the new directory `path`
    /// (as rosbag2 puts `NAME_0.mcap` in its directory), which [`crate::Bag::open`] also opens.
    pub fn create(
        path: &Path,
        format: BagFormat,
        compression: Option<&str>,
    ) -> Result<Self, BagError> {
        let bad = |reason: String| BagError::Write {
            path: path.to_path_buf(),
            reason,
        };
        Ok(match format {
            BagFormat::Rosbag2 => {
                let (compression, level) = match compression {
                    Some(c) => Compression::parse_spec(c).map_err(bad)?,
                    None => (Compression::Zstd, 0),
                };
                AnyWriter::Rosbag2(Box::new(BagWriter::create(
                    path,
                    &WriterOptions {
                        compression,
                        level,
                        ..Default::default()
                    },
                )?))
            }
            BagFormat::Ros1 => {
                let compression = match compression {
                    Some(c) => c.parse::<Ros1Compression>().map_err(bad)?,
                    None => Ros1Compression::None,
                };
                let (file, dir) = if path.extension().is_some_and(|e| e == "bag") {
                    (path.to_path_buf(), None)
                } else {
                    let empty = !path.exists()
                        || std::fs::read_dir(path)
                            .map_err(|source| BagError::Io {
                                path: path.to_path_buf(),
                                source,
                            })?
                            .next()
                            .is_none();
                    if !empty {
                        return Err(bad("the directory exists and is not empty".into()));
                    }
                    std::fs::create_dir_all(path).map_err(|source| BagError::Io {
                        path: path.to_path_buf(),
                        source,
                    })?;
                    let stem = path
                        .file_name()
                        .and_then(|n| n.to_str())
                        .filter(|s| !s.is_empty())
                        .unwrap_or("bag");
                    (path.join(format!("{stem}.bag")), Some(path.to_path_buf()))
                };
                AnyWriter::Ros1(
                    Box::new(Ros1Writer::create(
                        &file,
                        &Ros1WriterOptions {
                            compression,
                            ..Default::default()
                        },
                    )?),
                    dir,
                )
            }
        })
    }

    /// The format being written.
    pub fn format(&self) -> BagFormat {
        match self {
            AnyWriter::Rosbag2(_) => BagFormat::Rosbag2,
            AnyWriter::Ros1(..) => BagFormat::Ros1,
        }
    }

    /// Adds a topic of a type the project has a schema for, named in either spelling
    /// (`sensor_msgs/msg/Image` or `sensor_msgs/Image`); returns its channel.
    pub fn add_topic(&mut self, topic: &str, type_name: &str) -> Result<u16, BagError> {
        match self {
            AnyWriter::Rosbag2(w) => {
                let name = perturb_core::formats::ros1::msg_type(type_name)
                    .map_or(type_name, |t| t.ros2_name);
                w.add_topic(topic, name)
            }
            AnyWriter::Ros1(w, _) => w.add_topic(topic, type_name),
        }
    }

    /// Adds a topic copied from a bag of the same format (type, schema, metadata); returns its
    /// channel.
    pub fn add_topic_like(&mut self, t: &TopicInfo) -> Result<u16, BagError> {
        match self {
            AnyWriter::Rosbag2(w) => w.add_topic_with_schema(
                &t.topic,
                &t.type_name,
                &t.schema_encoding,
                &t.schema,
                t.metadata.clone(),
            ),
            AnyWriter::Ros1(w, _) => {
                let md5 = t.metadata.get("md5sum").cloned().or_else(|| {
                    perturb_core::formats::ros1::msg_type(&t.type_name).map(|m| m.md5sum.into())
                });
                let Some(md5) = md5 else {
                    return Err(BagError::Write {
                        path: PathBuf::new(),
                        reason: format!("no md5sum known for `{}` ({})", t.topic, t.type_name),
                    });
                };
                w.add_connection(
                    &t.topic,
                    &t.type_name,
                    &md5,
                    &String::from_utf8_lossy(&t.schema),
                    t.metadata.get("callerid").map(String::as_str),
                    t.metadata
                        .get("latching")
                        .is_some_and(|l| l == "true" || l == "1"),
                )
            }
        }
    }

    /// Writes one message, serialized in the format's encoding ([`BagFormat::encoding`]).
    pub fn write(
        &mut self,
        channel: u16,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), BagError> {
        match self {
            AnyWriter::Rosbag2(w) => w.write(channel, log_time, publish_time, data),
            AnyWriter::Ros1(w, _) => w.write(channel, log_time, data),
        }
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        match self {
            AnyWriter::Rosbag2(w) => w.message_count(),
            AnyWriter::Ros1(w, _) => w.message_count(),
        }
    }

    /// Finishes the bag (index, summary); returns its path (the directory, if it was created
    /// as one).
    pub fn finish(self) -> Result<PathBuf, BagError> {
        match self {
            AnyWriter::Rosbag2(w) => w.finish(),
            AnyWriter::Ros1(w, dir) => {
                let file = w.finish()?;
                Ok(dir.unwrap_or(file))
            }
        }
    }
}
