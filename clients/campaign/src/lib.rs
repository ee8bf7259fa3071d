//! # perturb-campaign
//!
//! A campaign says which perturbation each stream runs when, so that a test drive runs its plan
//! without an operator switching by hand. A campaign file (TOML) lists steps; each step names
//! its streams, a perturbation (id, severity, seed) and one trigger:
//!
//! - `time = [from, to]`: seconds since the campaign started;
//! - `route = [from, to]`: metres of arc length along the route (the vehicle's position projected
//!   on the route polyline, as `perturb analyze` does; `max_offset_m` from the route at most);
//! - `geofence = [[x, y], ...]`: while the vehicle is inside the polygon (map frame);
//! - `manual = true`: from one `perturb ctl next` to the next (manual steps run in file order).
//!
//! Outside every step's trigger a stream passes raw frames. A stream's steps use one kind of
//! trigger and never overlap (checked when the file is read), so at any time a stream runs at
//! most one step.
//!
//! ```
//! use perturb_campaign::{Campaign, Inputs};
//! let c = Campaign::parse(r#"
//! [[steps]]
//! name = "rain"
//! streams = ["cam_front"]
//! id = "C-C7"
//! severity = 3
//! trigger = { time = [10.0, 20.0] }
//! "#, None).unwrap();
//! let mut t = c.tracker();
//! assert_eq!(c.assignment(&Inputs { t: 12.0, ..Default::default() }, &mut t)["cam_front"], Some(0));
//! assert_eq!(c.assignment(&Inputs { t: 25.0, ..Default::default() }, &mut t)["cam_front"], None);
//! ```

use perturb_core::registry::{self, Modality};
use perturb_core::route::{Polygon, Route};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What is wrong with a campaign; every variant says where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CampaignError {
    /// A file could not be read.
    #[error("{path}: {reason}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The TOML does not parse.
    #[error("{key}: {reason}")]
    Syntax {
        /// Where (`line 4 \`trigger\``, `steps[2]`).
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A step's field is wrong.
    #[error("steps[{index}] ({name}).{field}: {reason}")]
    Step {
        /// The step's index in the file.
        index: usize,
        /// Its name.
        name: String,
        /// The field at fault (`trigger.geofence`, `id`).
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// The route does not parse.
    #[error("route {path}: {reason}")]
    Route {
        /// The CSV file.
        path: PathBuf,
        /// What is wrong (with the line).
        reason: String,
    },
    /// Two steps of one stream may be active at once.
    #[error(
        "steps[{a}] ({a_name}) and steps[{b}] ({b_name}) overlap on stream `{stream}`: {reason}"
    )]
    Overlap {
        /// The stream.
        stream: String,
        /// The first step.
        a: usize,
        /// Its name.
        a_name: String,
        /// The second step.
        b: usize,
        /// Its name.
        b_name: String,
        /// How.
        reason: String,
    },
}

/// A step's trigger, as written.
#[derive(Clone, Debug, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TriggerFile {
    time: Option<[f64; 2]>,
    route: Option<[f64; 2]>,
    geofence: Option<Vec<[f64; 2]>>,
    manual: Option<bool>,
}

/// A step, as written.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StepFile {
    name: Option<String>,
    streams: Vec<String>,
    id: String,
    severity: u8,
    #[serde(default)]
    seed: u64,
    trigger: TriggerFile,
}

/// `[route]`, as written.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RouteFile {
    csv: PathBuf,
    #[serde(default = "default_offset")]
    max_offset_m: f64,
}

fn default_offset() -> f64 {
    10.0
}

/// The file, as written.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CampaignFile {
    name: Option<String>,
    route: Option<RouteFile>,
    #[serde(default)]
    steps: Vec<StepFile>,
}

/// When a step is active.
#[derive(Clone, Debug, PartialEq)]
pub enum Trigger {
    /// Seconds since the campaign started, `[from, to)`.
    Time(f64, f64),
    /// Arc length along the route, metres, `[from, to)`.
    Route(f64, f64),
    /// Inside this polygon.
    Geofence(Polygon),
    /// The `k`-th manual step (0-based among the manual steps): from the `k+1`-th `next` on,
    /// until the following one.
    Manual(usize),
}

impl Trigger {
    /// `time`, `route`, `geofence`, `manual`.
    pub fn kind(&self) -> &'static str {
        match self {
            Trigger::Time(..) => "time",
            Trigger::Route(..) => "route",
            Trigger::Geofence(_) => "geofence",
            Trigger::Manual(_) => "manual",
        }
    }

    /// In words (`time 10-20 s`, `route 100-600 m`, `geofence of 4 vertices`, `manual #2`).
    pub fn describe(&self) -> String {
        match self {
            Trigger::Time(a, b) => format!("time {a}-{b} s"),
            Trigger::Route(a, b) => format!("route {a}-{b} m"),
            Trigger::Geofence(p) => format!("geofence of {} vertices", p.points.len()),
            Trigger::Manual(k) => format!("manual #{}", k + 1),
        }
    }
}

/// One step of a campaign.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// Its name (`step 3` when the file gives none).
    pub name: String,
    /// The streams it perturbs.
    pub streams: Vec<String>,
    /// The perturbation's catalogue id (`C-C7`).
    pub id: String,
    /// Its severity.
    pub severity: u8,
    /// Its seed.
    pub seed: u64,
    /// When it is active.
    pub trigger: Trigger,
}

/// A campaign, checked.
#[derive(Clone, Debug, PartialEq)]
pub struct Campaign {
    /// Its name.
    pub name: String,
    /// The steps, in file order.
    pub steps: Vec<Step>,
    /// The route of the `route` triggers.
    pub route: Option<Route>,
    /// How far from the route (metres) the vehicle may be for its arc length to count.
    pub max_offset_m: f64,
}

/// What a campaign is evaluated on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Inputs {
    /// Seconds since the campaign started.
    pub t: f64,
    /// The vehicle's position in the map frame, if known.
    pub pose: Option<[f64; 2]>,
    /// How many times `perturb ctl next` was called (0: no manual step yet).
    pub next: usize,
}

/// Where the vehicle was last found along the route (so a route that passes near itself is
/// followed in order).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tracker {
    last_s: Option<f64>,
}

impl Tracker {
    /// The arc length found last, metres.
    pub fn arc_length(&self) -> Option<f64> {
        self.last_s
    }
}

impl Campaign {
    /// Reads and checks a campaign file; a `[route] csv` is relative to the file.
    pub fn load(path: &Path) -> Result<Campaign, CampaignError> {
        let text = std::fs::read_to_string(path).map_err(|e| CampaignError::Io {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        Campaign::parse(&text, path.parent())
    }

    /// Parses and checks campaign text; `dir` is where a relative route CSV is looked for
    /// (`None`: the current folder).
    pub fn parse(text: &str, dir: Option<&Path>) -> Result<Campaign, CampaignError> {
        let file: CampaignFile = toml::from_str(text).map_err(|e| {
            let key = e
                .span()
                .map(|s| {
                    let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                    format!("line {line}")
                })
                .unwrap_or_else(|| "(toml)".into());
            CampaignError::Syntax {
                key,
                reason: e.message().to_string(),
            }
        })?;
        let (route, max_offset_m) = match &file.route {
            Some(r) => {
                let path = match dir {
                    Some(d) if r.csv.is_relative() => d.join(&r.csv),
                    _ => r.csv.clone(),
                };
                let text = std::fs::read_to_string(&path).map_err(|e| CampaignError::Io {
                    path: path.clone(),
                    reason: e.to_string(),
                })?;
                let route = Route::from_csv_text(&text)
                    .map_err(|reason| CampaignError::Route { path, reason })?;
                if !(r.max_offset_m.is_finite() && r.max_offset_m > 0.0) {
                    return Err(CampaignError::Syntax {
                        key: "route.max_offset_m".into(),
                        reason: format!("{} must be a positive number of metres", r.max_offset_m),
                    });
                }
                (Some(route), r.max_offset_m)
            }
            None => (None, default_offset()),
        };
        Campaign::from_file(file, route, max_offset_m)
    }

    /// The same campaign with another route (`perturb campaign check --route`).
    pub fn with_route(mut self, route: Route) -> Self {
        self.route = Some(route);
        self
    }

    fn from_file(
        file: CampaignFile,
        route: Option<Route>,
        max_offset_m: f64,
    ) -> Result<Campaign, CampaignError> {
        if file.steps.is_empty() {
            return Err(CampaignError::Syntax {
                key: "steps".into(),
                reason: "a campaign needs at least one [[steps]]".into(),
            });
        }
        let mut steps = Vec::new();
        let mut manual = 0;
        for (index, s) in file.steps.into_iter().enumerate() {
            let name = s
                .name
                .clone()
                .unwrap_or_else(|| format!("step {}", index + 1));
            let bad = |field: &str, reason: String| CampaignError::Step {
                index,
                name: name.clone(),
                field: field.into(),
                reason,
            };
            if s.streams.is_empty() {
                return Err(bad("streams", "names no stream".into()));
            }
            if let Some(st) = s.streams.iter().find(|st| st.trim().is_empty()) {
                return Err(bad("streams", format!("`{st}` is not a stream name")));
            }
            let entry = registry::find(&s.id).map_err(|e| bad("id", e.to_string()))?;
            registry::find_with_severity(entry.id, s.severity)
                .map_err(|e| bad("severity", e.to_string()))?;
            let t = &s.trigger;
            let given = [
                t.time.is_some(),
                t.route.is_some(),
                t.geofence.is_some(),
                t.manual.is_some(),
            ];
            if given.iter().filter(|g| **g).count() != 1 {
                return Err(bad(
                    "trigger",
                    "give exactly one of `time = [from, to]`, `route = [from, to]`, `geofence = [[x, y], ...]`, `manual = true`".into(),
                ));
            }
            let interval = |field: &str, [a, b]: [f64; 2], unit: &str| {
                if a.is_finite() && b.is_finite() && a >= 0.0 && a < b {
                    Ok(())
                } else {
                    Err(bad(
                        field,
                        format!(
                            "[{a}, {b}] must be a window [from, to) of {unit} with 0 <= from < to"
                        ),
                    ))
                }
            };
            let trigger = if let Some(w) = t.time {
                interval("trigger.time", w, "seconds")?;
                Trigger::Time(w[0], w[1])
            } else if let Some(w) = t.route {
                interval("trigger.route", w, "metres")?;
                if route.is_none() {
                    return Err(bad(
                        "trigger.route",
                        "a route trigger needs the campaign's [route] (csv = \"route.csv\")".into(),
                    ));
                }
                Trigger::Route(w[0], w[1])
            } else if let Some(p) = &t.geofence {
                Trigger::Geofence(Polygon::new(p.clone()).map_err(|e| bad("trigger.geofence", e))?)
            } else {
                if t.manual != Some(true) {
                    return Err(bad("trigger.manual", "must be `true`".into()));
                }
                manual += 1;
                Trigger::Manual(manual - 1)
            };
            steps.push(Step {
                name,
                streams: s.streams,
                id: entry.id.to_string(),
                severity: s.severity,
                seed: s.seed,
                trigger,
            });
        }
        let c = Campaign {
            name: file.name.unwrap_or_else(|| "campaign".into()),
            steps,
            route,
            max_offset_m,
        };
        c.check_overlaps()?;
        Ok(c)
    }

    /// No stream has two steps that can be active at once.
    fn check_overlaps(&self) -> Result<(), CampaignError> {
        for (a, sa) in self.steps.iter().enumerate() {
            for (b, sb) in self.steps.iter().enumerate().skip(a + 1) {
                let Some(stream) = sa.streams.iter().find(|s| sb.streams.contains(s)) else {
                    continue;
                };
                let reason = match (&sa.trigger, &sb.trigger) {
                    (Trigger::Time(a0, a1), Trigger::Time(b0, b1))
                    | (Trigger::Route(a0, a1), Trigger::Route(b0, b1)) => {
                        (a0 < b1 && b0 < a1).then(|| "their windows overlap".to_string())
                    }
                    (Trigger::Geofence(p), Trigger::Geofence(q)) => {
                        p.overlaps(q).then(|| "their polygons overlap".to_string())
                    }
                    (Trigger::Manual(_), Trigger::Manual(_)) => None,
                    (x, y) => Some(format!(
                        "a stream's steps use one kind of trigger ({} and {} could hold at once)",
                        x.kind(),
                        y.kind()
                    )),
                };
                if let Some(reason) = reason {
                    return Err(CampaignError::Overlap {
                        stream: stream.clone(),
                        a,
                        a_name: sa.name.clone(),
                        b,
                        b_name: sb.name.clone(),
                        reason,
                    });
                }
            }
        }
        Ok(())
    }

    /// Checks the campaign against the streams that run it (name and modality): every stream
    /// exists and every step's perturbation fits its modality.
    pub fn check_streams(&self, streams: &[(String, Modality)]) -> Result<(), CampaignError> {
        for (index, s) in self.steps.iter().enumerate() {
            let entry = registry::find(&s.id).map_err(|e| CampaignError::Step {
                index,
                name: s.name.clone(),
                field: "id".into(),
                reason: e.to_string(),
            })?;
            for st in &s.streams {
                let bad = |reason: String| CampaignError::Step {
                    index,
                    name: s.name.clone(),
                    field: "streams".into(),
                    reason,
                };
                match streams.iter().find(|(n, _)| n == st) {
                    None => {
                        let known: Vec<&str> = streams.iter().map(|(n, _)| n.as_str()).collect();
                        return Err(bad(format!(
                            "no stream `{st}` (streams: {})",
                            known.join(", ")
                        )));
                    }
                    Some((_, m)) if *m != entry.modality => {
                        return Err(bad(format!(
                            "{} is a {:?} perturbation and `{st}` a {m:?} stream",
                            entry.id, entry.modality
                        )));
                    }
                    Some(_) => {}
                }
            }
        }
        Ok(())
    }

    /// Every stream the campaign drives.
    pub fn streams(&self) -> Vec<String> {
        let mut v: Vec<String> = self.steps.iter().flat_map(|s| s.streams.clone()).collect();
        v.sort();
        v.dedup();
        v
    }

    /// A fresh route tracker.
    pub fn tracker(&self) -> Tracker {
        Tracker::default()
    }

    /// The vehicle's arc length along the route, if it is within `max_offset_m` of it.
    pub fn arc_length(&self, pose: [f64; 2], tracker: &mut Tracker) -> Option<f64> {
        let route = self.route.as_ref()?;
        let p = match tracker.last_s {
            Some(s) => route.project_near(pose, s),
            None => route.project(pose),
        };
        if p.offset.abs() > self.max_offset_m {
            // Off the route: the next fix searches the whole route again.
            tracker.last_s = None;
            return None;
        }
        tracker.last_s = Some(p.s);
        Some(p.s)
    }

    /// The steps whose trigger holds for `inputs`.
    pub fn active(&self, inputs: &Inputs, tracker: &mut Tracker) -> Vec<usize> {
        let s = inputs.pose.and_then(|p| self.arc_length(p, tracker));
        self.steps
            .iter()
            .enumerate()
            .filter(|(_, step)| match &step.trigger {
                Trigger::Time(a, b) => inputs.t >= *a && inputs.t < *b,
                Trigger::Route(a, b) => s.is_some_and(|s| s >= *a && s < *b),
                Trigger::Geofence(p) => inputs.pose.is_some_and(|x| p.contains(x)),
                Trigger::Manual(k) => inputs.next == k + 1,
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// Each stream of the campaign with the step it runs now (`None`: raw).
    pub fn assignment(
        &self,
        inputs: &Inputs,
        tracker: &mut Tracker,
    ) -> BTreeMap<String, Option<usize>> {
        let mut out: BTreeMap<String, Option<usize>> =
            self.streams().into_iter().map(|s| (s, None)).collect();
        for i in self.active(inputs, tracker) {
            for st in &self.steps[i].streams {
                out.insert(st.clone(), Some(i));
            }
        }
        out
    }

    /// How many manual steps there are.
    pub fn manual_steps(&self) -> usize {
        self.steps
            .iter()
            .filter(|s| matches!(s.trigger, Trigger::Manual(_)))
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Campaign, CampaignError> {
        Campaign::parse(s, None)
    }

    const STEP: &str =
        "[[steps]]\nname = \"a\"\nstreams = [\"cam\"]\nid = \"C-C7\"\nseverity = 3\n";

    #[test]
    fn bad_campaigns_name_the_step_and_field() {
        let e = parse(&format!(
            "{STEP}trigger = {{ geofence = [[0, 0], [1, 1]] }}\n"
        ))
        .unwrap_err();
        assert!(
            matches!(&e, CampaignError::Step { index: 0, field, .. } if field == "trigger.geofence"),
            "{e}"
        );
        assert!(e.to_string().contains("at least 3"), "{e}");
        let e = parse(&format!("{STEP}trigger = {{ time = [5, 1] }}\n")).unwrap_err();
        assert!(e.to_string().contains("steps[0] (a).trigger.time"), "{e}");
        let e = parse(&format!(
            "{}trigger = {{ time = [0, 1] }}\n",
            STEP.replace("C-C7", "C-Z9")
        ))
        .unwrap_err();
        assert!(e.to_string().contains("steps[0] (a).id"), "{e}");
        let e = parse(&format!("{STEP}trigger = {{ route = [0, 100] }}\n")).unwrap_err();
        assert!(
            e.to_string().contains("needs the campaign's [route]"),
            "{e}"
        );
        let e = parse(&format!(
            "{STEP}trigger = {{ time = [0, 1], manual = true }}\n"
        ))
        .unwrap_err();
        assert!(e.to_string().contains("exactly one"), "{e}");
        let e = parse(&format!(
            "{}trigger = {{ time = [0, 1] }}\n",
            STEP.replace("severity = 3", "severity = 9")
        ))
        .unwrap_err();
        assert!(e.to_string().contains("steps[0] (a).severity"), "{e}");
        let e = parse("[[steps]]\nstreams = [\"cam\"]\nid = \"C-C7\"\nseverity = 3\ntrigger = { time = [0, 1] }\nspeed = 2\n").unwrap_err();
        assert!(
            matches!(&e, CampaignError::Syntax { key, .. } if key.starts_with("line")),
            "{e}"
        );
    }

    #[test]
    fn overlapping_steps_on_one_stream_are_refused() {
        let two = |a: &str, b: &str| {
            format!(
                "{STEP}trigger = {a}\n[[steps]]\nname = \"b\"\nstreams = [\"cam\", \"lid\"]\nid = \"C-A1\"\nseverity = 1\ntrigger = {b}\n"
            )
        };
        let e = parse(&two("{ time = [0, 10] }", "{ time = [5, 20] }")).unwrap_err();
        assert!(
            matches!(&e, CampaignError::Overlap { stream, a: 0, b: 1, .. } if stream == "cam"),
            "{e}"
        );
        assert!(parse(&two("{ time = [0, 10] }", "{ time = [10, 20] }")).is_ok());
        let e = parse(&two(
            "{ geofence = [[0, 0], [10, 0], [10, 10]] }",
            "{ geofence = [[5, 1], [20, 1], [20, 20]] }",
        ))
        .unwrap_err();
        assert!(e.to_string().contains("polygons overlap"), "{e}");
        let e = parse(&two("{ time = [0, 10] }", "{ manual = true }")).unwrap_err();
        assert!(e.to_string().contains("one kind of trigger"), "{e}");
    }

    #[test]
    fn steps_fire_by_time_geofence_route_and_by_hand() {
        let dir = std::env::temp_dir().join(format!("campaign-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("route.csv"), "x,y\n0,0\n100,0\n100,100\n").unwrap();
        let text = "name = \"t\"\n[route]\ncsv = \"route.csv\"\n\
            [[steps]]\nstreams = [\"cam\"]\nid = \"C-C7\"\nseverity = 3\ntrigger = { route = [50, 150] }\n\
            [[steps]]\nstreams = [\"lid\"]\nid = \"L-A1\"\nseverity = 2\ntrigger = { geofence = [[90, -5], [110, -5], [110, 5], [90, 5]] }\n\
            [[steps]]\nstreams = [\"cam2\"]\nid = \"C-A1\"\nseverity = 1\ntrigger = { manual = true }\n\
            [[steps]]\nstreams = [\"cam2\"]\nid = \"C-A2\"\nseverity = 1\ntrigger = { manual = true }\n";
        let c = Campaign::parse(text, Some(&dir)).unwrap();
        let mut tr = c.tracker();
        let at = |x: f64, y: f64, next: usize, tr: &mut Tracker| {
            c.assignment(
                &Inputs {
                    t: 0.0,
                    pose: Some([x, y]),
                    next,
                },
                tr,
            )
        };
        let a = at(40.0, 1.0, 0, &mut tr);
        assert_eq!((a["cam"], a["lid"], a["cam2"]), (None, None, None));
        let a = at(60.0, -2.0, 1, &mut tr);
        assert_eq!((a["cam"], a["cam2"]), (Some(0), Some(2)));
        let a = at(100.0, 0.0, 2, &mut tr);
        assert_eq!((a["cam"], a["lid"], a["cam2"]), (Some(0), Some(1), Some(3)));
        assert_eq!(tr.arc_length(), Some(100.0));
        let a = at(100.0, 60.0, 3, &mut tr);
        assert_eq!(
            (a["cam"], a["lid"], a["cam2"]),
            (None, None, None),
            "s = 160 m"
        );
        let far = at(300.0, 300.0, 0, &mut tr);
        assert_eq!(far["cam"], None);
        assert_eq!(tr.arc_length(), None, "off the route");
        assert_eq!(c.manual_steps(), 2);
        let e = c
            .check_streams(&[
                ("cam".into(), Modality::Camera),
                ("lid".into(), Modality::Camera),
            ])
            .unwrap_err();
        assert!(e.to_string().contains("`lid`"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("route.csv"), "x,y\n0,0\nten,0\n").unwrap();
        let e = Campaign::parse(text, Some(&dir)).unwrap_err();
        assert!(
            matches!(&e, CampaignError::Route { reason, .. } if reason.contains("line 3")),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
