//! The daemon's controls in the live view: Foxglove services that send `perturb ctl`'s requests
//! over the daemon's control channel, with `perturb ctl`'s checks (a stream and an ID given, a
//! severity of 1..=5; the daemon checks the rest and its refusal comes back as the call's error):
//!
//! | service | request (JSON) | as |
//! |---|---|---|
//! | `/perturb/set` | `{"stream", "id", "severity", "seed"?}` | `perturb ctl set STREAM ID --severity N [--seed S]` |
//! | `/perturb/off` | `{"stream"}` | `perturb ctl off STREAM` |
//! | `/perturb/kill` | `{"reason"?}` | `perturb ctl off --all [--reason R]` (the kill switch) |
//! | `/perturb/arm` | `{}` | `perturb ctl arm` |
//! | `/perturb/status` | `{}` | `perturb ctl status --json` |
//!
//! The answer is the daemon's (`ControlResponse` as JSON). iceoryx2 ports live in the thread
//! that made them, so one thread owns the line to the daemon and the service handlers (on the
//! server's blocking pool) hand it their requests.

use crate::daemon_link::DaemonLink;
use crate::events::EventsHub;
use crate::frame::wall_ns;
use crossbeam::channel::{Receiver, Sender, bounded};
use foxglove::Schema;
use foxglove::websocket::service::{Request, Service, ServiceSchema};
use perturb_bag::events::EventRecord;
use perturb_wire::control::{ControlRequest, ControlResponse};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Why a control call failed.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// The request does not say what `perturb ctl` needs.
    #[error("{service}: {problem}")]
    BadRequest {
        /// The service.
        service: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The daemon did not answer.
    #[error("perturbd did not answer: {0}")]
    NoAnswer(String),
    /// The daemon refused (its words, as `perturb ctl` prints them).
    #[error("perturbd refused: {0}")]
    Refused(String),
}

/// A request for the control thread and where its answer goes.
type Call = (ControlRequest, Sender<Result<ControlResponse, String>>);

/// The handle the services and the statistics use to reach the daemon.
#[derive(Clone)]
pub struct DaemonPort {
    tx: Sender<Call>,
}

/// How long a caller waits for the control thread's answer (the link itself waits 500 ms).
const WAIT: Duration = Duration::from_secs(2);

impl DaemonPort {
    /// Sends `req` and waits for the daemon's answer; a refusal is an error.
    pub fn request(&self, req: ControlRequest) -> Result<ControlResponse, ControlError> {
        let (tx, rx) = bounded(1);
        self.tx
            .send((req, tx))
            .map_err(|_| ControlError::NoAnswer("the view is stopping".into()))?;
        let r = rx
            .recv_timeout(WAIT)
            .map_err(|_| ControlError::NoAnswer("no answer in 2 s".into()))?
            .map_err(ControlError::NoAnswer)?;
        if r.ok {
            Ok(r)
        } else {
            Err(ControlError::Refused(
                r.error.unwrap_or_else(|| "no reason given".into()),
            ))
        }
    }
}

/// The control thread's end: requests come in on `rx`, until `stop`.
pub fn port() -> (DaemonPort, Receiver<Call>) {
    let (tx, rx) = bounded(16);
    (DaemonPort { tx }, rx)
}

/// Runs the line to the daemon: each request is sent over `link` and its answer returned.
pub fn serve(mut link: DaemonLink, rx: Receiver<Call>, stop: &AtomicBool) {
    while !stop.load(Ordering::Relaxed) {
        let Ok((req, answer)) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let r = link.request(&req).map_err(|e| format!("{e:#}"));
        let _ = answer.send(r);
    }
}

/// The JSON schema of a service's request (`properties`, `required`), for the viewers.
fn request_schema(name: &str, properties: &str, required: &[&str]) -> Schema {
    let required: Vec<String> = required.iter().map(|r| format!("\"{r}\"")).collect();
    let text = format!(
        "{{\"$schema\":\"https://json-schema.org/draft/2020-12/schema\",\"type\":\"object\",\
         \"properties\":{{{properties}}},\"required\":[{}],\"additionalProperties\":false}}",
        required.join(",")
    );
    Schema::new(name, "jsonschema", text.into_bytes())
}

/// The response schema: the daemon's answer.
fn response_schema() -> Schema {
    Schema::new(
        "perturb.ControlResponse",
        "jsonschema",
        br#"{"$schema":"https://json-schema.org/draft/2020-12/schema","type":"object","required":["ok"],"properties":{"ok":{"type":"boolean"},"message":{"type":"string"},"streams":{"type":"array"},"killed":{"type":["object","null"]},"campaign":{"type":["object","null"]}}}"#.to_vec(),
    )
}

/// A JSON object from a request's payload.
fn object(
    service: &'static str,
    req: &Request,
) -> Result<serde_json::Map<String, serde_json::Value>, ControlError> {
    let bad = |problem: String| ControlError::BadRequest { service, problem };
    if req.encoding() != "json" {
        return Err(bad(format!(
            "the request is `{}`-encoded; send JSON",
            req.encoding()
        )));
    }
    let payload = req.payload();
    let payload = if payload.is_empty() { b"{}" } else { payload };
    match serde_json::from_slice(payload) {
        Ok(serde_json::Value::Object(m)) => Ok(m),
        Ok(_) => Err(bad("the request must be a JSON object".into())),
        Err(e) => Err(bad(format!("the request is not JSON: {e}"))),
    }
}

/// A string field that must be there and not be empty.
fn text(
    service: &'static str,
    m: &serde_json::Map<String, serde_json::Value>,
    key: &str,
) -> Result<String, ControlError> {
    match m.get(key) {
        Some(serde_json::Value::String(s)) if !s.trim().is_empty() => Ok(s.trim().to_string()),
        Some(other) => Err(ControlError::BadRequest {
            service,
            problem: format!("`{key}` must be a non-empty string, not {other}"),
        }),
        None => Err(ControlError::BadRequest {
            service,
            problem: format!("`{key}` is missing"),
        }),
    }
}

/// Makes the control request a service call asks for, with `perturb ctl`'s checks.
pub fn request_of(
    service: &'static str,
    req: &Request,
    client: u32,
) -> Result<ControlRequest, ControlError> {
    let m = object(service, req)?;
    let bad = |problem: String| ControlError::BadRequest { service, problem };
    let known = |keys: &[&str]| match m.keys().find(|k| !keys.contains(&k.as_str())) {
        Some(k) => Err(bad(format!(
            "unknown field `{k}` (known: {})",
            keys.join(", ")
        ))),
        None => Ok(()),
    };
    Ok(match service {
        "/perturb/set" => {
            known(&["stream", "id", "severity", "seed"])?;
            let severity = match m.get("severity").and_then(serde_json::Value::as_u64) {
                Some(s @ 1..=5) => s as u8,
                _ => {
                    return Err(bad(format!(
                        "`severity` must be a whole number in 1..=5, not {}",
                        m.get("severity")
                            .map_or("nothing".to_string(), |v| v.to_string())
                    )));
                }
            };
            let seed =
                match m.get("seed") {
                    None | Some(serde_json::Value::Null) => None,
                    Some(v) => Some(v.as_u64().ok_or_else(|| {
                        bad(format!("`seed` must be a whole number >= 0, not {v}"))
                    })?),
                };
            ControlRequest::Set {
                stream: text(service, &m, "stream")?,
                id: text(service, &m, "id")?,
                severity,
                seed,
            }
        }
        "/perturb/off" => {
            known(&["stream"])?;
            ControlRequest::Off {
                stream: text(service, &m, "stream")?,
            }
        }
        "/perturb/kill" => {
            known(&["reason"])?;
            let reason = match m.get("reason") {
                Some(serde_json::Value::String(r)) if !r.trim().is_empty() => r.trim().into(),
                None | Some(serde_json::Value::Null) => format!("live view (client {client})"),
                Some(v) => return Err(bad(format!("`reason` must be a string, not {v}"))),
            };
            ControlRequest::Kill {
                reason: Some(reason),
            }
        }
        "/perturb/arm" => {
            known(&[])?;
            ControlRequest::Arm
        }
        _ => {
            known(&[])?;
            ControlRequest::Status
        }
    })
}

/// The services (`/perturb/set`, `off`, `kill`, `arm`, `status`); a kill or an arm the daemon
/// took goes on the events channel as the kill topic's would.
pub fn services(daemon: DaemonPort, events: Option<Arc<EventsHub>>) -> Vec<Service> {
    let string = r#""type":"string","minLength":1"#;
    let defs: [(&'static str, String, &[&str]); 5] = [
        (
            "/perturb/set",
            format!(
                r#""stream":{{{string}}},"id":{{{string}}},"severity":{{"type":"integer","minimum":1,"maximum":5}},"seed":{{"type":"integer","minimum":0}}"#
            ),
            &["stream", "id", "severity"],
        ),
        (
            "/perturb/off",
            format!(r#""stream":{{{string}}}"#),
            &["stream"],
        ),
        ("/perturb/kill", r#""reason":{"type":"string"}"#.into(), &[]),
        ("/perturb/arm", String::new(), &[]),
        ("/perturb/status", String::new(), &[]),
    ];
    defs.into_iter()
        .map(|(name, props, required)| {
            let schema = ServiceSchema::new(format!("perturb{}", name.replace('/', ".")))
                .with_request(
                    "json",
                    request_schema(&format!("{name} request"), &props, required),
                )
                .with_response("json", response_schema());
            let (daemon, events) = (daemon.clone(), events.clone());
            Service::builder(name, schema).blocking_handler_fn(move |req: Request| {
                let client = u32::from(req.client_id());
                let request = request_of(name, &req, client)?;
                let kill_reason = match &request {
                    ControlRequest::Kill { reason } => reason.clone(),
                    _ => None,
                };
                let answer = daemon.request(request)?;
                if let Some(ev) = &events {
                    match (name, kill_reason) {
                        ("/perturb/kill", Some(r)) => {
                            ev.send(EventRecord::kill(true, &r, wall_ns()))
                        }
                        ("/perturb/arm", _) => ev.send(EventRecord::kill(
                            false,
                            &format!("live view (client {client})"),
                            wall_ns(),
                        )),
                        _ => {}
                    }
                }
                tracing::info!(
                    "live view: client {client} called {name}: {}",
                    answer.message.as_deref().unwrap_or("ok")
                );
                serde_json::to_vec(&answer).map_err(|e| ControlError::NoAnswer(e.to_string()))
            })
        })
        .collect()
}
