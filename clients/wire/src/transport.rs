//! The iceoryx2 side: which shared-memory namespace a process joins, its node, the stale-resource
//! sweep, the per-stream QoS, service naming and the shared clock.

use crate::error::{WireError, WireResult};
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The iceoryx2 service flavour every process of the project uses: inter-process, with ports
/// that may move between threads (the daemon hands received samples from its receiver thread to
/// its processing thread). It shares the shared-memory layout of `ipc::Service`, so plain iceoryx2
/// programs interoperate.
pub type Ipc = iceoryx2::service::ipc_threadsafe::Service;

/// Environment variable overriding the iceoryx2 file prefix.
pub const ENV_PREFIX: &str = "PERTURB_IOX2_PREFIX";
/// Environment variable overriding the iceoryx2 root path.
pub const ENV_ROOT: &str = "PERTURB_IOX2_ROOT";
/// Environment variable naming an iceoryx2 config file.
pub const ENV_CONFIG: &str = "PERTURB_IOX2_CONFIG";

/// Which iceoryx2 namespace to join. Processes only see each other when they agree on all three.
///
/// - `prefix`: prefix of every file iceoryx2 creates (shared memory in `/dev/shm`, and the files
///   under the root path); default `iox2_`.
/// - `root`: directory of iceoryx2's node and service records; default `/tmp/iceoryx2/`.
/// - `iceoryx2_config`: an iceoryx2 TOML config file to start from (default: iceoryx2's built-in
///   defaults; iceoryx2's own config-file search is not used, so a stray `config/iceoryx2.toml` in
///   the working directory changes nothing).
///
/// Tests give every test its own prefix and root so they neither see each other nor other users
/// of the machine.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransportOptions {
    /// iceoryx2 file prefix (letters, digits, `_`, `-`, `.`).
    #[serde(default)]
    pub prefix: Option<String>,
    /// iceoryx2 root directory.
    #[serde(default)]
    pub root: Option<PathBuf>,
    /// iceoryx2 config file.
    #[serde(default)]
    pub iceoryx2_config: Option<PathBuf>,
}

impl TransportOptions {
    /// The options given by the `PERTURB_IOX2_*` environment variables.
    pub fn from_env() -> Self {
        TransportOptions::default().with_env_overrides()
    }

    /// These options with each `PERTURB_IOX2_*` variable that is set taking precedence.
    pub fn with_env_overrides(mut self) -> Self {
        let get = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty());
        if let Some(p) = get(ENV_PREFIX) {
            self.prefix = Some(p.to_string_lossy().into_owned());
        }
        if let Some(r) = get(ENV_ROOT) {
            self.root = Some(PathBuf::from(r));
        }
        if let Some(c) = get(ENV_CONFIG) {
            self.iceoryx2_config = Some(PathBuf::from(c));
        }
        self
    }

    /// A namespace private to `tag` and this process (for tests): prefix `pt_<tag>_<pid>_` and a
    /// root under the system temp directory. The tag is cut to 12 characters: iceoryx2's event
    /// listeners are Unix sockets under the root, named with the prefix, and a socket path may
    /// not exceed 108 bytes (a long tag and a 7-digit process id made the daemon's control
    /// listener fail to open).
    pub fn isolated(tag: &str) -> Self {
        let clean: String = tag
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .take(12)
            .collect();
        let pid = std::process::id();
        TransportOptions {
            prefix: Some(format!("pt_{clean}_{pid}_")),
            root: Some(std::env::temp_dir().join(format!("pio-{clean}-{pid}"))),
            iceoryx2_config: None,
        }
    }

    /// Deletes every file of this namespace: the shared-memory objects in `/dev/shm` whose name
    /// starts with the prefix, and the root directory. Only for a namespace private to its user
    /// (a test's [`TransportOptions::isolated`]); refuses the default prefix and root. Call it when
    /// no process uses the namespace any more.
    pub fn remove_namespace_files(&self) -> std::io::Result<usize> {
        let (Some(prefix), Some(root)) = (&self.prefix, &self.root) else {
            return Err(std::io::Error::other(
                "refusing to clean a namespace without its own prefix and root",
            ));
        };
        if prefix == "iox2_" || prefix.is_empty() {
            return Err(std::io::Error::other(
                "refusing to clean the default prefix",
            ));
        }
        let mut n = 0;
        if let Ok(dir) = std::fs::read_dir("/dev/shm") {
            for e in dir.flatten() {
                if e.file_name().to_string_lossy().starts_with(prefix.as_str()) {
                    std::fs::remove_file(e.path())?;
                    n += 1;
                }
            }
        }
        if root.exists() {
            std::fs::remove_dir_all(root)?;
        }
        Ok(n)
    }

    /// Sets the environment variables so child processes join the same namespace.
    pub fn to_env(&self) -> Vec<(&'static str, String)> {
        let mut v = Vec::new();
        if let Some(p) = &self.prefix {
            v.push((ENV_PREFIX, p.clone()));
        }
        if let Some(r) = &self.root {
            v.push((ENV_ROOT, r.display().to_string()));
        }
        if let Some(c) = &self.iceoryx2_config {
            v.push((ENV_CONFIG, c.display().to_string()));
        }
        v
    }

    /// The iceoryx2 [`Config`] these options describe.
    pub fn iceoryx2(&self) -> WireResult<Config> {
        let mut cfg = match &self.iceoryx2_config {
            Some(path) => {
                let fp = FilePath::new(path.to_string_lossy().as_bytes()).map_err(|e| {
                    WireError::Config(format!("iceoryx2 config path {}: {e:?}", path.display()))
                })?;
                Config::from_file(&fp).map_err(|e| {
                    WireError::Config(format!(
                        "cannot load iceoryx2 config {}: {e:?}",
                        path.display()
                    ))
                })?
            }
            None => Config::default(),
        };
        if let Some(prefix) = &self.prefix {
            cfg.global.prefix = FileName::new(prefix.as_bytes()).map_err(|e| {
                WireError::Config(format!(
                    "iceoryx2 prefix `{prefix}` is not a valid file name ({e:?})"
                ))
            })?;
        }
        if let Some(root) = &self.root {
            let mut s = root.to_string_lossy().into_owned();
            if !s.ends_with('/') {
                s.push('/');
            }
            std::fs::create_dir_all(&s)
                .map_err(|e| WireError::Config(format!("cannot create iceoryx2 root {s}: {e}")))?;
            let p = Path::new(s.as_bytes()).map_err(|e| {
                WireError::Config(format!("iceoryx2 root `{s}` is not a valid path ({e:?})"))
            })?;
            cfg.global.set_root_path(&p);
        }
        Ok(cfg)
    }

    /// One line for logs: where this namespace lives.
    pub fn describe(&self) -> String {
        format!(
            "iceoryx2 prefix `{}`, root {}",
            self.prefix.as_deref().unwrap_or("iox2_"),
            self.root
                .as_ref()
                .map_or("/tmp/iceoryx2/".to_string(), |r| r.display().to_string())
        )
    }
}

/// Quality of service of one stream's services. Every process on a stream must use the same
/// values (iceoryx2 checks them when a process opens a service another one created, and the
/// error names the value that differs).
///
/// Memory: each publisher preallocates `max_subscribers * (subscriber_buffer +
/// subscriber_borrowed) + publisher_loans` samples of the current frame size (iceoryx2's worst
/// case, so a loan never fails). The defaults give 2 * (2 + 4) + 2 = 14 frames per publisher:
/// 17 MB for an 800x503 rgb8 camera, 97 MB for 1920x1208.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StreamQos {
    /// Publishers per service (the daemon restarts with a new publisher while iceoryx2 may
    /// still list the dead one: keep at least 2).
    pub max_publishers: usize,
    /// Subscribers per service: on raw the daemon, a guarded egress (its fallback), a recorder
    /// and one more (a monitor, the live view); on perturbed the egress, a recorder and two more.
    pub max_subscribers: usize,
    /// Samples a subscriber's queue holds; when full, the oldest is overwritten (safe overflow)
    /// and the receiver counts the gap in sequence numbers.
    pub subscriber_buffer: usize,
    /// Samples a subscriber may hold at once (the daemon holds its queue plus the frame in work).
    pub subscriber_borrowed: usize,
    /// Samples a publisher may have on loan at once.
    pub publisher_loans: usize,
}

impl Default for StreamQos {
    fn default() -> Self {
        StreamQos {
            max_publishers: 2,
            max_subscribers: 4,
            subscriber_buffer: 2,
            subscriber_borrowed: 4,
            publisher_loans: 2,
        }
    }
}

impl StreamQos {
    /// Checks the values are usable.
    pub fn validate(&self) -> Result<(), String> {
        let check = |name: &str, v: usize, lo: usize, hi: usize| {
            if v < lo || v > hi {
                Err(format!("{name} = {v} is out of range {lo}..={hi}"))
            } else {
                Ok(())
            }
        };
        check("max_publishers", self.max_publishers, 1, 16)?;
        check("max_subscribers", self.max_subscribers, 1, 16)?;
        check("subscriber_buffer", self.subscriber_buffer, 1, 256)?;
        check("subscriber_borrowed", self.subscriber_borrowed, 1, 256)?;
        check("publisher_loans", self.publisher_loans, 1, 16)
    }

    /// Samples each publisher preallocates.
    pub fn preallocated_samples(&self) -> usize {
        self.max_subscribers * (self.subscriber_buffer + self.subscriber_borrowed)
            + self.publisher_loans
    }
}

/// Default service names of a stream: `<stream>/raw` (ingress to daemon) and
/// `<stream>/perturbed` (daemon to egress).
pub mod names {
    /// `<stream>/raw`.
    pub fn raw(stream: &str) -> String {
        format!("{stream}/raw")
    }
    /// `<stream>/perturbed`.
    pub fn perturbed(stream: &str) -> String {
        format!("{stream}/perturbed")
    }
    /// The daemon's control service.
    pub const CONTROL: &str = "perturb/control";

    /// Checks a stream name, the one rule the daemon and the bridge share: 1 to 200 bytes of
    /// letters, digits, `_`, `-` and `.`, in `/`-separated segments (none empty, none `.` or
    /// `..`: a stream name is not a path). The error says what is wrong with it.
    pub fn check_stream(name: &str) -> Result<(), String> {
        if name.is_empty() || name.len() > 200 {
            return Err(format!("stream name `{name}` must be 1-200 bytes long"));
        }
        if let Some(c) = name
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/')))
        {
            return Err(format!(
                "stream name `{name}` contains {c:?}: use letters, digits, `_`, `-`, `.` and `/` between segments"
            ));
        }
        if name.split('/').any(|p| p == "." || p == "..") {
            return Err(format!(
                "stream name `{name}` contains `.` or `..` segments: a stream name is not a path"
            ));
        }
        if name.split('/').any(str::is_empty) {
            return Err(format!(
                "stream name `{name}` must not start or end with `/` nor contain `//`"
            ));
        }
        Ok(())
    }
}

/// CLOCK_MONOTONIC in nanoseconds: the clock every hop timestamp uses, comparable between all
/// processes of the machine.
// libc's clock_gettime.
#[allow(unsafe_code)]
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own; CLOCK_MONOTONIC always exists on Linux.
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// What the stale-resource sweep found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SweepReport {
    /// Nodes whose process is alive.
    pub alive: usize,
    /// Dead nodes whose resources were removed.
    pub removed: usize,
    /// Dead nodes that could not be removed (permissions, or another process is cleaning them).
    pub failed: usize,
}

/// A process's membership in an iceoryx2 namespace: one iceoryx2 node, from which it opens
/// publishers and subscribers.
pub struct Transport {
    node: Node<Ipc>,
    config: Config,
    options: TransportOptions,
}

impl std::fmt::Debug for Transport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Transport")
            .field("node", &self.node.name())
            .field("options", &self.options)
            .finish()
    }
}

/// iceoryx2 logs to stderr itself, its warnings with a `Debug` dump of the object concerned (a
/// node that could not remove a dead peer's records printed a 6 kB line on a daemon restart).
/// Every iceoryx2 failure reaches this crate as an error that is reported in words, so iceoryx2's
/// own log is limited to its errors, unless `IOX2_LOG_LEVEL` asks for more.
fn quiet_iceoryx2_log() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    });
}

impl Transport {
    /// Joins the namespace `options` describes with a node called `node_name`.
    pub fn open(node_name: &str, options: &TransportOptions) -> WireResult<Self> {
        quiet_iceoryx2_log();
        let config = options.iceoryx2()?;
        let name = NodeName::new(node_name)
            .map_err(|e| WireError::Config(format!("node name `{node_name}`: {e:?}")))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&config)
            // Signal handling stays with the application: the daemon reacts to SIGINT/SIGTERM
            // through its WaitSet, the helpers exit on them by default.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| WireError::iox(format!("creating node `{node_name}`"), e))?;
        Ok(Transport {
            node,
            config,
            options: options.clone(),
        })
    }

    /// The iceoryx2 node.
    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }

    /// The iceoryx2 config in use.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The namespace options.
    pub fn options(&self) -> &TransportOptions {
        &self.options
    }

    /// Removes the shared memory and records of every dead node in this namespace (processes
    /// that ended without cleaning up, e.g. after `kill -9`).
    pub fn sweep_dead_nodes(&self) -> WireResult<SweepReport> {
        sweep_dead_nodes(&self.config)
    }
}

/// [`Transport::sweep_dead_nodes`] for a config without a node of one's own.
pub fn sweep_dead_nodes(config: &Config) -> WireResult<SweepReport> {
    quiet_iceoryx2_log();
    let mut report = SweepReport::default();
    Node::<Ipc>::list(config, |state| {
        match state {
            NodeState::Alive(_) => report.alive += 1,
            NodeState::Dead(dead) => match dead.try_remove_stale_resources() {
                Ok(()) => report.removed += 1,
                Err(_) => report.failed += 1,
            },
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => {}
        }
        CallbackProgression::Continue
    })
    .map_err(|e| WireError::iox("listing iceoryx2 nodes", e))?;
    Ok(report)
}

/// Maps a service-open failure to a message that says what to do.
pub(crate) fn open_error(service: &str, e: impl std::fmt::Debug) -> WireError {
    let detail = format!("{e:?}");
    let hint = if detail.contains("IncompatibleTypes") || detail.contains("IncompatibleHeaderType")
    {
        " (the service exists with another frame header type: a peer built against another perturb-wire version)"
    } else if detail.contains("DoesNotSupport") || detail.contains("IncompatibleOverflow") {
        " (the service exists with smaller QoS values than this process asks for: give every process of the stream the same [streams.qos])"
    } else if detail.contains("IncompatibleMessagingPattern") {
        " (a service of another kind already uses this name)"
    } else {
        ""
    };
    WireError::Incompatible {
        service: service.to_string(),
        detail: format!("{detail}{hint}"),
    }
}

pub(crate) fn service_name(service: &str) -> WireResult<ServiceName> {
    ServiceName::new(service)
        .map_err(|e| WireError::Config(format!("service name `{service}` is invalid ({e:?})")))
}
