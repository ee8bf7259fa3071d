//! `perturb list`.

use perturb_core::registry::{CATALOGUE, Calibration, Modality};

/// Arguments of `perturb list`.
#[derive(clap::Args)]
pub struct Args {
    /// Print a JSON array (id, name, modality, family, severities, description, reference,
    /// calibration: how far a forwarded camera_info still holds, null when exactly).
    #[arg(long)]
    json: bool,
    /// Only this modality: camera or lidar.
    #[arg(long)]
    modality: Option<Modality>,
}

#[derive(serde::Serialize)]
struct Row {
    id: &'static str,
    name: &'static str,
    modality: Modality,
    family: &'static str,
    severities: Vec<u8>,
    description: &'static str,
    reference: &'static str,
    /// How far the forwarded `camera_info` still describes the output; `None`: exactly.
    calibration: Option<&'static str>,
}

/// Prints the catalogue.
pub fn run(args: Args) -> anyhow::Result<()> {
    let rows: Vec<Row> = CATALOGUE
        .iter()
        .filter(|e| args.modality.is_none_or(|m| m == e.modality))
        .map(|e| Row {
            id: e.id,
            name: e.name,
            modality: e.modality,
            family: e.family,
            severities: e.severities().collect(),
            description: e.description,
            reference: e.reference,
            calibration: match e.calibration() {
                Calibration::Kept => None,
                Calibration::Approximate(note) => Some(note),
            },
        })
        .collect();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "{:<6} {:<24} {:<7} {:<11} {:<5} description",
        "id", "name", "sensor", "family", "sev"
    );
    for r in &rows {
        let sev = format!("1-{}", r.severities.len());
        println!(
            "{:<6} {:<24} {:<7} {:<11} {:<5} {}",
            r.id,
            r.name,
            r.modality.as_str(),
            r.family,
            sev,
            r.description
        );
    }
    let moved: Vec<&Row> = rows.iter().filter(|r| r.calibration.is_some()).collect();
    if !moved.is_empty() {
        println!(
            "\ncamera_info is forwarded unchanged: it describes every output exactly but these:"
        );
        for r in moved {
            println!("  {}: {}", r.id, r.calibration.unwrap_or_default());
        }
    }
    Ok(())
}
