//! Any bytes: `parse_c3d` returns a trial or an error naming the file, never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match smocap::io::c3d::parse_c3d(data, "fuzz.c3d") {
        Ok(t) => assert!(t.check_consistent().is_ok()),
        Err(e) => assert!(e.to_string().starts_with("fuzz.c3d")),
    }
});
