//! OBJ bytes → the OBJ reader (no material libraries): no panic, and every error names the file.
#![no_main]
use libfuzzer_sys::fuzz_target;
use valgi::scene::files::ReadPolicy;

fuzz_target!(|data: &[u8]| {
    if let Err(e) = valgi::scene::obj::parse(data, "fuzz.obj", None, ReadPolicy::default()) {
        assert!(e.to_string().starts_with("fuzz.obj: "), "{e}");
    }
});
