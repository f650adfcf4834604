//! Any text as an OpenSim model: `parse_osim` returns a model or an error, never panics or
//! allocates without bound (run with `-rss_limit_mb=1024`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok((m, _)) = smocap::io::osim::parse_osim(text, "fuzz.osim") {
            assert!(m.nb() <= smocap::model::MAX_BODIES);
        }
    }
});
