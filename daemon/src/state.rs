//! What survives a restart of `perturbd`, in two small files next to the report
//! (`<report>.state.json` and `<report>.counters` for a report `<report>.json`):
//!
//! - the **runtime state**: the perturbation each stream runs after `perturb ctl set/off`, written
//!   atomically (a temporary file renamed over the old one) on every change. On start it is
//!   restored and logged, unless the configuration file changed that stream's perturbation since
//!   (the file then wins, and the log says so) or `--fresh` is given.
//! - the **counters**: every stream's counters, the publisher it last heard from and that
//!   publisher's last sequence number, in a memory-mapped file the workers update in place (one
//!   atomic add per event, no system call; the kernel keeps the pages when the process is killed).
//!   A restarted daemon counts the sequence numbers it missed while it was down as
//!   `dropped_upstream`. After a crash or `kill -9` (no report was written) the previous counters
//!   carry on, and the frames the dead daemon had taken in but not yet published are counted as
//!   `dropped_restart`, so the counts still add up to every frame published; after a clean stop
//!   (the report has the final counts) they start again from zero.

use crate::config::StreamConfig;
use memmap2::MmapRaw;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// Where the two state files of a report live.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StatePaths {
    /// The runtime state (JSON).
    pub runtime: PathBuf,
    /// The counters (binary, memory-mapped).
    pub counters: PathBuf,
}

impl StatePaths {
    /// The state files that go with the report `report`: `X.json` -> `X.state.json`,
    /// `X.counters`.
    pub fn for_report(report: &Path) -> Self {
        let stem = report
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "perturbd".into());
        let dir = report.parent().unwrap_or(Path::new(""));
        StatePaths {
            runtime: dir.join(format!("{stem}.state.json")),
            counters: dir.join(format!("{stem}.counters")),
        }
    }
}

/// A perturbation as the state file stores it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Saved {
    /// Catalogue ID.
    pub id: String,
    /// Severity.
    pub severity: u8,
    /// Seed.
    pub seed: u64,
}

/// One stream in the runtime state.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamState {
    /// What runs now (`None`: off).
    pub active: Option<Saved>,
    /// What the configuration file said when this was written: if the file says something else
    /// now, it was edited since, and the file wins.
    pub configured: Option<Saved>,
}

/// The runtime state file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RuntimeState {
    /// Format version (1).
    pub version: u32,
    /// Per stream name.
    pub streams: BTreeMap<String, StreamState>,
    /// The kill switch, when it was engaged: a restarted daemon keeps it engaged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub killed: Option<crate::safety::KillRecord>,
    /// The running campaign: a restarted daemon carries on with it, on the same clock.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaign: Option<crate::campaign::CampaignState>,
}

/// What the configuration says a stream runs at start.
pub fn configured(s: &StreamConfig) -> Option<Saved> {
    s.perturbation.as_ref().map(|p| Saved {
        id: p.id.clone(),
        severity: p.severity,
        seed: p.seed,
    })
}

impl RuntimeState {
    /// Reads the file; `Ok(None)` when there is none.
    pub fn load(path: &Path) -> Result<Option<Self>, String> {
        match std::fs::read(path) {
            Ok(b) => serde_json::from_slice(&b)
                .map(Some)
                .map_err(|e| format!("{}: unreadable runtime state: {e}", path.display())),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(format!("{}: {e}", path.display())),
        }
    }

    /// Writes the file atomically: a temporary file next to it, synced, renamed over it.
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        use std::io::Write;
        let tmp = path.with_extension("json.tmp");
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&serde_json::to_vec_pretty(self).map_err(std::io::Error::other)?)?;
        f.write_all(b"\n")?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    }

    /// What to restore for `stream`: `Some(active)` when the state applies (the configuration
    /// still says what it said when the state was written), else `None`.
    pub fn restore_for(&self, stream: &StreamConfig) -> Option<Option<Saved>> {
        let s = self.streams.get(&stream.name)?;
        (s.configured == configured(stream)).then(|| s.active.clone())
    }
}

/// A stream's counters, as atomics in memory or in the memory-mapped counters file
/// (`#[repr(C)]`: the file's layout).
#[derive(Debug, Default)]
#[repr(C)]
pub struct Counters {
    /// Frames received.
    pub frames_in: AtomicU64,
    /// Frames published.
    pub frames_out: AtomicU64,
    /// Dropped from the worker's queue.
    pub dropped_queue: AtomicU64,
    /// Missing sequence numbers on the input.
    pub dropped_upstream: AtomicU64,
    /// Could not be published.
    pub dropped_output: AtomicU64,
    /// Taken in by a daemon that died before publishing them.
    pub dropped_restart: AtomicU64,
    /// Refused as invalid.
    pub invalid: AtomicU64,
    /// Perturbation failed (forwarded unperturbed).
    pub perturb_failed: AtomicU64,
    /// Over the latency budget.
    pub over_budget: AtomicU64,
    /// Last sequence number received + 1 (0: none yet).
    pub last_seq_plus_one: AtomicU64,
    /// The publisher of that frame (high and low halves of its iceoryx2 id; `origin_set` 1 when
    /// valid).
    pub origin_hi: AtomicU64,
    /// See `origin_hi`.
    pub origin_lo: AtomicU64,
    /// 1 when `origin_hi`/`origin_lo` hold a publisher.
    pub origin_set: AtomicU64,
    /// Frames the input's publisher sent that this daemon never received while it ran: its
    /// input queue overflowed because it was stalled (SIGSTOP, a frozen machine) or overloaded
    /// (gaps in [`perturb_wire::FrameHeader::publish_index`]).
    pub dropped_input: AtomicU64,
    /// Frames the input's publisher sent while no daemon ran (killed, crashed, restarting),
    /// counted by the next daemon from the gap in `publish_index`.
    pub dropped_down: AtomicU64,
    /// The last `publish_index` received + 1 (0: none yet), of the publisher in `origin_*`.
    pub last_index_plus_one: AtomicU64,
}

/// How many counters a stream has (the `u64`s of [`Counters`], in order).
const N_COUNTERS: usize = 16;

impl Counters {
    /// Adds `n` to a counter.
    pub fn add(c: &AtomicU64, n: u64) {
        c.fetch_add(n, Ordering::Relaxed);
    }

    /// Reads a counter.
    pub fn get(c: &AtomicU64) -> u64 {
        c.load(Ordering::Relaxed)
    }

    fn all(&self) -> [&AtomicU64; N_COUNTERS] {
        [
            &self.frames_in,
            &self.frames_out,
            &self.dropped_queue,
            &self.dropped_upstream,
            &self.dropped_output,
            &self.dropped_restart,
            &self.invalid,
            &self.perturb_failed,
            &self.over_budget,
            &self.last_seq_plus_one,
            &self.origin_hi,
            &self.origin_lo,
            &self.origin_set,
            &self.dropped_input,
            &self.dropped_down,
            &self.last_index_plus_one,
        ]
    }

    fn set_values(&self, v: &[u64; N_COUNTERS]) {
        for (c, v) in self.all().iter().zip(v) {
            c.store(*v, Ordering::Relaxed);
        }
    }

    /// The publisher last heard from and its last sequence number.
    pub fn last_origin(&self) -> Option<(u128, u64)> {
        if Self::get(&self.origin_set) != 1 {
            return None;
        }
        let seq = Self::get(&self.last_seq_plus_one).checked_sub(1)?;
        let origin =
            ((Self::get(&self.origin_hi) as u128) << 64) | Self::get(&self.origin_lo) as u128;
        Some((origin, seq))
    }

    /// Records the publisher of the frame being received.
    pub fn set_origin(&self, origin: u128) {
        if self.last_origin().map(|(o, _)| o) == Some(origin) {
            return;
        }
        self.origin_set.store(0, Ordering::Relaxed);
        self.origin_hi
            .store((origin >> 64) as u64, Ordering::Relaxed);
        self.origin_lo.store(origin as u64, Ordering::Relaxed);
        self.origin_set.store(1, Ordering::Release);
    }

    /// Frames taken in but neither published nor counted yet (in the queue or in work).
    pub fn in_flight(&self) -> u64 {
        let g = Self::get;
        g(&self.frames_in).saturating_sub(
            g(&self.frames_out)
                + g(&self.invalid)
                + g(&self.dropped_queue)
                + g(&self.dropped_output)
                + g(&self.dropped_restart),
        )
    }

    /// The publisher last heard from and the last `publish_index` received from it.
    pub fn last_index(&self) -> Option<(u128, u64)> {
        let (origin, _) = self.last_origin()?;
        let index = Self::get(&self.last_index_plus_one).checked_sub(1)?;
        Some((origin, index))
    }
}

/// Where a stream's counters live.
pub enum CounterCell {
    /// In this process only (tests, or no counters file).
    Owned(Box<Counters>),
    /// In the memory-mapped counters file.
    Mapped {
        /// The mapping (shared by every stream).
        map: Arc<MmapRaw>,
        /// Byte offset of this stream's slot.
        offset: usize,
    },
}

impl Default for CounterCell {
    fn default() -> Self {
        CounterCell::Owned(Box::default())
    }
}

impl std::fmt::Debug for CounterCell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (**self).fmt(f)
    }
}

impl std::ops::Deref for CounterCell {
    type Target = Counters;
    // The counters live in a shared memory-mapped file.
    #[allow(unsafe_code)]
    fn deref(&self) -> &Counters {
        match self {
            CounterCell::Owned(b) => b,
            CounterCell::Mapped { map, offset } => {
                // SAFETY: `CountersFile::open` sized the mapping to hold every slot and placed
                // each slot at a multiple of SLOT (a multiple of 8) from the page-aligned start,
                // so the pointer is in bounds and aligned for `Counters` (16 `AtomicU64`s,
                // `repr(C)`). The mapping is `MAP_SHARED` read-write and lives as long as `map`;
                // it is only ever accessed through these atomics (shared references are fine
                // for them), and the file is this daemon's own.
                unsafe { &*(map.as_ptr().add(*offset) as *const Counters) }
            }
        }
    }
}

const MAGIC: &[u8; 8] = b"PTRBCNT1";
const HEADER: usize = 64;
const NAME: usize = 128;
const SLOT: usize = 256;
const _: () = assert!(NAME + std::mem::size_of::<Counters>() <= SLOT);

/// What [`CountersFile::open`] found of the previous run.
#[derive(Debug, Default)]
pub struct Carried {
    /// Streams whose counters carried on after an unclean end, with the frames the dead daemon
    /// had in flight.
    pub after_crash: Vec<(String, u64)>,
    /// True if the previous run stopped cleanly.
    pub clean: bool,
    /// True if there was a previous run.
    pub found: bool,
}

/// The memory-mapped counters file.
pub struct CountersFile {
    map: Arc<MmapRaw>,
    slots: BTreeMap<String, usize>,
}

impl std::fmt::Debug for CountersFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CountersFile")
            .field("streams", &self.slots.keys().collect::<Vec<_>>())
            .finish()
    }
}

/// The previous file's slots: name -> counter values, and whether it stopped cleanly.
fn read_previous(path: &Path) -> Option<(BTreeMap<String, [u64; N_COUNTERS]>, bool)> {
    let b = std::fs::read(path).ok()?;
    if b.len() < HEADER || &b[..8] != MAGIC {
        return None;
    }
    let u = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"));
    let n = u(8) as usize;
    let clean = u(16) == 1;
    if b.len() < HEADER + n.checked_mul(SLOT)? {
        return None;
    }
    let mut out = BTreeMap::new();
    for i in 0..n {
        let at = HEADER + i * SLOT;
        let name = &b[at..at + NAME];
        let end = name.iter().position(|&c| c == 0).unwrap_or(NAME);
        let Ok(name) = std::str::from_utf8(&name[..end]) else {
            continue;
        };
        let mut v = [0u64; N_COUNTERS];
        for (k, x) in v.iter_mut().enumerate() {
            *x = u(at + NAME + 8 * k);
        }
        out.insert(name.to_string(), v);
    }
    Some((out, clean))
}

impl CountersFile {
    /// Creates the counters file for `streams` at `path`, taking over what the previous run left
    /// there (see the module documentation). With `fresh`, the previous file is ignored.
    /// Streams whose name is longer than 128 bytes keep their counters in memory only.
    // The counters live in a shared memory-mapped file.
    #[allow(unsafe_code)]
    pub fn open(
        path: &Path,
        streams: &[StreamConfig],
        fresh: bool,
    ) -> std::io::Result<(Self, Carried)> {
        let previous = if fresh { None } else { read_previous(path) };
        let mut carried = Carried::default();
        let names: Vec<&str> = streams
            .iter()
            .map(|s| s.name.as_str())
            .filter(|n| n.len() <= NAME)
            .collect();
        let len = HEADER + names.len().max(1) * SLOT;
        let tmp = path.with_extension("counters.tmp");
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&tmp)?;
        file.set_len(len as u64)?;
        let map = Arc::new(MmapRaw::map_raw(&file)?);
        // SAFETY: the mapping is `len` bytes long and this process created the file just now;
        // nothing else writes it while the header and names are filled in.
        let bytes = unsafe { std::slice::from_raw_parts_mut(map.as_mut_ptr(), len) };
        bytes[..8].copy_from_slice(MAGIC);
        bytes[8..16].copy_from_slice(&(names.len() as u64).to_le_bytes());
        let mut slots = BTreeMap::new();
        for (i, name) in names.iter().enumerate() {
            let at = HEADER + i * SLOT;
            bytes[at..at + name.len()].copy_from_slice(name.as_bytes());
            slots.insert(name.to_string(), at + NAME);
        }
        let file = CountersFile { map, slots };
        if let Some((old, clean)) = previous {
            carried.found = true;
            carried.clean = clean;
            for name in &names {
                let Some(v) = old.get(*name) else { continue };
                let c = file.cell(name).expect("a slot per stream");
                c.set_values(v);
                if clean {
                    // The report has the counts; keep only where the stream was.
                    let (seq, hi, lo, set, index) = (
                        Counters::get(&c.last_seq_plus_one),
                        Counters::get(&c.origin_hi),
                        Counters::get(&c.origin_lo),
                        Counters::get(&c.origin_set),
                        Counters::get(&c.last_index_plus_one),
                    );
                    c.set_values(&[0; N_COUNTERS]);
                    c.last_seq_plus_one.store(seq, Ordering::Relaxed);
                    c.last_index_plus_one.store(index, Ordering::Relaxed);
                    c.origin_hi.store(hi, Ordering::Relaxed);
                    c.origin_lo.store(lo, Ordering::Relaxed);
                    c.origin_set.store(set, Ordering::Relaxed);
                } else {
                    let lost = c.in_flight();
                    Counters::add(&c.dropped_restart, lost);
                    carried.after_crash.push((name.to_string(), lost));
                }
            }
        }
        file.map.flush()?;
        std::fs::rename(&tmp, path)?;
        Ok((file, carried))
    }

    /// The counters of stream `name` in the file (`None` for a stream without a slot).
    pub fn cell(&self, name: &str) -> Option<CounterCell> {
        self.slots.get(name).map(|&offset| CounterCell::Mapped {
            map: self.map.clone(),
            offset,
        })
    }

    /// Marks the run as stopped cleanly (the report holds its final counts).
    // The counters live in a shared memory-mapped file.
    #[allow(unsafe_code)]
    pub fn mark_clean(&self) {
        // SAFETY: bytes 16..24 of the header belong to no stream's counters and are written by
        // this thread only, after the workers stopped.
        unsafe {
            let p = self.map.as_mut_ptr().add(16) as *mut AtomicU64;
            (*p).store(1, Ordering::Release);
        }
        let _ = self.map.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use perturb_core::registry::Modality;

    fn stream(name: &str) -> StreamConfig {
        crate::config::Config::parse(&format!(
            "[[streams]]\nname = \"{name}\"\nmodality = \"camera\"\n"
        ))
        .unwrap()
        .streams
        .remove(0)
    }

    #[test]
    fn paths_sit_next_to_the_report() {
        let p = StatePaths::for_report(Path::new("/x/run/perturbd-report.json"));
        assert_eq!(p.runtime, Path::new("/x/run/perturbd-report.state.json"));
        assert_eq!(p.counters, Path::new("/x/run/perturbd-report.counters"));
    }

    #[test]
    fn counters_survive_an_unclean_end_and_restart_after_a_clean_one() {
        let dir = std::env::temp_dir().join(format!("perturbd-state-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("r.counters");
        let streams = vec![stream("cam"), stream("other")];
        assert_eq!(streams[0].modality, Modality::Camera);
        {
            let (f, carried) = CountersFile::open(&path, &streams, false).unwrap();
            assert!(!carried.found);
            let c = f.cell("cam").unwrap();
            Counters::add(&c.frames_in, 10);
            Counters::add(&c.frames_out, 7);
            Counters::add(&c.dropped_queue, 1);
            c.last_seq_plus_one.store(10, Ordering::Relaxed);
            c.set_origin(42);
            // Dropped without `mark_clean`: as after kill -9.
        }
        let (f, carried) = CountersFile::open(&path, &streams, false).unwrap();
        assert!(carried.found && !carried.clean);
        assert_eq!(
            carried.after_crash,
            vec![("cam".into(), 2), ("other".into(), 0)]
        );
        let c = f.cell("cam").unwrap();
        assert_eq!(Counters::get(&c.frames_out), 7);
        assert_eq!(Counters::get(&c.dropped_restart), 2);
        assert_eq!(c.last_origin(), Some((42, 9)));
        assert_eq!(c.in_flight(), 0);
        f.mark_clean();
        drop(f);
        let (f, carried) = CountersFile::open(&path, &streams, false).unwrap();
        assert!(carried.found && carried.clean);
        let c = f.cell("cam").unwrap();
        assert_eq!(Counters::get(&c.frames_out), 0);
        assert_eq!(c.last_origin(), Some((42, 9)));
        drop(f);
        let (f, carried) = CountersFile::open(&path, &streams, true).unwrap();
        assert!(!carried.found);
        assert_eq!(f.cell("cam").unwrap().last_origin(), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn runtime_state_yields_to_an_edited_configuration() {
        let s = stream("cam");
        let mut st = RuntimeState {
            version: 1,
            ..Default::default()
        };
        let set = Saved {
            id: "C-F5".into(),
            severity: 1,
            seed: 3,
        };
        st.streams.insert(
            "cam".into(),
            StreamState {
                active: Some(set.clone()),
                configured: None,
            },
        );
        assert_eq!(st.restore_for(&s), Some(Some(set)));
        st.streams.get_mut("cam").unwrap().configured = Some(Saved {
            id: "C-A1".into(),
            severity: 2,
            seed: 0,
        });
        assert_eq!(st.restore_for(&s), None);
        assert_eq!(st.restore_for(&stream("nosuch")), None);
    }
}
