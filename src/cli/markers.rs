//! `smocap markers FILE`: what a marker file holds.

use crate::io::read_markers;
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct MarkersArgs {
    /// Marker file (TRC or C3D).
    pub file: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Summary of one marker.
#[derive(Serialize)]
struct MarkerSummary {
    label: String,
    /// Frames where the marker is missing.
    gaps: usize,
    /// Longest run of missing frames.
    longest_gap: usize,
}

/// Summary of a marker file.
#[derive(Serialize)]
struct Summary {
    file: String,
    frames: usize,
    rate_hz: f64,
    units: String,
    start_s: f64,
    end_s: f64,
    markers: Vec<MarkerSummary>,
    warnings: Vec<String>,
}

pub fn run(a: MarkersArgs) -> anyhow::Result<u8> {
    let t = read_markers(&a.file)?;
    let markers = (0..t.n_markers())
        .map(|m| {
            let (mut gaps, mut run, mut longest) = (0, 0, 0);
            for f in 0..t.n_frames() {
                if t.position(f, m).is_none() {
                    gaps += 1;
                    run += 1;
                    longest = longest.max(run);
                } else {
                    run = 0;
                }
            }
            MarkerSummary { label: t.labels[m].clone(), gaps, longest_gap: longest }
        })
        .collect();
    let s = Summary {
        file: a.file.display().to_string(),
        frames: t.n_frames(),
        rate_hz: t.rate_hz,
        units: t.source_units.clone(),
        start_s: t.times.first().copied().unwrap_or(0.0),
        end_s: t.times.last().copied().unwrap_or(0.0),
        markers,
        warnings: t.warnings.clone(),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        return Ok(0);
    }
    println!(
        "{}: {} frames at {} Hz ({} to {} s), {} markers, units {}",
        s.file,
        s.frames,
        s.rate_hz,
        s.start_s,
        s.end_s,
        s.markers.len(),
        s.units
    );
    println!("{:<24} {:>8} {:>12}", "marker", "gaps", "longest gap");
    for m in &s.markers {
        println!("{:<24} {:>8} {:>12}", m.label, m.gaps, m.longest_gap);
    }
    for w in &s.warnings {
        println!("warning: {w}");
    }
    Ok(0)
}
