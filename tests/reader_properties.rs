//! Property tests over the scene readers: mutated bytes of small real inputs (byte flips,
//! insertions, deletions, truncations, repeated chunks) never panic, and every failure is an
//! error that names the file. Whatever loads is finite and in range. Case counts are bounded
//! so the suite runs in seconds; `fuzz/` holds the open-ended version of the same targets.

use proptest::prelude::*;
use std::path::{Path, PathBuf};
use valgi::scene::files::ReadPolicy;
use valgi::scene::{gltf_import, mitsuba, obj, ply, Scene, SceneError};

fn shared(relative: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(relative);
    path.exists().then_some(path)
}

/// Small inputs for each reader: real files when the shared data is present, plus inputs
/// written here so the properties hold without it.
fn seeds(kind: &str) -> Vec<(Vec<u8>, Option<PathBuf>)> {
    let mut out: Vec<(Vec<u8>, Option<PathBuf>)> = Vec::new();
    let real: &[&str] = match kind {
        "gltf" => &[
            "gltf-samples/EmissiveStrengthTest/glTF-Binary/EmissiveStrengthTest.glb",
            "gltf-samples/EnvironmentTest/glTF/EnvironmentTest.gltf",
        ],
        "ply" => &["bunny/bun_zipper_res4.ply"],
        "obj" => &[
            "veach-ajar/models/Mesh008.obj",
            "veach-ajar/models/Mesh005.obj",
        ],
        _ => &["veach-ajar/scene.xml"],
    };
    for relative in real {
        if let Some(path) = shared(relative) {
            let bytes = std::fs::read(&path).unwrap();
            out.push((bytes, path.parent().map(Path::to_path_buf)));
        }
    }
    let written: &[u8] = match kind {
        "gltf" => include_bytes!("corpus/gltf/ok-triangle.gltf"),
        "ply" => include_bytes!("corpus/ply/ok-quad-binary.ply"),
        "obj" => include_bytes!("corpus/obj/ok-quad.obj"),
        _ => include_bytes!("corpus/xml/ok-room.xml"),
    };
    out.push((written.to_vec(), None));
    out
}

#[derive(Clone, Debug)]
enum Edit {
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Truncate(usize),
    Repeat(usize, usize),
    /// Replaces a run of ASCII digits with a hostile number.
    Number(usize, &'static str),
}

fn edit() -> impl Strategy<Value = Edit> {
    let hostile = prop::sample::select(vec![
        "0",
        "-1",
        "4294967295",
        "4294967296",
        "18446744073709551615",
        "4611686018427387904",
        "1e39",
        "-1e39",
        "nan",
        "999999999999",
    ]);
    prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(at, b)| Edit::Flip(at, b)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(at, b)| Edit::Insert(at, b)),
        (any::<usize>(), 1usize..64).prop_map(|(at, n)| Edit::Delete(at, n)),
        any::<usize>().prop_map(Edit::Truncate),
        (any::<usize>(), 1usize..256).prop_map(|(at, n)| Edit::Repeat(at, n)),
        (any::<usize>(), hostile).prop_map(|(at, n)| Edit::Number(at, n)),
    ]
}

fn apply(bytes: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for e in edits {
        if out.is_empty() {
            break;
        }
        let len = out.len();
        match e {
            Edit::Flip(at, b) => out[at % len] ^= b | 1,
            Edit::Insert(at, b) => {
                let at = at % (len + 1);
                out.splice(at..at, b.iter().copied());
            }
            Edit::Delete(at, n) => {
                let at = at % len;
                out.drain(at..(at + n).min(len));
            }
            Edit::Truncate(at) => out.truncate(at % len),
            Edit::Repeat(at, n) => {
                let at = at % len;
                let chunk = out[at..(at + n).min(len)].to_vec();
                out.splice(at..at, chunk);
            }
            Edit::Number(at, n) => {
                let Some(start) = (0..len)
                    .map(|k| (at + k) % len)
                    .find(|&k| out[k].is_ascii_digit())
                else {
                    continue;
                };
                let end = (start..len)
                    .find(|&k| !out[k].is_ascii_digit())
                    .unwrap_or(len);
                out.splice(start..end, n.bytes());
            }
        }
    }
    out
}

/// The properties every reader's outcome must have.
fn check(result: Result<Scene, SceneError>, display: &str) -> Result<(), TestCaseError> {
    match result {
        Err(e) => {
            let message = e.to_string();
            prop_assert!(
                message.starts_with(&format!("{display}: ")),
                "error does not name the file: {message}"
            );
        }
        Ok(scene) => {
            for mesh in &scene.meshes {
                prop_assert!(mesh.positions.iter().all(|p| p.is_finite()));
                prop_assert_eq!(mesh.normals.len(), mesh.positions.len());
                prop_assert!(mesh.normals.iter().all(|n| n.is_finite()));
                prop_assert!(mesh.uv0.iter().all(|uv| uv.is_finite()));
                prop_assert!(mesh
                    .indices
                    .iter()
                    .all(|&i| (i as usize) < mesh.positions.len()));
            }
            for m in &scene.materials {
                prop_assert!(m.base_color.is_finite() && m.base_color.min_element() >= 0.0);
                prop_assert!(m.emissive.is_finite() && m.emissive.min_element() >= 0.0);
            }
            for l in &scene.lights {
                let power = l.radiometric();
                prop_assert!(power.is_finite() && power.min_element() >= 0.0);
            }
        }
    }
    Ok(())
}

fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config(512))]

    #[test]
    fn mutated_gltf_never_panics(seed in any::<prop::sample::Index>(),
                                 edits in prop::collection::vec(edit(), 1..6)) {
        let seeds = seeds("gltf");
        let (bytes, dir) = &seeds[seed.index(seeds.len())];
        let mutated = apply(bytes, &edits);
        let display = "mutated.gltf";
        check(gltf_import::load_from_slice(&mutated, dir.as_deref(), display), display)?;
    }

    #[test]
    fn mutated_ply_never_panics(seed in any::<prop::sample::Index>(),
                                edits in prop::collection::vec(edit(), 1..6)) {
        let seeds = seeds("ply");
        let (bytes, _) = &seeds[seed.index(seeds.len())];
        let mutated = apply(bytes, &edits);
        let display = "mutated.ply";
        let result = ply::parse(&mutated, display).map(|mesh| Scene {
            meshes: vec![mesh],
            ..Scene::default()
        });
        check(result, display)?;
    }

    #[test]
    fn mutated_obj_never_panics(seed in any::<prop::sample::Index>(),
                                edits in prop::collection::vec(edit(), 1..6)) {
        let seeds = seeds("obj");
        let (bytes, dir) = &seeds[seed.index(seeds.len())];
        let mutated = apply(bytes, &edits);
        let display = "mutated.obj";
        check(obj::parse(&mutated, display, dir.as_deref(), ReadPolicy::default()), display)?;
    }

    #[test]
    fn mutated_mitsuba_never_panics(seed in any::<prop::sample::Index>(),
                                    edits in prop::collection::vec(edit(), 1..6)) {
        let seeds = seeds("xml");
        let (bytes, dir) = &seeds[seed.index(seeds.len())];
        let mutated = apply(bytes, &edits);
        let display = "mutated.xml";
        check(mitsuba::parse(&mutated, display, dir.as_deref(), ReadPolicy::default()), display)?;
    }
}
