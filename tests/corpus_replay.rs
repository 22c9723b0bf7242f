//! Replays `tests/corpus/`: inputs that once crashed, hung, read outside their folder or made
//! non-finite pixels. A file named `err-*` must fail with an error that names it; `ok-*` must
//! load, finite and in range (hostile values repaired with warnings).

use std::path::Path;
use valgi::scene::{self, LoadParams};

#[test]
fn corpus_inputs_behave() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut files = Vec::new();
    for dir in std::fs::read_dir(&root).unwrap() {
        for entry in std::fs::read_dir(dir.unwrap().path()).unwrap() {
            let path = entry.unwrap().path();
            let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
            if ["gltf", "glb", "ply", "obj", "xml"].contains(&ext) {
                files.push(path);
            }
        }
    }
    files.sort();
    assert!(files.len() >= 20, "corpus has {} files", files.len());
    let params = LoadParams {
        max_edge: 10.0,
        ..LoadParams::default()
    };
    for path in &files {
        let name = path.file_name().unwrap().to_str().unwrap();
        let shown = path.display().to_string();
        let result = scene::load_with(&shown, &params);
        if name.starts_with("err-") {
            let err = match result {
                Ok(_) => panic!("{name} loaded but must fail"),
                Err(e) => e.to_string(),
            };
            assert!(err.starts_with(&format!("{shown}: ")), "{name}: {err}");
        } else {
            assert!(
                name.starts_with("ok-"),
                "corpus file {name} is neither ok- nor err-"
            );
            let scene = result.unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(
                scene.triangle_count() > 0 || name.contains("missing"),
                "{name}"
            );
            for mesh in &scene.meshes {
                assert!(mesh.positions.iter().all(|p| p.is_finite()), "{name}");
                assert!(mesh.normals.iter().all(|n| n.is_finite()), "{name}");
            }
            for m in &scene.materials {
                assert!(m.base_color.min_element() >= 0.0 && m.base_color.is_finite());
                assert!(m.emissive.min_element() >= 0.0 && m.emissive.is_finite());
            }
            for l in &scene.lights {
                let power = l.radiometric();
                assert!(power.is_finite() && power.min_element() >= 0.0, "{name}");
            }
        }
    }
}

#[test]
fn hostile_corpus_files_say_why() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let params = LoadParams::default();
    let expect = |relative: &str, needle: &str| {
        let path = root.join(relative).display().to_string();
        let err = scene::load_with(&path, &params).unwrap_err().to_string();
        assert!(err.contains(needle), "{relative}: {err}");
    };
    expect("gltf/err-dev-zero-buffer.gltf", "absolute");
    expect("gltf/err-passwd-escape.gltf", "outside the scene's folder");
    expect("gltf/err-huge-count.gltf", "out of range");
    expect("gltf/err-glb-chunk-past-end.glb", "past the end");
    expect("ply/err-vertex-count-4e9.ply", "exceed the limit");
    expect("ply/err-face-list-2pow64m1.ply", "out of range for U32");
    expect("ply/err-binary-list-past-end.ply", "declares 255 items");
    expect(
        "ply/err-vertex-list-then-garbage.ply",
        "vertex 1: list 've4' length",
    );
    expect("obj/err-huge-negative-index.obj", "line 4");
    expect("xml/err-mesh-escape.xml", "outside the scene's folder");
    expect("xml/err-entity-expansion.xml", "malformed XML");
    let scene = scene::load_with(
        &root.join("obj/ok-mtllib-escape.obj").display().to_string(),
        &params,
    )
    .unwrap();
    let warnings = scene.warnings.join("\n");
    assert!(warnings.contains("outside the scene's folder") && warnings.contains("absolute"));
    let scene = scene::load_with(
        &root
            .join("gltf/ok-infinite-factors.gltf")
            .display()
            .to_string(),
        &params,
    )
    .unwrap();
    // The file's punctual light (its emissive surfaces add proxy lights beside it).
    let punctual = scene.lights.iter().filter(|l| !l.kind.is_emission_proxy());
    assert_eq!(punctual.count(), 1, "{:#?}", scene.warnings);
}
