//! glTF / GLB bytes → the importer: no panic, and every error names the file.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(e) = valgi::scene::gltf_import::load_from_slice(data, None, "fuzz.gltf") {
        assert!(e.to_string().starts_with("fuzz.gltf: "), "{e}");
    }
});
