//! PLY bytes (ASCII or binary) → the mesh reader: no panic, and every error names the file.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match valgi::scene::ply::parse(data, "fuzz.ply") {
        Ok(mesh) => assert!(mesh
            .indices
            .iter()
            .all(|&i| (i as usize) < mesh.positions.len())),
        Err(e) => assert!(e.to_string().starts_with("fuzz.ply: "), "{e}"),
    }
});
