//! Any text: `parse_trc` returns a trial or an error naming the file, never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    match smocap::io::trc::parse_trc(&text, "fuzz.trc") {
        Ok(t) => assert!(t.check_consistent().is_ok()),
        Err(e) => assert!(e.to_string().starts_with("fuzz.trc")),
    }
});
