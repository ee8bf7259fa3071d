//! The processing thread: checks each frame, perturbs it straight from the input sample into a
//! loaned output sample and publishes it; bad frames and failures are counted, never fatal.

use super::runtime::StreamRuntime;
use super::{Item, TICK, should_log};
use crate::perturbation::Active;
use crate::stats::Counters;
use crossbeam::channel::{Receiver, RecvTimeoutError};
use perturb_core::encoding::Scratch;
use perturb_core::registry::Modality;
use perturb_wire::{Frame, FramePublisher, LayoutCache, WireError, WireModality, monotonic_ns};
use std::sync::atomic::Ordering;
use tracing::{debug, error, info, warn};

pub(super) fn process_loop(
    rt: &StreamRuntime,
    mut publisher: FramePublisher,
    rx: Receiver<Item>,
    mut active: Option<Active>,
) {
    let name = rt.config.name.as_str();
    let mut cache = LayoutCache::default();
    let mut step = rt.step();
    // The conversion buffers of frames in encodings that are not working layouts (Bayer, YUV,
    // 16-bit), reused from frame to frame.
    let mut scratch = Scratch::new();
    loop {
        let item = match rx.recv_timeout(TICK) {
            Ok(i) => i,
            // The receiver drops the sender when it stops (shutdown); the queue is drained first.
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        if let Some((change, change_step)) = rt.take_pending() {
            step = change_step;
            match &change {
                Some(a) => info!(
                    stream = name,
                    id = a.spec().entry.id,
                    severity = a.spec().severity,
                    seed = a.spec().seed,
                    seq = item.frame.header().seq,
                    "perturbation active from this frame"
                ),
                None => info!(
                    stream = name,
                    seq = item.frame.header().seq,
                    "perturbation off from this frame"
                ),
            }
            active = change;
        }
        process_one(
            rt,
            &mut publisher,
            item,
            &mut active,
            step,
            &mut cache,
            &mut scratch,
        );
    }
    debug!(stream = name, "processor stopped");
}

/// Checks a received frame is one the stream can process: header and payload agree, the
/// modality is the stream's, the image's encoding is in the encoding table and its size, step
/// and data fit it, or the point layout is readable.
pub(super) fn check(
    modality: Modality,
    frame: &Frame,
    layouts: &mut LayoutCache,
) -> Result<(), WireError> {
    match modality {
        Modality::Camera => match frame.validate()? {
            WireModality::Camera => frame.header().encoded_view(frame.payload()).map(|_| ()),
            WireModality::Lidar => Err(WireError::invalid("expected an image, got a point cloud")),
        },
        Modality::Lidar => frame.cloud_cached(layouts).map(|_| ()),
    }
}

/// Counts an invalid frame and logs it (the first ten, then every 100th); an encoding the
/// table does not have is logged once per stream and encoding instead.
pub(super) fn invalid(rt: &StreamRuntime, seq: u64, e: &WireError) {
    let n = rt.stats.counters.invalid.fetch_add(1, Ordering::Relaxed) + 1;
    if let WireError::Core(perturb_core::Error::UnsupportedEncoding { encoding }) = e {
        let mut seen = rt.unsupported.lock().unwrap_or_else(|p| p.into_inner());
        if seen.insert(encoding.clone()) {
            warn!(
                stream = rt.config.name.as_str(),
                seq,
                invalid = n,
                "{e}; frames in `{encoding}` are counted as invalid and skipped, the stream carries on (logged once)"
            );
        }
        return;
    }
    if should_log(n) {
        warn!(
            stream = rt.config.name.as_str(),
            seq,
            invalid = n,
            "invalid frame skipped: {e}"
        );
    }
}

fn failed(rt: &StreamRuntime, seq: u64, id: &str, e: &dyn std::fmt::Display) {
    let n = rt
        .stats
        .counters
        .perturb_failed
        .fetch_add(1, Ordering::Relaxed)
        + 1;
    if should_log(n) {
        warn!(
            stream = rt.config.name.as_str(),
            seq, id, "perturbation failed, frame forwarded unperturbed: {e}"
        );
    }
}

fn process_one(
    rt: &StreamRuntime,
    publisher: &mut FramePublisher,
    item: Item,
    active: &mut Option<Active>,
    step: u16,
    cache: &mut LayoutCache,
    scratch: &mut Scratch,
) {
    let Item { frame, t_rx } = item;
    let h = *frame.header();
    let want = match rt.config.modality {
        Modality::Camera => WireModality::Camera,
        Modality::Lidar => WireModality::Lidar,
    };
    match frame.validate() {
        Ok(m) if m == want => {}
        Ok(m) => {
            let e = WireError::invalid(format!(
                "a {} frame on a {} stream",
                m.as_str(),
                want.as_str()
            ));
            return invalid(rt, h.seq, &e);
        }
        Err(e) => return invalid(rt, h.seq, &e),
    }
    let t0 = monotonic_ns();
    let budget_ns = (rt.config.budget() * 1e6) as u64;
    let due = ingress(&h, t_rx).unwrap_or(t_rx).saturating_add(budget_ns);
    // The kill switch: raw frames from the next frame on, whatever the stream is set to run.
    let killed = rt.kill.engaged();
    let mut held = None;
    let active = if killed { &mut held } else { active };
    let loan = match want {
        WireModality::Camera => camera(rt, publisher, &frame, &h, due, active, scratch),
        WireModality::Lidar => lidar(rt, publisher, &frame, &h, due, active, cache),
    };
    let mut loan = match loan {
        Ok(Some(l)) => l,
        Ok(None) => return,
        Err(e) => {
            let n = rt
                .stats
                .counters
                .dropped_output
                .fetch_add(1, Ordering::Relaxed)
                + 1;
            if should_log(n) {
                error!(
                    stream = rt.config.name.as_str(),
                    seq = h.seq,
                    "frame dropped, no output sample: {e}"
                );
            }
            return;
        }
    };
    let t1 = monotonic_ns();
    {
        let hd = loan.header_mut();
        hd.t_daemon_rx_ns = t_rx;
        hd.t_daemon_tx_ns = monotonic_ns();
        hd.flags = if killed {
            perturb_wire::header::FLAG_KILLED
        } else {
            0
        };
        hd.campaign_step = if killed { 0 } else { step };
    }
    let t_tx = loan.header().t_daemon_tx_ns;
    drop(frame); // hand the input sample back before publishing
    let c = &rt.stats.counters;
    match publisher.send(loan) {
        Ok(_) => Counters::add(&c.frames_out, 1),
        Err(e) => {
            let n = c.dropped_output.fetch_add(1, Ordering::Relaxed) + 1;
            if should_log(n) {
                error!(
                    stream = rt.config.name.as_str(),
                    seq = h.seq,
                    "publishing failed: {e}"
                );
            }
            return;
        }
    }
    let mut lat = rt.stats.latencies.lock().unwrap_or_else(|p| p.into_inner());
    lat.perturb.record(t1.saturating_sub(t0));
    lat.rx_to_tx.record(t_tx.saturating_sub(t_rx));
    let total = match ingress(&h, t_rx) {
        Some(t_in) => {
            lat.ingress_to_rx.record(t_rx - t_in);
            lat.ingress_to_tx.record(t_tx - t_in);
            t_tx - t_in
        }
        None => t_tx.saturating_sub(t_rx),
    };
    drop(lat);
    if total > budget_ns {
        let n = c.over_budget.fetch_add(1, Ordering::Relaxed) + 1;
        if should_log(n) {
            warn!(
                stream = rt.config.name.as_str(),
                seq = h.seq,
                latency_ms = total as f64 / 1e6,
                budget_ms = rt.config.budget(),
                "frame over budget"
            );
        }
    }
}

/// When a frame entered the middleware, its ingress stamp, if it has one on this host's clock
/// (else its budget counts from its reception by the daemon, `t_rx`).
fn ingress(h: &perturb_wire::FrameHeader, t_rx: u64) -> Option<u64> {
    (h.t_ingress_ns != 0 && h.t_ingress_ns <= t_rx).then_some(h.t_ingress_ns)
}

type Loan = perturb_wire::FrameLoan;

/// Writes the output image into a loan: perturbed (through the working view for encodings that
/// are not working layouts, written back in the input's encoding, size and step), or copied
/// when off (or when the perturbation fails). `Ok(None)`: the frame was invalid and counted.
/// `due`: the frame's deadline (CLOCK_MONOTONIC ns), its turn in the deadline gate.
fn camera(
    rt: &StreamRuntime,
    publisher: &FramePublisher,
    frame: &Frame,
    h: &perturb_wire::FrameHeader,
    due: u64,
    active: &mut Option<Active>,
    scratch: &mut Scratch,
) -> Result<Option<Loan>, WireError> {
    let input = match h
        .encoded_view(frame.payload())
        .and_then(|v| rt.with_bit_depth(v))
    {
        Ok(v) => v,
        Err(e) => {
            invalid(rt, h.seq, &e);
            return Ok(None);
        }
    };
    let g = input.working_geometry();
    {
        let mut last = rt.geometry.lock().unwrap_or_else(|p| p.into_inner());
        if *last != Some(g) {
            *last = Some(g);
        }
    }
    let len = h.data_len as usize;
    let mut loan = publisher.loan(len.max(1))?;
    *loan.header_mut() = *h;
    loan.header_mut().set_applied(None);
    let data = frame.data()?;
    match active {
        Some(Active::Camera(p)) => {
            let result = {
                let out = &mut loan.payload_mut()[..len];
                rt.on_workers(due, || p.apply_encoded(&input, out, h.seq, scratch))
            };
            match result {
                Ok(()) => {
                    let spec = p.spec();
                    loan.header_mut().set_applied(Some(&spec));
                }
                Err(e) => {
                    failed(rt, h.seq, p.spec().entry.id, &e);
                    loan.payload_mut()[..len].copy_from_slice(data);
                }
            }
        }
        _ => loan.payload_mut()[..len].copy_from_slice(data),
    }
    Ok(Some(loan))
}

/// Writes the output cloud into a loan sized for the perturbation's worst case and records the
/// size it produced (`due` as for [`camera`]).
fn lidar(
    rt: &StreamRuntime,
    publisher: &FramePublisher,
    frame: &Frame,
    h: &perturb_wire::FrameHeader,
    due: u64,
    active: &mut Option<Active>,
    cache: &mut LayoutCache,
) -> Result<Option<Loan>, WireError> {
    let input = match frame.cloud_cached(cache) {
        Ok(v) => v,
        Err(e) => {
            invalid(rt, h.seq, &e);
            return Ok(None);
        }
    };
    let data = frame.data()?;
    let len = data.len();
    if let Some(Active::Lidar(p)) = active {
        let max = p.max_output_bytes(&input);
        let mut loan = publisher.loan(max.max(1))?;
        *loan.header_mut() = *h;
        let payload = loan.payload_mut();
        match rt.on_workers(due, || p.apply(&input, payload, h.seq, None)) {
            Ok(shape) => {
                let spec = p.spec();
                let hd = loan.header_mut();
                hd.width = shape.width;
                hd.height = shape.height;
                hd.row_step = shape.row_step as u32;
                hd.data_len = shape.bytes as u64;
                hd.set_applied(Some(&spec));
                return Ok(Some(loan));
            }
            Err(e) => failed(rt, h.seq, p.spec().entry.id, &e),
        }
    }
    let mut loan = publisher.loan(len.max(1))?;
    *loan.header_mut() = *h;
    loan.header_mut().set_applied(None);
    loan.payload_mut()[..len].copy_from_slice(data);
    Ok(Some(loan))
}
