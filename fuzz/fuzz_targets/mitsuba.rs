//! Mitsuba XML bytes → the scene reader (no referenced files): no panic, and every error names
//! the file.
#![no_main]
use libfuzzer_sys::fuzz_target;
use valgi::scene::files::ReadPolicy;

fuzz_target!(|data: &[u8]| {
    if let Err(e) = valgi::scene::mitsuba::parse(data, "fuzz.xml", None, ReadPolicy::default()) {
        assert!(e.to_string().starts_with("fuzz.xml: "), "{e}");
    }
});
