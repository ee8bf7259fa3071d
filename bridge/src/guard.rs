//! The safety envelope of an egress: the ADS never goes blind because of the middleware.
//!
//! A guarded egress reads both sides of its stream. It keeps each raw frame it receives (held in
//! shared memory, no copy) until the perturbed frame of the same sequence number arrives, which
//! it publishes, or until the frame's deadline passes: then, with `on_late = "raw"` (the
//! default), it publishes the raw frame in its place, header unchanged, and counts it
//! (`fallback_raw`, by reason). When `perturbd` is gone (its output has no publisher) raw frames
//! go out at once, without waiting for the deadline; while the bridge's kill switch holds, too.
//! A daemon that has delivered nothing for two deadlines is taken as stalled: raw frames go out
//! at once (reason `late`), in the sensor's cadence, until it delivers again. A perturbed frame
//! that arrives after its raw frame went out is discarded (counted `late_discarded`): the ADS gets
//! each frame once, in order.
//!
//! With `on_late = "drop"` (hardware-in-the-loop timing studies, where a fallback would mask the
//! daemon's latency) a late frame is not published and is counted lost (`daemon_late` or
//! `daemon_down`).
//!
//! The deadline is per stream: `deadline_ms`, else one frame period of `rate_hz`, else one frame
//! period of the rate measured on the raw side (the median of the last 15 intervals; 100 ms until
//! two frames were seen).

use crate::bus::{Bus, Held, Side};
use crate::frame::{StreamKind, monotonic_ns};
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// What an egress does with a frame whose perturbed version misses its deadline.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnLate {
    /// Publish the raw frame in its place (the vehicle's choice: never worse than no
    /// middleware).
    #[default]
    Raw,
    /// Publish nothing for it, count it lost (timing studies, where a fallback would hide the
    /// daemon's latency).
    Drop,
    /// No deadline: publish each perturbed frame when it comes, however late, and nothing while
    /// the daemon is down (the egress does not read the raw side; for comparisons and for
    /// replays where every perturbed frame matters more than its time).
    Wait,
}

/// The deadline settings of one egress stream.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GuardSettings {
    /// A fixed deadline; `None`: one frame period of `rate_hz` or of the measured rate.
    pub deadline: Option<Duration>,
    /// The stream's nominal rate, if configured.
    pub rate_hz: Option<f64>,
    /// What to do with a late frame.
    pub on_late: OnLate,
}

/// Why a raw frame was published instead of its perturbed version.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fallback {
    /// The perturbed frame did not arrive within the deadline (the daemon is stalled,
    /// overloaded, or dropped the frame).
    Late,
    /// `perturbd` is not running (its output has no publisher).
    DaemonDown,
    /// The kill switch holds.
    Killed,
}

impl Fallback {
    /// `late`, `daemon_down`, `killed`.
    pub fn as_str(self) -> &'static str {
        match self {
            Fallback::Late => "late",
            Fallback::DaemonDown => "daemon_down",
            Fallback::Killed => "killed",
        }
    }
}

/// Raw frames published in place of perturbed ones, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FallbackCounts {
    /// The perturbed frame missed its deadline.
    pub late: u64,
    /// `perturbd` was not running.
    pub daemon_down: u64,
    /// The kill switch held.
    pub killed: u64,
}

impl FallbackCounts {
    /// Counts one.
    pub fn add(&mut self, why: Fallback) {
        match why {
            Fallback::Late => self.late += 1,
            Fallback::DaemonDown => self.daemon_down += 1,
            Fallback::Killed => self.killed += 1,
        }
    }

    /// All reasons together.
    pub fn total(&self) -> u64 {
        self.late + self.daemon_down + self.killed
    }
}

/// The bridge's own kill switch, shared by every egress: set by the kill topic (or its
/// dead-man timeout), it makes every guarded egress publish raw frames at once, before the
/// daemon even knows; the daemon's latch (engaged through its control channel) keeps the
/// streams off after that.
#[derive(Debug, Default)]
pub struct LocalKill {
    engaged: AtomicBool,
}

impl LocalKill {
    /// True while engaged.
    pub fn engaged(&self) -> bool {
        self.engaged.load(Ordering::Acquire)
    }

    /// Engages or releases it.
    pub fn set(&self, on: bool) {
        self.engaged.store(on, Ordering::Release);
    }
}

/// What the guard decided for one frame.
pub enum Decision {
    /// Publish the perturbed frame (it may have passed unperturbed: perturbation off, killed in
    /// the daemon).
    Perturbed(Held),
    /// Publish the raw frame in its place, for this reason.
    Raw(Held, Fallback),
    /// Publish nothing: late or the daemon down, with `on_late = "drop"` (counted lost).
    Dropped(u64, Fallback),
}

/// What identifies a frame on both sides of the daemon: its sequence number and header stamp
/// (two publishers on one topic, or a driver that restarted, number their frames from the same
/// values; their stamps differ).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameKey {
    seq: u64,
    sec: i32,
    nanosec: u32,
}

impl FrameKey {
    /// The key of a held frame.
    pub fn of(f: &Held) -> Self {
        let h = f.payload();
        let h = h.header();
        FrameKey {
            seq: f.meta().seq,
            sec: h.stamp_sec,
            nanosec: h.stamp_nanosec,
        }
    }
}

/// A raw frame waiting for its perturbed version.
struct Pending {
    frame: Held,
    key: FrameKey,
    deadline: Instant,
}

/// The frame-matching state machine of one guarded egress (no I/O: the egress feeds it the
/// frames it receives and publishes what it returns, in order).
pub struct Guard {
    settings: GuardSettings,
    pending: VecDeque<Pending>,
    /// Frames published lately (a perturbed frame among them came too late).
    recent: VecDeque<FrameKey>,
    /// Recent raw inter-arrival intervals, ns.
    intervals: VecDeque<u64>,
    last_raw_ns: Option<u64>,
    /// Raw frames published in place of perturbed ones.
    pub fallback: FallbackCounts,
    /// Perturbed frames that came after their raw frame had gone out.
    pub late_discarded: u64,
    /// When the last perturbed frame arrived.
    last_perturbed: Option<Instant>,
}

/// How many recent sequence numbers the guard remembers.
const RECENT: usize = 256;
/// How many intervals the rate estimate uses.
const INTERVALS: usize = 15;
/// The deadline until the rate is known.
const INITIAL_DEADLINE: Duration = Duration::from_millis(100);

impl Guard {
    /// A guard with `settings`.
    pub fn new(settings: GuardSettings) -> Self {
        Guard {
            settings,
            pending: VecDeque::new(),
            recent: VecDeque::new(),
            intervals: VecDeque::new(),
            last_raw_ns: None,
            fallback: FallbackCounts::default(),
            late_discarded: 0,
            last_perturbed: None,
        }
    }

    /// The deadline a raw frame gets now.
    pub fn deadline(&self) -> Duration {
        if let Some(d) = self.settings.deadline {
            return d;
        }
        if let Some(hz) = self.settings.rate_hz.filter(|h| *h > 0.0) {
            return Duration::from_secs_f64(1.0 / hz);
        }
        if self.intervals.len() < 2 {
            return INITIAL_DEADLINE;
        }
        let mut v: Vec<u64> = self.intervals.iter().copied().collect();
        v.sort_unstable();
        Duration::from_nanos(v[v.len() / 2])
    }

    /// When the oldest waiting raw frame's deadline passes, if one waits.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.pending.front().map(|p| p.deadline)
    }

    /// Raw frames waiting.
    pub fn waiting(&self) -> usize {
        self.pending.len()
    }

    fn published(&mut self, key: FrameKey) {
        if self.recent.len() == RECENT {
            self.recent.pop_front();
        }
        self.recent.push_back(key);
    }

    fn late(&mut self, p: Pending, why: Fallback, out: &mut Vec<Decision>) {
        let seq = p.frame.meta().seq;
        self.published(p.key);
        match self.settings.on_late {
            OnLate::Raw => {
                self.fallback.add(why);
                out.push(Decision::Raw(p.frame, why));
            }
            // `wait` has no guard; treated as `drop` should a guard be built with it.
            OnLate::Drop | OnLate::Wait => out.push(Decision::Dropped(seq, why)),
        }
    }

    /// A raw frame arrived at `now`. `daemon_up`: the daemon's output has a publisher;
    /// `killed`: the bridge's kill switch holds.
    pub fn on_raw(
        &mut self,
        frame: Held,
        now: Instant,
        daemon_up: bool,
        killed: bool,
        out: &mut Vec<Decision>,
    ) {
        let t = monotonic_ns();
        if let Some(last) = self.last_raw_ns.replace(t)
            && t > last
        {
            if self.intervals.len() == INTERVALS {
                self.intervals.pop_front();
            }
            self.intervals.push_back(t - last);
        }
        let key = FrameKey::of(&frame);
        if self.recent.contains(&key) {
            // Its perturbed frame came first and went out.
            return;
        }
        if killed {
            // Raw at once, as the kill switch says, after what was waiting (in order).
            self.flush(Fallback::Killed, out);
            self.published(key);
            self.fallback.add(Fallback::Killed);
            out.push(Decision::Raw(frame, Fallback::Killed));
            return;
        }
        let deadline = self.deadline();
        let p = Pending {
            frame,
            key,
            deadline: now + deadline,
        };
        if !daemon_up {
            self.flush(Fallback::DaemonDown, out);
            self.late(p, Fallback::DaemonDown, out);
            return;
        }
        // A daemon silent for two deadlines is stalled: the frames go out at once, in the
        // sensor's cadence, until it delivers again (the first late frame waited its deadline).
        if self
            .last_perturbed
            .is_some_and(|t| now.saturating_duration_since(t) > 2 * deadline)
        {
            self.flush(Fallback::Late, out);
            self.late(p, Fallback::Late, out);
            return;
        }
        self.pending.push_back(p);
    }

    /// A perturbed frame arrived.
    pub fn on_perturbed(&mut self, frame: Held, out: &mut Vec<Decision>) {
        self.last_perturbed = Some(Instant::now());
        let key = FrameKey::of(&frame);
        if let Some(i) = self.pending.iter().position(|p| p.key == key) {
            // Older raw frames whose perturbed versions never came (the daemon dropped them):
            // they go out first, in order.
            for p in self.pending.drain(..i).collect::<Vec<_>>() {
                self.late(p, Fallback::Late, out);
            }
            self.pending.pop_front();
            self.published(key);
            out.push(Decision::Perturbed(frame));
        } else if self.recent.contains(&key) {
            self.late_discarded += 1;
        } else {
            // Its raw frame was never seen here (lost on this side, or a bus without a raw
            // side): it goes out, after the raw frames waiting (older).
            self.flush(Fallback::Late, out);
            self.published(key);
            out.push(Decision::Perturbed(frame));
        }
    }

    /// The deadlines that passed by `now`: those frames go out raw (or are dropped).
    pub fn expire(&mut self, now: Instant, daemon_up: bool, out: &mut Vec<Decision>) {
        while self.pending.front().is_some_and(|p| p.deadline <= now) {
            let p = self.pending.pop_front().expect("front exists");
            let why = if daemon_up {
                Fallback::Late
            } else {
                Fallback::DaemonDown
            };
            self.late(p, why, out);
        }
    }

    /// Everything still waiting goes out raw at once (the daemon is gone, or the kill switch
    /// was just engaged).
    pub fn flush(&mut self, why: Fallback, out: &mut Vec<Decision>) {
        while let Some(p) = self.pending.pop_front() {
            self.late(p, why, out);
        }
    }
}

/// Reads one side of a stream on a thread of its own (iceoryx2 ports live in the thread that
/// made them) and sends the frames, held, to `tx`. `publishers` tracks the side's publishers
/// (for the perturbed side: whether `perturbd` is up). Runs until `stop`; says on `ready` once
/// subscribed, or why it could not.
#[allow(clippy::too_many_arguments)]
pub fn reader_thread(
    bus: &dyn Bus,
    stream: &str,
    kind: StreamKind,
    side: Side,
    tx: crossbeam::channel::Sender<Held>,
    publishers: Arc<AtomicUsize>,
    stop: Arc<AtomicBool>,
    ready: crossbeam::channel::Sender<anyhow::Result<()>>,
) {
    let mut sub = match bus.subscriber(stream, kind, side) {
        Ok(s) => {
            let _ = ready.send(Ok(()));
            s
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    while !stop.load(Ordering::Relaxed) {
        match sub.recv_held(Duration::from_millis(20)) {
            Ok(frames) => {
                for f in frames {
                    if tx.send(f).is_err() {
                        return;
                    }
                }
            }
            Err(e) => {
                tracing::warn!("{stream}/{}: {e:#}", side.as_str());
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        publishers.store(sub.publishers().unwrap_or(1), Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{FrameMeta, OwnedPayload};
    use perturb_core::synthetic::street_image;

    fn frame(seq: u64) -> Held {
        frame_stamped(seq, seq as i32)
    }

    fn frame_stamped(seq: u64, sec: i32) -> Held {
        let meta = FrameMeta {
            seq,
            ..Default::default()
        };
        let p = OwnedPayload::Image {
            sec,
            nanosec: 0,
            frame_id: "cam".into(),
            image: street_image(8, 4, 0),
        };
        Box::new(std::sync::Arc::new((meta, p)))
    }

    fn seqs(out: &[Decision]) -> Vec<(u64, &'static str)> {
        out.iter()
            .map(|d| match d {
                Decision::Perturbed(f) => (f.meta().seq, "perturbed"),
                Decision::Raw(f, why) => (f.meta().seq, why.as_str()),
                Decision::Dropped(s, _) => (*s, "dropped"),
            })
            .collect()
    }

    fn guard(on_late: OnLate) -> Guard {
        Guard::new(GuardSettings {
            deadline: Some(Duration::from_millis(30)),
            rate_hz: None,
            on_late,
        })
    }

    #[test]
    fn perturbed_frames_replace_their_raw_frames_in_time() {
        let mut g = guard(OnLate::Raw);
        let t = Instant::now();
        let mut out = Vec::new();
        for s in 0..3 {
            g.on_raw(frame(s), t, true, false, &mut out);
        }
        assert!(
            out.is_empty(),
            "nothing goes out before its perturbed frame or deadline"
        );
        g.on_perturbed(frame(0), &mut out);
        g.on_perturbed(frame(1), &mut out);
        g.expire(t + Duration::from_millis(10), true, &mut out);
        assert_eq!(seqs(&out), [(0, "perturbed"), (1, "perturbed")]);
        assert_eq!(g.waiting(), 1);
        assert_eq!(g.fallback.total(), 0);
    }

    #[test]
    fn a_late_frame_goes_out_raw_once_and_its_perturbed_frame_is_discarded() {
        let mut g = guard(OnLate::Raw);
        let t = Instant::now();
        let mut out = Vec::new();
        g.on_raw(frame(5), t, true, false, &mut out);
        g.expire(t + Duration::from_millis(29), true, &mut out);
        assert!(out.is_empty());
        g.expire(t + Duration::from_millis(31), true, &mut out);
        g.on_perturbed(frame(5), &mut out);
        assert_eq!(seqs(&out), [(5, "late")]);
        assert_eq!((g.fallback.late, g.late_discarded), (1, 1));
    }

    #[test]
    fn frames_the_daemon_skipped_go_out_raw_before_the_next_perturbed_one() {
        let mut g = guard(OnLate::Raw);
        let t = Instant::now();
        let mut out = Vec::new();
        for s in 10..13 {
            g.on_raw(frame(s), t, true, false, &mut out);
        }
        g.on_perturbed(frame(12), &mut out);
        assert_eq!(
            seqs(&out),
            [(10, "late"), (11, "late"), (12, "perturbed")],
            "in order"
        );
    }

    #[test]
    fn without_a_daemon_or_under_the_kill_switch_raw_frames_go_out_at_once() {
        let mut g = guard(OnLate::Raw);
        let t = Instant::now();
        let mut out = Vec::new();
        g.on_raw(frame(0), t, true, false, &mut out);
        g.on_raw(frame(1), t, false, false, &mut out);
        g.on_raw(frame(2), t, true, true, &mut out);
        g.on_raw(frame(3), t, true, false, &mut out);
        g.expire(t + Duration::from_secs(1), false, &mut out);
        assert_eq!(
            seqs(&out),
            [
                (0, "daemon_down"),
                (1, "daemon_down"),
                (2, "killed"),
                (3, "daemon_down")
            ],
            "in order: what waited goes out first"
        );
        assert_eq!(
            g.fallback,
            FallbackCounts {
                late: 0,
                daemon_down: 3,
                killed: 1
            }
        );
    }

    #[test]
    fn drop_policy_publishes_nothing_for_a_late_frame() {
        let mut g = guard(OnLate::Drop);
        let t = Instant::now();
        let mut out = Vec::new();
        g.on_raw(frame(1), t, true, false, &mut out);
        g.on_raw(frame(2), t, false, false, &mut out);
        g.expire(t + Duration::from_secs(1), true, &mut out);
        assert_eq!(seqs(&out), [(1, "dropped"), (2, "dropped")]);
        assert_eq!(g.fallback.total(), 0);
    }

    #[test]
    fn a_raw_frame_after_its_perturbed_one_is_not_published_again_but_a_restarted_publisher_is() {
        let mut g = guard(OnLate::Raw);
        let t = Instant::now();
        let mut out = Vec::new();
        g.on_perturbed(frame(4), &mut out);
        g.on_raw(frame(4), t, true, false, &mut out);
        g.expire(t + Duration::from_secs(1), true, &mut out);
        assert_eq!(seqs(&out), [(4, "perturbed")]);
        // Another publisher (or the driver restarted): the same numbers, other stamps.
        g.on_raw(frame_stamped(4, 99), t, true, false, &mut out);
        g.on_perturbed(frame_stamped(4, 99), &mut out);
        assert_eq!(seqs(&out), [(4, "perturbed"), (4, "perturbed")]);
    }

    #[test]
    fn a_stalled_daemon_gets_one_deadline_then_frames_go_out_at_once() {
        let mut g = guard(OnLate::Raw);
        let t = Instant::now();
        let mut out = Vec::new();
        g.on_raw(frame(1), t, true, false, &mut out);
        g.on_perturbed(frame(1), &mut out);
        let later = Instant::now() + Duration::from_millis(61);
        g.on_raw(frame(2), later, true, false, &mut out);
        assert_eq!(
            seqs(&out),
            [(1, "perturbed"), (2, "late")],
            "silent for 61 ms > 2 x 30 ms"
        );
    }

    #[test]
    fn the_deadline_follows_the_measured_rate() {
        let g = Guard::new(GuardSettings::default());
        assert_eq!(g.deadline(), INITIAL_DEADLINE);
        let g = Guard::new(GuardSettings {
            rate_hz: Some(20.0),
            ..Default::default()
        });
        assert_eq!(g.deadline(), Duration::from_millis(50));
        let mut g = Guard::new(GuardSettings::default());
        g.intervals
            .extend([33_000_000, 34_000_000, 90_000_000, 33_500_000]);
        assert_eq!(g.deadline(), Duration::from_nanos(34_000_000));
    }
}
