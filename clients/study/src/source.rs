//! Recorded runs as the study reads them: open a bag, list its topics with their types and
//! schemas, and go through its messages in log-time order (topic, log time, raw bytes). Any bag
//! format plugs in behind [`RecordedRun`]; today every bag `perturb-bag` reads: rosbag2 MCAP (a
//! `.mcap` file or a rosbag2 directory), ROS 1 profile MCAP and ROS 1 `.bag` files.

use crate::error::{Result, StudyError};
use perturb_bag::{Bag, Filter};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// A topic of a recorded run and what is needed to decode its messages.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicSchema {
    /// Topic name.
    pub topic: String,
    /// Message type (`nav_msgs/msg/Odometry`, `nav_msgs/Odometry`).
    pub type_name: String,
    /// Schema encoding (`ros2msg`, `ros1msg`).
    pub schema_encoding: String,
    /// Schema text.
    pub schema: Vec<u8>,
    /// Message encoding (`cdr`, `ros1`).
    pub message_encoding: String,
}

/// One message of a recorded run, borrowed while the callback runs.
#[derive(Clone, Copy, Debug)]
pub struct RunMessage<'a> {
    /// Topic name.
    pub topic: &'a str,
    /// Receive (log) time, ns.
    pub log_time: u64,
    /// The serialised message.
    pub data: &'a [u8],
}

/// A recorded run: a bag of any supported format.
pub trait RecordedRun {
    /// The run's topics.
    fn topics(&self) -> Result<Vec<TopicSchema>>;
    /// Calls `f` for every message on `topics`, in log-time order. Returns a description of
    /// damage found part-way (the messages before it were delivered), if any.
    fn read(
        &self,
        topics: &[String],
        f: &mut dyn FnMut(RunMessage<'_>) -> Result<()>,
    ) -> Result<Option<String>>;
}

/// A run in any bag format `perturb-bag` reads.
pub struct BagRun(Bag);

impl RecordedRun for BagRun {
    fn topics(&self) -> Result<Vec<TopicSchema>> {
        Ok(self
            .0
            .topics()?
            .into_iter()
            .map(|t| TopicSchema {
                topic: t.topic,
                type_name: t.type_name,
                schema_encoding: t.schema_encoding,
                schema: t.schema,
                message_encoding: t.message_encoding,
            })
            .collect())
    }

    fn read(
        &self,
        topics: &[String],
        f: &mut dyn FnMut(RunMessage<'_>) -> Result<()>,
    ) -> Result<Option<String>> {
        let filter = Filter {
            topics: topics.to_vec(),
            ..Filter::default()
        };
        let mut failed = None;
        let report = self.0.for_each(&filter, |m| {
            match f(RunMessage {
                topic: m.topic,
                log_time: m.log_time,
                data: m.data,
            }) {
                Ok(()) => Ok(ControlFlow::Continue(())),
                Err(e) => {
                    failed = Some(e);
                    Ok(ControlFlow::Break(()))
                }
            }
        })?;
        if let Some(e) = failed {
            return Err(e);
        }
        Ok(report.damage)
    }
}

/// True if `path` looks like a bag: an `.mcap` or `.bag` file, or a folder holding
/// `metadata.yaml` or `.mcap` files (a rosbag2 bag).
pub fn is_bag(path: &Path) -> bool {
    let ext = |p: &Path, e: &str| p.extension().is_some_and(|x| x == e);
    if path.is_file() {
        return ext(path, "mcap") || ext(path, "bag");
    }
    path.is_dir()
        && (path.join("metadata.yaml").exists()
            || std::fs::read_dir(path).is_ok_and(|rd| {
                rd.filter_map(|e| e.ok())
                    .any(|e| e.path().is_file() && ext(&e.path(), "mcap"))
            }))
}

/// Opens the run at `path`.
pub fn open_run(path: &Path) -> Result<Box<dyn RecordedRun>> {
    Ok(Box::new(BagRun(Bag::open(path)?)))
}

/// A run found in a runs folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunEntry {
    /// The run's name: its file or folder name without `.mcap`/`.bag`.
    pub name: String,
    /// The bag.
    pub path: PathBuf,
    /// The sub-folder it is in, if any (a condition or a set of runs, e.g. `mud`).
    pub group: Option<String>,
}

fn run_name(p: &Path) -> String {
    let n = p
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    n.strip_suffix(".mcap")
        .or_else(|| n.strip_suffix(".bag"))
        .map(str::to_string)
        .unwrap_or(n)
}

fn sorted_entries(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(StudyError::io(dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    v.sort();
    Ok(v)
}

/// The runs under `dir`: every bag in it, and every bag one level down in a sub-folder that is
/// not itself a bag (the sub-folder's name becomes the run's group). `dir` may also be a single
/// bag.
pub fn find_runs(dir: &Path) -> Result<Vec<RunEntry>> {
    if !dir.exists() {
        return Err(StudyError::input(dir, "does not exist"));
    }
    if is_bag(dir) {
        return Ok(vec![RunEntry {
            name: run_name(dir),
            path: dir.to_path_buf(),
            group: None,
        }]);
    }
    let mut runs = Vec::new();
    for p in sorted_entries(dir)? {
        if is_bag(&p) {
            runs.push(RunEntry {
                name: run_name(&p),
                path: p,
                group: None,
            });
        } else if p.is_dir() {
            let group = run_name(&p);
            for q in sorted_entries(&p)? {
                if is_bag(&q) {
                    runs.push(RunEntry {
                        name: format!("{group}/{}", run_name(&q)),
                        path: q,
                        group: Some(group.clone()),
                    });
                }
            }
        }
    }
    if runs.is_empty() {
        return Err(StudyError::input(
            dir,
            "holds no recorded run (a .mcap or ROS 1 .bag file or a rosbag2 folder, directly or one folder down)",
        ));
    }
    Ok(runs)
}
