//! The daemon's runtime control channel: iceoryx2 request-response carrying small JSON
//! documents, plus an event service of the same name that wakes the daemon when a request
//! arrives (no polling on either side of the daemon).
//!
//! Requests are [`ControlRequest`], answers [`ControlResponse`]: `ok`, an `error` message when not
//! ok, a `message` (the acknowledgement of a change) and, for `status` and `stats`, one
//! [`StreamReport`] per stream.

use crate::error::{WireError, WireResult};
use crate::transport::{Ipc, Transport, service_name};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

/// Version of the control documents; a daemon refuses requests of another version.
pub const CONTROL_VERSION: u32 = 1;

/// A control request.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "cmd", rename_all = "lowercase", deny_unknown_fields)]
pub enum ControlRequest {
    /// Activate perturbation `id` at `severity` on `stream` (seed: keep the stream's current
    /// seed when absent).
    Set {
        /// Stream name.
        stream: String,
        /// Perturbation ID or name.
        id: String,
        /// Severity.
        severity: u8,
        /// Seed.
        #[serde(default)]
        seed: Option<u64>,
    },
    /// Forward `stream` unchanged.
    Off {
        /// Stream name.
        stream: String,
    },
    /// The active perturbation of every stream.
    Status,
    /// Counters and latencies of every stream.
    Stats,
    /// The kill switch: every stream passes raw frames from the next frame on and stays so,
    /// across daemon restarts, until [`ControlRequest::Arm`] (`perturb ctl off --all`).
    Kill {
        /// What engaged it (logged, reported, in the events).
        #[serde(default)]
        reason: Option<String>,
    },
    /// Releases the kill switch: each stream goes back to what it is set to run
    /// (`perturb ctl arm`).
    Arm,
    /// The vehicle's position in the map frame, for a campaign's route and geofence steps (sent
    /// by the bridge from the pose topic).
    Pose {
        /// x, metres.
        x: f64,
        /// y, metres.
        y: f64,
    },
    /// The next manual step of the campaign (`perturb ctl next`).
    Next,
    /// Starts the campaign in `file` (replacing the one running), or with `stop` ends it (its
    /// streams pass raw frames); without either, says which runs (`perturb ctl campaign`).
    Campaign {
        /// The campaign file to start (a path the daemon can read).
        #[serde(default)]
        file: Option<String>,
        /// End the running campaign.
        #[serde(default)]
        stop: bool,
    },
}

/// The envelope on the wire: version + request.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ControlEnvelope {
    /// [`CONTROL_VERSION`].
    pub v: u32,
    /// The request.
    #[serde(flatten)]
    pub request: ControlRequest,
}

/// Latency percentiles in microseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LatencySummary {
    /// Samples recorded.
    pub count: u64,
    /// Median.
    pub p50_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// Largest.
    pub max_us: f64,
    /// Mean.
    pub mean_us: f64,
}

/// Latencies of one stream.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamLatency {
    /// Computing the perturbation (or the copy when off) into the output sample.
    pub perturb: LatencySummary,
    /// Ingress publish to daemon receive (the shared-memory hop and the wake-up).
    pub ingress_to_rx: LatencySummary,
    /// Daemon receive to daemon publish (queueing, perturbation, publish).
    pub rx_to_tx: LatencySummary,
    /// Ingress publish to daemon publish: what the budget applies to.
    pub ingress_to_tx: LatencySummary,
}

/// One stream's state and counters, as `perturb ctl status|stats --json` prints them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamReport {
    /// Stream name.
    pub name: String,
    /// `camera` or `lidar`.
    pub modality: String,
    /// Input service.
    pub input: String,
    /// Output service.
    pub output: String,
    /// Active perturbation ID (null when off).
    pub id: Option<String>,
    /// Its name in the catalogue.
    pub perturbation: Option<String>,
    /// Active severity (null when off).
    pub severity: Option<u8>,
    /// Seed used when a perturbation is active.
    pub seed: u64,
    /// Frames received from the input service.
    pub frames_in: u64,
    /// Frames published on the output service.
    pub frames_out: u64,
    /// Frames dropped, all causes: `dropped_queue + dropped_input + dropped_down +
    /// dropped_upstream + dropped_output + dropped_restart` (the same frames as `lost`, by
    /// cause).
    pub dropped: u64,
    /// Dropped because the worker fell behind (oldest pending frame replaced).
    pub dropped_queue: u64,
    /// Lost before the middleware (sensor, driver, network): gaps the source saw in the
    /// sensor's own sequence numbers, reported frame by frame (`lost_before` in the header).
    pub dropped_upstream: u64,
    /// Sent by the input's publisher while this daemon ran but never received: its input queue
    /// overflowed because it was stalled (SIGSTOP) or overloaded.
    #[serde(default)]
    pub dropped_input: u64,
    /// Sent by the input's publisher while no daemon ran (killed, crashed, restarting, not
    /// started yet); counted by the daemon that came next.
    #[serde(default)]
    pub dropped_down: u64,
    /// Perturbed but could not be published (no output sample, transport failure).
    pub dropped_output: u64,
    /// Taken in by a daemon that was killed before it published them (counted by the daemon
    /// that replaced it).
    #[serde(default)]
    pub dropped_restart: u64,
    /// Frames refused as invalid (counted, logged, skipped).
    pub invalid: u64,
    /// Frames whose perturbation failed; forwarded unperturbed (their header says so).
    pub perturb_failed: u64,
    /// Frames whose ingress-to-publish latency exceeded the budget.
    pub over_budget: u64,
    /// The stream's budget in milliseconds.
    pub budget_ms: f64,
    /// Sequence number of the last frame received.
    pub last_seq: Option<u64>,
    /// The frames the daemon did not publish, by cause (the causes every report uses).
    #[serde(default)]
    pub lost: LostByCause,
    /// True while the kill switch holds every stream off (until `perturb ctl arm`).
    #[serde(default)]
    pub killed: bool,
    /// The campaign step that set the stream's perturbation (1-based; 0: none).
    #[serde(default)]
    pub step: u16,
    /// Latencies (in `stats` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency: Option<StreamLatency>,
}

/// Frames lost, by cause: the same causes, with the same names, in `perturb ctl stats`, the
/// bridge's and the recorder's reports and the events channel. Each place counts the causes it
/// can see (the daemon cannot see a slow subscriber of the egress, the egress cannot see a
/// sensor's own drops on another bridge), and where two places see the same cause they count
/// the same frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LostByCause {
    /// Before the middleware: the sensor, its driver, the network (gaps in a ROS 1 publisher's
    /// header `seq`, counted per publisher by the ingress).
    pub upstream: u64,
    /// The daemon was not running (killed, crashed, restarting): published into the raw stream
    /// while no daemon read it, or taken in by a daemon that died before publishing them.
    pub daemon_down: u64,
    /// The daemon ran but did not keep up (stalled, overloaded): its input queue overflowed,
    /// its worker dropped the oldest waiting frame, or (egress) the perturbed frame came after
    /// its deadline.
    pub daemon_late: u64,
    /// The daemon could not publish a frame it had perturbed (no free output sample).
    pub daemon_output: u64,
    /// The egress could not deliver: a subscriber slower than the stream (ROS 1 queue full) or
    /// a write that failed.
    pub egress: u64,
    /// The recorder could not write a frame into the bag.
    pub recorder: u64,
}

impl LostByCause {
    /// Every cause with its name, in a fixed order (for tables and logs).
    pub fn causes(&self) -> [(&'static str, u64); 6] {
        [
            ("upstream", self.upstream),
            ("daemon_down", self.daemon_down),
            ("daemon_late", self.daemon_late),
            ("daemon_output", self.daemon_output),
            ("egress", self.egress),
            ("recorder", self.recorder),
        ]
    }

    /// All causes together.
    pub fn total(&self) -> u64 {
        self.causes().iter().map(|(_, n)| n).sum()
    }

    /// `upstream 3, daemon_down 40` (causes with a count only; `none` when nothing was lost).
    pub fn describe(&self) -> String {
        let parts: Vec<String> = self
            .causes()
            .iter()
            .filter(|(_, n)| *n > 0)
            .map(|(k, n)| format!("{k} {n}"))
            .collect();
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    }
}

/// Why and when the kill switch was engaged.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KillRecord {
    /// What engaged it (`perturb ctl off --all`, `kill topic /vehicle/takeover`, ...).
    pub reason: String,
    /// Unix time, seconds.
    pub since_unix_s: f64,
}

/// An answer.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ControlResponse {
    /// True if the request was carried out.
    pub ok: bool,
    /// Why not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The acknowledgement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    /// Per-stream reports (status, stats).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub streams: Option<Vec<StreamReport>>,
    /// The kill switch, when engaged (status, stats, kill).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub killed: Option<KillRecord>,
    /// The running campaign (status, stats, campaign, next).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaign: Option<CampaignStatus>,
}

/// What a running campaign is doing.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CampaignStatus {
    /// Its name.
    pub name: String,
    /// Its file.
    pub file: String,
    /// Seconds since it started.
    pub elapsed_s: f64,
    /// How many times `next` was called.
    pub next: usize,
    /// The vehicle's last position, if any came.
    pub pose: Option<[f64; 2]>,
    /// Its arc length along the route, if on the route.
    pub arc_length_m: Option<f64>,
    /// The steps active now, by name.
    pub active: Vec<String>,
}

impl ControlResponse {
    /// A failure with a message.
    pub fn error(msg: impl Into<String>) -> Self {
        ControlResponse {
            ok: false,
            error: Some(msg.into()),
            ..Default::default()
        }
    }

    /// A success with an acknowledgement.
    pub fn ack(msg: impl Into<String>) -> Self {
        ControlResponse {
            ok: true,
            message: Some(msg.into()),
            ..Default::default()
        }
    }
}

/// `perturb ctl` clients the control service accepts at once (each is an iceoryx2 node with a
/// client and a notifier on the service; a killed one holds its place until swept).
pub const MAX_CLIENTS: usize = 64;

/// How long [`ControlClient::connect`] retries a full control service.
pub const CONNECT_RETRY: Duration = Duration::from_secs(3);

/// True for the iceoryx2 errors of a service that is full (too many nodes, clients or
/// notifiers), which go away when other clients leave.
fn is_capacity(e: &WireError) -> bool {
    match e {
        WireError::Iceoryx { detail, .. } => detail.contains("ExceedsMax"),
        _ => false,
    }
}

type RrClient = Client<Ipc, [u8], (), [u8], ()>;
type RrServer = Server<Ipc, [u8], (), [u8], ()>;

/// The client side (`perturb ctl`).
pub struct ControlClient {
    service: String,
    client: RrClient,
    notifier: Notifier<Ipc>,
}

impl std::fmt::Debug for ControlClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControlClient")
            .field("service", &self.service)
            .finish()
    }
}

impl ControlClient {
    /// Connects to the daemon's control service (which must exist). When the service is full
    /// (more `perturb ctl` clients at once than [`MAX_CLIENTS`], or dead clients not swept yet),
    /// it retries for up to [`CONNECT_RETRY`] before giving up with [`WireError::Busy`].
    pub fn connect(transport: &Transport, service: &str) -> WireResult<Self> {
        let start = Instant::now();
        let mut pause = Duration::from_millis(5);
        loop {
            match Self::try_connect(transport, service) {
                Err(e) if is_capacity(&e) => {
                    if start.elapsed() >= CONNECT_RETRY {
                        return Err(WireError::Busy {
                            service: service.to_string(),
                            detail: format!(
                                "more `perturb ctl` clients at once than it accepts ({MAX_CLIENTS}); retried for {:.1} s, try again",
                                CONNECT_RETRY.as_secs_f64()
                            ),
                        });
                    }
                    std::thread::sleep(pause);
                    pause = (pause * 2).min(Duration::from_millis(100));
                }
                other => return other,
            }
        }
    }

    fn try_connect(transport: &Transport, service: &str) -> WireResult<Self> {
        let name = service_name(service)?;
        let not_running = |e: &dyn std::fmt::Debug| {
            let d = format!("{e:?}");
            if d.contains("DoesNotExist") {
                WireError::NoSuchService {
                    service: service.to_string(),
                    hint: format!(
                        "no perturbd is serving it in this iceoryx2 namespace ({}); start `perturbd --config FILE`, or point at its namespace with --iox2-prefix/--iox2-root",
                        transport.options().describe()
                    ),
                }
            } else {
                WireError::iox(format!("opening control service `{service}`"), d)
            }
        };
        let rr = transport
            .node()
            .service_builder(&name)
            .request_response::<[u8], [u8]>()
            .open()
            .map_err(|e| not_running(&e))?;
        let ev = transport
            .node()
            .service_builder(&name)
            .event()
            .open()
            .map_err(|e| not_running(&e))?;
        let client = rr
            .client_builder()
            .initial_max_slice_len(1024)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| WireError::iox("creating the control client", e))?;
        let notifier = ev
            .notifier_builder()
            .create()
            .map_err(|e| WireError::iox("creating the control notifier", e))?;
        Ok(ControlClient {
            service: service.to_string(),
            client,
            notifier,
        })
    }

    /// Sends `request` and waits up to `timeout` for the answer.
    pub fn request(
        &self,
        request: &ControlRequest,
        timeout: Duration,
    ) -> WireResult<ControlResponse> {
        let body = serde_json::to_vec(&ControlEnvelope {
            v: CONTROL_VERSION,
            request: request.clone(),
        })
        .map_err(|e| WireError::Control(format!("encoding the request: {e}")))?;
        let loan = self
            .client
            .loan_slice_uninit(body.len())
            .map_err(|e| WireError::iox("loaning a control request", e))?;
        let pending = loan
            .write_from_slice(&body)
            .send()
            .map_err(|e| WireError::iox("sending the control request", e))?;
        let _ = self.notifier.notify();
        let start = Instant::now();
        loop {
            if let Some(resp) = pending
                .receive()
                .map_err(|e| WireError::iox("receiving the control response", e))?
            {
                return serde_json::from_slice(resp.payload()).map_err(|e| {
                    WireError::Control(format!("perturbd sent an unreadable answer: {e}"))
                });
            }
            if start.elapsed() > timeout {
                return Err(WireError::Control(format!(
                    "perturbd did not answer on `{}` within {:.1} s: it may be busy (a heavy perturbation on every stream, a loaded machine) or stopped; try a longer --timeout, and see its log",
                    self.service,
                    timeout.as_secs_f64()
                )));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

/// The daemon side.
pub struct ControlServer {
    service: String,
    server: RrServer,
    listener: Listener<Ipc>,
}

impl std::fmt::Debug for ControlServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControlServer")
            .field("service", &self.service)
            .finish()
    }
}

impl ControlServer {
    /// Creates (or opens) the control service and serves it.
    pub fn create(transport: &Transport, service: &str) -> WireResult<Self> {
        let name = service_name(service)?;
        let rr = transport
            .node()
            .service_builder(&name)
            .request_response::<[u8], [u8]>()
            .max_servers(2)
            .max_clients(MAX_CLIENTS)
            .max_nodes(MAX_CLIENTS + 8)
            .open_or_create()
            .map_err(|e| crate::transport::open_error(service, e))?;
        let ev = transport
            .node()
            .service_builder(&name)
            .event()
            .max_listeners(4)
            .max_notifiers(MAX_CLIENTS + 8)
            .max_nodes(MAX_CLIENTS + 8)
            .open_or_create()
            .map_err(|e| crate::transport::open_error(service, e))?;
        let server = rr
            .server_builder()
            .initial_max_slice_len(64 * 1024)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| WireError::iox("creating the control server", e))?;
        let listener = ev
            .listener_builder()
            .create()
            .map_err(|e| WireError::iox("creating the control listener", e))?;
        Ok(ControlServer {
            service: service.to_string(),
            server,
            listener,
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The listener to attach to a WaitSet.
    pub fn listener(&self) -> &Listener<Ipc> {
        &self.listener
    }

    /// Answers every pending request with `handler`; returns how many were handled.
    pub fn serve(
        &self,
        mut handler: impl FnMut(ControlRequest) -> ControlResponse,
    ) -> WireResult<usize> {
        let _ = self.listener.try_wait(|_| {});
        let mut n = 0;
        while let Some(active) = self
            .server
            .receive()
            .map_err(|e| WireError::iox("receiving a control request", e))?
        {
            n += 1;
            let resp = match serde_json::from_slice::<ControlEnvelope>(active.payload()) {
                Ok(env) if env.v == CONTROL_VERSION => handler(env.request),
                Ok(env) => ControlResponse::error(format!(
                    "control protocol version {} is not supported (this perturbd speaks {CONTROL_VERSION})",
                    env.v
                )),
                Err(e) => ControlResponse::error(format!("malformed control request: {e}")),
            };
            respond(&active, &resp)?;
        }
        Ok(n)
    }
}

fn respond(
    active: &ActiveRequest<Ipc, [u8], (), [u8], ()>,
    resp: &ControlResponse,
) -> WireResult<()> {
    let body = serde_json::to_vec(resp)
        .map_err(|e| WireError::Control(format!("encoding a control response: {e}")))?;
    let loan = active
        .loan_slice_uninit(body.len())
        .map_err(|e| WireError::iox("loaning a control response", e))?;
    loan.write_from_slice(&body)
        .send()
        .map_err(|e| WireError::iox("sending a control response", e))
}
