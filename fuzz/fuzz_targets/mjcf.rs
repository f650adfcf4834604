//! Any text as an MJCF model: `parse_mjcf` returns a model or an error, never panics or
//! allocates without bound (run with `-rss_limit_mb=1024`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(m) = smocap::io::mjcf::parse_mjcf(text, "fuzz.xml") {
            assert!(m.nb() <= smocap::model::MAX_BODIES);
        }
    }
});
