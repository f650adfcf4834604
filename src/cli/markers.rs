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
    /// Frames where the marker is missing, as a count and a fraction of the frames.
    gaps: usize,
    missing_fraction: f64,
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
    /// Missing (frame, marker) samples over all markers.
    missing_samples: usize,
    markers: Vec<MarkerSummary>,
    warnings: Vec<String>,
}

pub fn run(a: MarkersArgs) -> anyhow::Result<u8> {
    let t = read_markers(&a.file)?;
    let markers: Vec<MarkerSummary> = (0..t.n_markers())
        .map(|m| {
            let (gaps, longest_gap) = t.gaps_and_longest(m);
            let missing_fraction = gaps as f64 / t.n_frames().max(1) as f64;
            MarkerSummary { label: t.labels[m].clone(), gaps, missing_fraction, longest_gap }
        })
        .collect();
    let s = Summary {
        file: a.file.display().to_string(),
        frames: t.n_frames(),
        rate_hz: t.rate_hz,
        units: t.source_units.clone(),
        start_s: t.times.first().copied().unwrap_or(0.0),
        end_s: t.times.last().copied().unwrap_or(0.0),
        missing_samples: markers.iter().map(|m| m.gaps).sum(),
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
    println!("{} missing samples", s.missing_samples);
    println!("{:<24} {:>8} {:>9} {:>12}", "marker", "gaps", "missing", "longest gap");
    for m in &s.markers {
        println!("{:<24} {:>8} {:>8.1}% {:>12}", m.label, m.gaps, 100.0 * m.missing_fraction, m.longest_gap);
    }
    for w in &s.warnings {
        println!("warning: {w}");
    }
    Ok(0)
}
