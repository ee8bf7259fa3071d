//! The iceoryx2 bus (through perturb-wire): not in this build yet.

use crate::bus::Bus;
use anyhow::Result;
use std::sync::Arc;

/// The iceoryx2 bus of node `name`.
pub fn bus(_name: &str) -> Result<Arc<dyn Bus>> {
    anyhow::bail!(
        "bridge.bus = \"iceoryx2\" needs the perturb-wire crate, which this build does not have yet; use bus = \"local\""
    )
}
