//! `smocap inspect`: what a converted MCAP file holds.

use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct InspectArgs {
    /// An MCAP file written by `smocap convert`.
    pub file: PathBuf,
    /// Print as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: InspectArgs) -> anyhow::Result<u8> {
    let info = crate::archive::inspect::inspect(&a.file)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(0);
    }
    println!("{}: {} messages", a.file.display(), info.messages);
    println!("{:<20} {:<26} {:<8} {:>8}", "topic", "schema", "encoding", "messages");
    for c in &info.channels {
        println!("{:<20} {:<26} {:<8} {:>8}", c.topic, c.schema, c.encoding, c.messages);
    }
    for (name, m) in &info.metadata {
        println!("metadata {name}:");
        for (k, v) in m {
            println!("  {k}: {v}");
        }
    }
    for (name, size) in &info.attachments {
        println!("attachment {name} ({size} bytes)");
    }
    Ok(0)
}
