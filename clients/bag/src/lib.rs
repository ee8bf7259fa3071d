//! # perturb-bag
//!
//! Bags: reading sensor messages in log-time order (the order a replayer needs, which is not
//! always file order) from rosbag2 MCAP bags, ROS 1 profile MCAP files and ROS 1 `.bag` files
//! (format 2.0, uncompressed, bz2 or lz4 chunks) through one API ([`Bag`]), and writing rosbag2
//! bags that `ros2 bag`, the Python `rosbags` package and the `mcap` tools read ([`BagWriter`]) or
//! ROS 1 bags that `rosbag info`/`rosbag play` read ([`ros1::Ros1Writer`]), or either through
//! [`AnyWriter`].
//!
//! Reading memory-maps the file and decompresses one chunk at a time, so a bag of hundreds of
//! gigabytes replays in bounded memory. A bag whose index is missing or corrupt (a recorder that
//! was killed, a truncated copy) is read in file order up to the damage, and the damage is
//! reported. Each message says its encoding (`cdr` or `ros1`) and carries its type's schema;
//! [`BagMessage::decode`] decodes the sensor types in either.
//!
//! ```no_run
//! use perturb_bag::{Bag, Filter};
//! let bag = Bag::open("recording.mcap".as_ref())?;
//! let report = bag.for_each(&Filter::default(), |msg| {
//!     println!("{} {} {} bytes", msg.log_time, msg.topic, msg.data.len());
//!     Ok(std::ops::ControlFlow::Continue(()))
//! })?;
//! println!("{} messages, damage: {:?}", report.delivered, report.damage);
//! # Ok::<(), perturb_bag::BagError>(())
//! ```

pub mod dynamic;
pub mod events;
pub mod guard;
mod message;
mod read;
pub mod ros1;
pub mod schema;
mod write;
mod writer;

pub use message::{
    BagMessage, Filter, ReadOrder, ReadReport, SensorMessage, SensorType, TopicInfo,
};
pub use read::Bag;
pub use write::{BagWriter, Compression, WriterOptions};
pub use writer::{AnyWriter, BagFormat, check_compression};

use std::path::PathBuf;

/// What can go wrong with a bag; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// The file or directory could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a readable bag (MCAP or ROS 1 `.bag`).
    #[error("{path}: not a readable bag: {reason}")]
    NotMcap {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A message could not be decoded.
    #[error("{path}: message on `{topic}` at log time {log_time} ns: {source}")]
    Message {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// Its log time.
        log_time: u64,
        /// The decoding error.
        source: perturb_core::Error,
    },
    /// Writing the bag failed.
    #[error("{path}: cannot write bag: {reason}")]
    Write {
        /// The bag directory or file.
        path: PathBuf,
        /// What failed.
        reason: String,
    },
    /// The caller's callback stopped the read with an error.
    #[error("{0}")]
    Callback(String),
}
