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

/// The recording suffixes of bag files: `.mcap`, `.bag`, and `.bag.active` (a ROS 1 bag whose
/// `rosbag record` was killed before it renamed the file: unindexed, read up to the damage).
const BAG_SUFFIXES: [&str; 3] = [".bag.active", ".mcap", ".bag"];

/// True if `path` is a bag file by its name (`.mcap`, `.bag`, `.bag.active`).
pub fn is_bag_file(path: &Path) -> bool {
    path.is_file()
        && path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .is_some_and(|n| BAG_SUFFIXES.iter().any(|s| n.ends_with(s)))
}

/// True if `dir` is a rosbag2 bag folder: it holds `metadata.yaml`, or (a recorder killed before
/// writing it) only the files `ros2 bag record` writes, `<folder name>_<N>.mcap`. A folder of
/// other bag files is a folder of runs, never one bag.
pub fn is_rosbag2_dir(dir: &Path) -> bool {
    if !dir.is_dir() {
        return false;
    }
    if dir.join("metadata.yaml").is_file() {
        return true;
    }
    let Some(stem) = dir.file_name().map(|n| n.to_string_lossy().to_string()) else {
        return false;
    };
    let Ok(rd) = std::fs::read_dir(dir) else {
        return false;
    };
    let mut split_files = 0;
    for e in rd.filter_map(|e| e.ok()) {
        let p = e.path();
        let name = e.file_name().to_string_lossy().to_string();
        let split = name
            .strip_prefix(&format!("{stem}_"))
            .and_then(|r| r.strip_suffix(".mcap"))
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        if split && p.is_file() {
            split_files += 1;
        } else if p.is_dir() || is_bag_file(&p) {
            return false;
        }
    }
    split_files > 0
}

/// True if `path` is a bag: a bag file ([`is_bag_file`]) or a rosbag2 folder ([`is_rosbag2_dir`]).
pub fn is_bag(path: &Path) -> bool {
    is_bag_file(path) || is_rosbag2_dir(path)
}

/// Opens the run at `path`.
pub fn open_run(path: &Path) -> Result<Box<dyn RecordedRun>> {
    Ok(Box::new(BagRun(Bag::open(path)?)))
}

/// A run found in a runs folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunEntry {
    /// The run's name: its file or folder name without `.mcap`/`.bag`/`.bag.active`
    /// (`group/name` for a run in a sub-folder).
    pub name: String,
    /// The bag.
    pub path: PathBuf,
    /// The sub-folder it is in, if any (a condition or a set of runs, e.g. `mud`).
    pub group: Option<String>,
}

/// Something in a runs folder that is not read as a run, and why.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Skipped {
    /// The file or folder.
    pub path: PathBuf,
    /// Why it is not a run.
    pub reason: String,
}

/// The runs of a runs folder and what was left out.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RunsFound {
    /// The runs, in name order (top-level runs and groups interleaved by name).
    pub runs: Vec<RunEntry>,
    /// Files and folders that are not runs (named, with the reason).
    pub skipped: Vec<Skipped>,
}

fn run_name(p: &Path) -> String {
    let n = p
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    BAG_SUFFIXES
        .iter()
        .find_map(|s| n.strip_suffix(s))
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

/// Why a file that is not a bag is left out (None: silently, e.g. a route or notes file).
fn not_a_run(p: &Path) -> Option<String> {
    let name = p.file_name()?.to_string_lossy().to_string();
    if name.starts_with('.') {
        return None;
    }
    if name.ends_with(".db3") {
        return Some(
            "a rosbag2 sqlite3 file: not read (re-record with `--storage mcap` or convert with `ros2 bag convert`)".into(),
        );
    }
    if name.ends_with(".mcap.active") || name.contains(".bag.orig") {
        return Some("not a finished bag file (an interrupted recording or a backup)".into());
    }
    Some("not a bag file (.mcap, .bag, .bag.active) or rosbag2 folder".into())
}

/// The runs under `dir`: each bag file (`.mcap`, `.bag`, `.bag.active`) and each rosbag2 folder
/// in it is one run; every other sub-folder is a group whose bags (files and rosbag2 folders) are
/// runs named `group/name`. `dir` may also be a single bag. Nothing is merged: two `.mcap` files
/// side by side are two runs. Other files and deeper folders are listed in
/// [`RunsFound::skipped`] with the reason.
pub fn find_runs(dir: &Path) -> Result<RunsFound> {
    if !dir.exists() {
        return Err(StudyError::input(dir, "does not exist"));
    }
    let mut found = RunsFound::default();
    if is_bag(dir) {
        found.runs.push(RunEntry {
            name: run_name(dir),
            path: dir.to_path_buf(),
            group: None,
        });
        return Ok(found);
    }
    if dir.is_file() {
        return Err(StudyError::input(
            dir,
            "is neither a folder of runs nor a bag file (.mcap, .bag, .bag.active)",
        ));
    }
    let mut skip = |path: &Path, reason: String| {
        found.skipped.push(Skipped {
            path: path.to_path_buf(),
            reason,
        })
    };
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
            let before = runs.len();
            for q in sorted_entries(&p)? {
                if is_bag(&q) {
                    runs.push(RunEntry {
                        name: format!("{group}/{}", run_name(&q)),
                        path: q,
                        group: Some(group.clone()),
                    });
                } else if q.is_dir() {
                    skip(
                        &q,
                        "a folder two levels down that is not a rosbag2 bag (runs are read from RUNS_DIR and one folder down)".into(),
                    );
                } else if let Some(why) = not_a_run(&q) {
                    skip(&q, why);
                }
            }
            if runs.len() == before
                && !p
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with('.'))
            {
                skip(&p, "a folder holding no run".into());
            }
        } else if let Some(why) = not_a_run(&p) {
            skip(&p, why);
        }
    }
    if runs.is_empty() {
        return Err(StudyError::input(
            dir,
            "holds no recorded run (a .mcap or ROS 1 .bag file or a rosbag2 folder, directly or one folder down)",
        ));
    }
    found.runs = runs;
    Ok(found)
}
