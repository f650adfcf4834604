//! Any bytes as a converted trial: the MCAP reading path of `inspect`, `export` and `--resume`'s
//! check returns a result or an error naming the file, never panics or allocates what corrupt
//! lengths claim (run with `-rss_limit_mb=1024`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(e) = smocap::archive::inspect::inspect_bytes(data, "fuzz.mcap") {
        assert!(e.to_string().starts_with("fuzz.mcap"));
    }
    if let Err(e) = smocap::archive::inspect::verify_bytes(data, "fuzz.mcap") {
        assert!(e.to_string().starts_with("fuzz.mcap"));
    }
    let _ = smocap::archive::export::parse_trial_record(data, "fuzz.mcap");
});
