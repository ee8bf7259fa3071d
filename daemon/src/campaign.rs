//! Running a campaign ([`perturb_campaign`]) in the daemon: on every tick (4 per second), every
//! pose the bridge forwards and every `perturb ctl next`, the campaign is evaluated and each of
//! its streams is switched to the step that holds now (or to raw frames), from its next frame
//! on. The frames carry the step (`campaign_step` in the header), so the egress's events record
//! says which step chose each frame's perturbation. While a campaign runs, `perturb ctl set` and
//! `off` on its streams are refused; the kill switch overrides it, like everything else.
//!
//! The campaign, its start time and its manual position are kept in the runtime state: a daemon
//! restarted mid-drive carries on with the same clock.

use crate::perturbation;
use crate::safety::unix_now;
use crate::worker::StreamRuntime;
use perturb_campaign::{Campaign, Inputs, Tracker};
use perturb_wire::control::CampaignStatus;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use tracing::{info, warn};

/// What the runtime state keeps of a running campaign.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CampaignState {
    /// The campaign file.
    pub file: PathBuf,
    /// When it started, Unix seconds.
    pub started_unix_s: f64,
    /// How many times `next` was called.
    pub next: usize,
}

/// A running campaign.
pub struct CampaignRunner {
    campaign: Campaign,
    state: CampaignState,
    tracker: Tracker,
    pose: Option<[f64; 2]>,
    /// What each stream runs now (step index, or None: raw).
    current: BTreeMap<String, Option<usize>>,
}

impl CampaignRunner {
    /// Loads `file` and checks it against the daemon's streams.
    pub fn start(
        file: PathBuf,
        streams: &[Arc<StreamRuntime>],
        resume: Option<&CampaignState>,
    ) -> Result<Self, String> {
        let campaign = Campaign::load(&file).map_err(|e| e.to_string())?;
        let names: Vec<(String, perturb_core::registry::Modality)> = streams
            .iter()
            .map(|s| (s.config.name.clone(), s.config.modality))
            .collect();
        campaign.check_streams(&names).map_err(|e| e.to_string())?;
        let state = match resume {
            Some(r) if r.file == file => r.clone(),
            _ => CampaignState {
                file,
                started_unix_s: unix_now(),
                next: 0,
            },
        };
        for s in streams {
            if campaign.streams().contains(&s.config.name) {
                s.set_campaign(true);
            }
        }
        info!(
            campaign = campaign.name.as_str(),
            file = %state.file.display(),
            steps = campaign.steps.len(),
            "campaign started"
        );
        Ok(CampaignRunner {
            tracker: campaign.tracker(),
            campaign,
            state,
            pose: None,
            current: BTreeMap::new(),
        })
    }

    /// What the runtime state keeps.
    pub fn state(&self) -> &CampaignState {
        &self.state
    }

    /// A new position of the vehicle.
    pub fn pose(&mut self, x: f64, y: f64) {
        self.pose = Some([x, y]);
    }

    /// `perturb ctl next`: the next manual step (past the last: none).
    pub fn advance(&mut self) -> Result<String, String> {
        if self.campaign.manual_steps() == 0 {
            return Err(format!(
                "campaign `{}` has no manual step",
                self.campaign.name
            ));
        }
        self.state.next += 1;
        Ok(if self.state.next > self.campaign.manual_steps() {
            format!(
                "past the last of {} manual step(s): their streams pass raw frames",
                self.campaign.manual_steps()
            )
        } else {
            format!(
                "manual step {} of {}",
                self.state.next,
                self.campaign.manual_steps()
            )
        })
    }

    /// Switches every stream of the campaign to the step that holds now; returns true if a
    /// stream changed.
    pub fn evaluate(&mut self, streams: &[Arc<StreamRuntime>]) -> bool {
        let inputs = Inputs {
            t: (unix_now() - self.state.started_unix_s).max(0.0),
            pose: self.pose,
            next: self.state.next,
        };
        let want = self.campaign.assignment(&inputs, &mut self.tracker);
        let mut changed = false;
        for (name, step) in want {
            if self.current.get(&name) == Some(&step) {
                continue;
            }
            let Some(rt) = streams.iter().find(|s| s.config.name == name) else {
                continue;
            };
            match step {
                Some(i) => {
                    let st = &self.campaign.steps[i];
                    match perturbation::build(
                        &rt.config,
                        &st.id,
                        st.severity,
                        st.seed,
                        rt.last_geometry(),
                    ) {
                        Ok((_, active)) => {
                            rt.set_step(Some(active), i as u16 + 1);
                            info!(
                                stream = name.as_str(),
                                step = st.name.as_str(),
                                id = st.id.as_str(),
                                severity = st.severity,
                                trigger = st.trigger.describe().as_str(),
                                t_s = inputs.t,
                                arc_length_m = self.tracker.arc_length(),
                                "campaign step on"
                            );
                        }
                        Err(e) => {
                            warn!(
                                stream = name.as_str(),
                                step = st.name.as_str(),
                                "campaign step cannot run: {e}"
                            );
                            rt.off();
                        }
                    }
                }
                None => {
                    rt.off();
                    info!(
                        stream = name.as_str(),
                        t_s = inputs.t,
                        "campaign: raw frames"
                    );
                }
            }
            self.current.insert(name, step);
            changed = true;
        }
        changed
    }

    /// Ends the campaign: its streams pass raw frames and take `set`/`off` again.
    pub fn stop(self, streams: &[Arc<StreamRuntime>]) {
        for s in streams {
            if s.in_campaign() {
                s.set_campaign(false);
                s.off();
            }
        }
        info!(campaign = self.campaign.name.as_str(), "campaign stopped");
    }

    /// What `perturb ctl status` shows.
    pub fn status(&self) -> CampaignStatus {
        let mut active: Vec<String> = self
            .current
            .values()
            .flatten()
            .map(|&i| self.campaign.steps[i].name.clone())
            .collect();
        active.sort();
        active.dedup();
        CampaignStatus {
            name: self.campaign.name.clone(),
            file: self.state.file.display().to_string(),
            elapsed_s: (unix_now() - self.state.started_unix_s).max(0.0),
            next: self.state.next,
            pose: self.pose,
            arc_length_m: self.tracker.arc_length(),
            active,
        }
    }
}
