//! The bridge's line to `perturbd`'s control channel (the kill switch engages the daemon's latch;
//! the pose of the vehicle goes to its campaign): connected when first needed, and again after a
//! failure (the daemon may have restarted).

use anyhow::Result;
use perturb_wire::control::{ControlClient, ControlRequest, ControlResponse};
use perturb_wire::{Transport, TransportOptions};
use std::time::Duration;

/// How long a request waits for the daemon's answer.
const ANSWER: Duration = Duration::from_millis(500);

/// A control channel to the daemon.
pub struct DaemonLink {
    transport: Option<Transport>,
    client: Option<ControlClient>,
    options: TransportOptions,
    service: String,
    node: String,
}

impl DaemonLink {
    /// A link to the control `service` in the namespace `iox2` (the `PERTURB_IOX2_*`
    /// variables override it, as for the bus); `role` names the iceoryx2 node.
    pub fn new(iox2: &TransportOptions, service: &str, role: &str) -> Self {
        DaemonLink {
            transport: None,
            client: None,
            options: iox2.clone().with_env_overrides(),
            service: service.to_string(),
            node: format!("perturb_bridge_{role}_{}", std::process::id()),
        }
    }

    /// Sends `req` and waits for the answer.
    pub fn request(&mut self, req: &ControlRequest) -> Result<ControlResponse> {
        if self.transport.is_none() {
            self.transport = Some(Transport::open(&self.node, &self.options)?);
        }
        if self.client.is_none() {
            let t = self.transport.as_ref().expect("opened above");
            self.client = Some(ControlClient::connect(t, &self.service)?);
        }
        let r = self
            .client
            .as_ref()
            .expect("connected above")
            .request(req, ANSWER);
        if r.is_err() {
            // The daemon may have restarted: connect again next time.
            self.client = None;
        }
        Ok(r?)
    }
}
