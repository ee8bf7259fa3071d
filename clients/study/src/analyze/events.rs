//! Perturbation events recorded apart from the runs: on the vehicle, `rosbag record` (or `ros2
//! bag record`) writes the ADS's topics and `perturb-bridge record` writes `/perturb/events`
//! into bags of its own. The events of every such bag are read once, in log-time order, and
//! each run takes those up to its end (the last one before its start gives its first condition).
//! Both recorders stamp log times with the same clock (one machine, or clocks kept in step by
//! NTP/PTP).

use crate::error::{Result, StudyError};
use crate::source::{find_runs, open_run};
use perturb_bag::dynamic::{MessageCodec, Value};
use perturb_bag::events::EventRecord;
use std::path::{Path, PathBuf};

/// Perturbation events from bags of their own, in log-time order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExternalEvents {
    /// (log time ns, event), sorted by time.
    pub events: Vec<(u64, EventRecord)>,
    /// The bags read.
    pub bags: Vec<PathBuf>,
    /// Messages that were not perturbation events (skipped).
    pub unreadable: usize,
}

impl ExternalEvents {
    /// The events with log times up to `end_ns`, from the last one before `start_ns` of each
    /// stream on (a stream's state at the start comes from its last event before it).
    pub fn window(&self, start_ns: u64, end_ns: u64) -> Vec<&(u64, EventRecord)> {
        let first_in = self.events.partition_point(|(t, _)| *t < start_ns);
        let last = self.events.partition_point(|(t, _)| *t <= end_ns);
        // Earlier events only matter as each stream's last one.
        let mut before: Vec<&(u64, EventRecord)> = Vec::new();
        for e in self.events[..first_in].iter().rev() {
            if !before.iter().any(|b| b.1.topic == e.1.topic) {
                before.push(e);
            }
        }
        before.reverse();
        before.extend(&self.events[first_in..last.max(first_in)]);
        before
    }

    /// Log time span of the events, ns.
    pub fn span(&self) -> Option<(u64, u64)> {
        Some((self.events.first()?.0, self.events.last()?.0))
    }
}

/// Reads the events topic of every bag in `dir` (a folder of bags, or one bag).
pub fn load_events_bags(dir: &Path, topic: &str) -> Result<ExternalEvents> {
    let found = find_runs(dir)?;
    let mut out = ExternalEvents::default();
    for entry in &found.runs {
        let bag = open_run(&entry.path)?;
        let topics = bag.topics()?;
        let Some(t) = topics.iter().find(|t| t.topic == topic) else {
            continue;
        };
        let codec = MessageCodec::new(
            &t.type_name,
            &t.schema_encoding,
            &t.schema,
            &t.message_encoding,
        )
        .map_err(|e| StudyError::input(&entry.path, format!("`{topic}`: {e}")))?;
        let path = codec
            .path("data")
            .map_err(|e| StudyError::input(&entry.path, format!("`{topic}`: {e}")))?;
        let mut bad = 0usize;
        bag.read(&[topic.to_string()], &mut |m| {
            match codec.get(m.data, &path) {
                Ok(Value::String(s)) => match EventRecord::parse(&s) {
                    Ok(ev) => out.events.push((m.log_time, ev)),
                    Err(_) => bad += 1,
                },
                _ => bad += 1,
            }
            Ok(())
        })?;
        out.unreadable += bad;
        out.bags.push(entry.path.clone());
    }
    if out.events.is_empty() {
        return Err(StudyError::input(
            dir,
            format!("no `{topic}` message in any bag (the events bags of `perturb-bridge record`)"),
        ));
    }
    out.events.sort_by_key(|e| e.0);
    Ok(out)
}
