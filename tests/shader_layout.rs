//! Every WGSL file parses and validates with naga, and every `#[repr(C)]` struct shared with
//! WGSL has the size and field offsets naga computes for it. No GPU needed.

use valgi::method::shared_layouts;
use valgi::shaders;

#[test]
fn every_wgsl_file_validates() {
    let mut failures = Vec::new();
    for (name, _) in shaders::FILES {
        if let Err(e) = shaders::validate(name) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn every_shader_in_the_folder_is_listed() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut found = 0;
    // One folder per part that owns shaders (shaders/<part>/<name>.wgsl).
    for folder in std::fs::read_dir(&root).expect("shaders folder") {
        let folder = folder.expect("entry").path();
        let files: Vec<std::path::PathBuf> = if folder.is_dir() {
            std::fs::read_dir(&folder)
                .expect("shader part folder")
                .map(|e| e.expect("entry").path())
                .collect()
        } else {
            vec![folder]
        };
        for file in files {
            let name = file.file_name().unwrap().to_string_lossy().to_string();
            if name.ends_with(".wgsl") {
                found += 1;
                assert!(
                    shaders::FILES.iter().any(|(n, _)| *n == name),
                    "{} is not in shaders::FILES, so it is neither embedded nor validated",
                    file.display()
                );
            }
        }
    }
    assert_eq!(
        found,
        shaders::FILES.len(),
        "shader files on disk and in shaders::FILES"
    );
}

#[test]
fn rust_structs_match_naga_layout() {
    for layout in shared_layouts() {
        let (wgsl_name, file, rust_size, rust_fields) =
            (layout.wgsl_name, layout.file, layout.size, layout.fields);
        let module = shaders::validate(file).unwrap_or_else(|e| panic!("{e}"));
        let ty = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(wgsl_name))
            .unwrap_or_else(|| panic!("struct {wgsl_name} not found in {file}"))
            .1;
        let naga::TypeInner::Struct { members, span } = &ty.inner else {
            panic!("{wgsl_name} is not a struct");
        };
        assert_eq!(
            *span as usize, rust_size,
            "{wgsl_name}: WGSL size {span} vs Rust {rust_size}"
        );
        assert_eq!(
            members.len(),
            rust_fields.len(),
            "{wgsl_name}: member count differs"
        );
        for (member, (rust_name, rust_offset)) in members.iter().zip(&rust_fields) {
            assert_eq!(
                member.name.as_deref(),
                Some(*rust_name),
                "{wgsl_name}: field order differs"
            );
            assert_eq!(
                member.offset as usize, *rust_offset,
                "{wgsl_name}.{rust_name}: WGSL offset {} vs Rust {rust_offset}",
                member.offset
            );
        }
    }
}

/// The dispatch sizes the Rust side computes match the workgroup sizes the WGSL declares.
#[test]
fn workgroup_sizes_match_the_dispatches() {
    let tile = valgi::frame::PIXEL_TILE;
    let group = valgi::vals::sparse::POINT_GROUP;
    let reduce = valgi::mixed_reality::depth_vals::REDUCE_GROUP;
    let append = valgi::light::rsm::APPEND_GROUP;
    let expected: &[(&str, &str, [u32; 3])] = &[
        ("direct_light.wgsl", "cs_main", [tile, tile, 1]),
        ("resolve.wgsl", "cs_main", [tile, tile, 1]),
        ("brute_vals.wgsl", "cs_main", [tile, tile, 1]),
        ("lpv_lookup.wgsl", "cs_main", [tile, tile, 1]),
        ("lpv_geometry.wgsl", "cs_camera", [tile, tile, 1]),
        ("atlas_apply.wgsl", "cs_main", [tile, tile, 1]),
        ("atlas_apply.wgsl", "cs_add", [tile, tile, 1]),
        ("vals_gather.wgsl", "cs_main", [group, 1, 1]),
        (
            "vals_gather.wgsl",
            "cs_window",
            [valgi::vals::sparse::WINDOW_POINT_GROUP, 1, 1],
        ),
        ("brute_vals.wgsl", "cs_window", [tile, tile, 1]),
        ("vals_gather_reduce.wgsl", "cs_main", [group, 1, 1]),
        ("vals_renormalize.wgsl", "cs_main", [group, 1, 1]),
        ("vals_occlusion.wgsl", "cs_main", [group, 1, 1]),
        ("vals_occluder_bounds.wgsl", "cs_main", [group, 1, 1]),
        ("vals_occluder_bounds.wgsl", "cs_tiles", [group, 1, 1]),
        ("vals_occluder_bounds.wgsl", "cs_nodes", [group, 1, 1]),
        ("vals_interpolate.wgsl", "cs_main", [group, 1, 1]),
        ("depth_vals.wgsl", "bilateral", [tile, tile, 1]),
        ("depth_vals.wgsl", "surfel", [tile, tile, 1]),
        ("depth_vals.wgsl", "reduce", [reduce, 1, 1]),
        (
            "depth_vals.wgsl",
            "cut",
            [valgi::mixed_reality::depth_vals::CUT_GROUP, 1, 1],
        ),
        (
            "depth_vals.wgsl",
            "samples_of_surfels",
            [valgi::mixed_reality::depth_vals::SAMPLES_GROUP, 1, 1],
        ),
        ("vals_append.wgsl", "count_rows", [append, 1, 1]),
        ("vals_append.wgsl", "append_rows", [append, 1, 1]),
    ];
    let mut expected = expected.to_vec();
    for entry in valgi::negative::VIEW_ENTRIES {
        let size = if valgi::negative::TILE_COLUMN_ENTRIES.contains(entry) {
            [tile, tile / valgi::negative::COLUMN, 1]
        } else {
            [tile, tile, 1]
        };
        expected.push(("negative_view.wgsl", entry, size));
    }
    let select = valgi::negative::SELECT_GROUP;
    expected.push(("negative_view.wgsl", "select_negatives", [select, 1, 1]));
    let positive = valgi::negative::POSITIVE_GROUP;
    expected.push(("negative_positives.wgsl", "cs_main", [positive, 1, 1]));
    let rows = valgi::light::rsm::ROW_GROUP;
    let scan = valgi::light::rsm::SCAN_GROUP;
    let texels = valgi::peers::lpv::TEXEL_GROUP;
    let block = valgi::peers::lpv::PROPAGATE_BLOCK;
    expected.extend([
        ("vals_from_rsm.wgsl", "count_rows", [rows, 1, 1]),
        ("vals_from_rsm.wgsl", "scan_rows", [scan, 1, 1]),
        ("vals_from_rsm.wgsl", "write_rows", [rows, 1, 1]),
        ("vals_visibility.wgsl", "cs_main", [group, 1, 1]),
        ("lpv_inject.wgsl", "cs_main", [texels, 1, 1]),
        ("lpv_geometry.wgsl", "cs_rsm", [texels, 1, 1]),
        ("lpv_propagate.wgsl", "cs_main", [block, block, block]),
        ("lpv_pack.wgsl", "cs_main", [block, block, block]),
        ("bench_fma.wgsl", "cs_main", [valgi::bench::FMA_GROUP, 1, 1]),
    ]);
    for (file, entry, size) in &expected {
        let module = shaders::validate(file).unwrap_or_else(|e| panic!("{file}: {e}"));
        let point = module
            .entry_points
            .iter()
            .find(|p| p.name == *entry)
            .unwrap_or_else(|| panic!("{file} has no entry point {entry}"));
        assert_eq!(point.workgroup_size, *size, "{file}::{entry}");
    }
    // Every compute entry point of every shader is listed: a new kernel declares the constant
    // its dispatch divides by, instead of a literal the two sides could disagree on.
    for (file, _) in shaders::FILES {
        let module = shaders::validate(file).unwrap_or_else(|e| panic!("{file}: {e}"));
        for point in &module.entry_points {
            if point.stage != naga::ShaderStage::Compute {
                continue;
            }
            assert!(
                expected
                    .iter()
                    .any(|(f, e, _)| f == file && *e == point.name),
                "{file}::{} is a compute kernel whose workgroup size no dispatch constant \
                 is checked against; add it to this list",
                point.name
            );
        }
    }
}

/// Constants the Rust side and the WGSL side each hold (CPU twins and dispatch code rely on
/// them) have the same values.
#[test]
fn shared_constants_match() {
    use valgi::light::rsm::{CLUSTER_SAMPLE_SIDE, MAX_CLUSTERS, SAMPLE_CANDIDATES};
    use valgi::raster::types as base;
    let occlusion = [
        ("TILE_MAX", valgi::vals::sparse::OCCLUSION_TILE_MAX),
        ("FANOUT", valgi::vals::math::OCCLUSION_FANOUT as u32),
        ("BOUNDS_VEC4S", valgi::vals::sparse::OCCLUDER_BOUNDS_VEC4S),
    ];
    let clusters = [
        ("MAX_CLUSTERS", MAX_CLUSTERS),
        ("CLUSTER_SAMPLE_SIDE", CLUSTER_SAMPLE_SIDE),
        ("SAMPLE_CANDIDATES", SAMPLE_CANDIDATES),
    ];
    let per_file: &[(&str, &[(&str, u32)])] = &[
        ("vals_from_rsm.wgsl", &clusters),
        (
            "vals_visibility.wgsl",
            &[
                clusters[0],
                clusters[1],
                clusters[2],
                ("MAX_RAY_TILES", valgi::vals::visibility::MAX_RAY_TILES),
                (
                    "BVH_ROW_SHIFT",
                    valgi::light::bvh::BVH_ROW_TEXELS.trailing_zeros(),
                ),
            ],
        ),
        (
            "sensor_occluder.wgsl",
            &[
                clusters[1],
                clusters[2],
                ("SENSOR_MAX_STEPS", valgi::light::sensor::SENSOR_MAX_STEPS),
            ],
        ),
        (
            "vals_gather.wgsl",
            &[(
                "POINT_SLOTS",
                valgi::vals::sparse::GATHER_POINTS_PER_INVOCATION_MAX,
            )],
        ),
        (
            "val_windows.wgsl",
            &[("WINDOW_VALS", valgi::light::rsm::VAL_WINDOW as u32)],
        ),
        (
            "vals_gather_raster.wgsl",
            &[("RASTER_WIDTH", valgi::vals::sparse::RASTER_GATHER_WIDTH)],
        ),
        (
            "vals_append.wgsl",
            &[("GROUP", valgi::light::rsm::APPEND_GROUP)],
        ),
        ("vals_occlusion.wgsl", &occlusion),
        ("vals_occluder_bounds.wgsl", &occlusion),
        (
            "vals_rsm.wgsl",
            &[(
                "EXACT_SOLID_ANGLE_SIDE",
                valgi::light::rsm::EXACT_SOLID_ANGLE_SIDE,
            )],
        ),
        (
            "direct_light.wgsl",
            &[
                ("NO_SHADOW", base::NO_SHADOW),
                ("LIGHT_POINT", base::LIGHT_POINT),
                ("LIGHT_SPOT", base::LIGHT_SPOT),
                ("LIGHT_DIRECTIONAL", base::LIGHT_DIRECTIONAL),
                ("LIGHT_EMITTER", base::LIGHT_EMITTER),
                ("LIGHT_BLOCK", valgi::raster::LIGHT_BLOCK),
                ("VIEW_BLOCK", valgi::raster::VIEW_BLOCK),
            ],
        ),
        (
            "negative_view.wgsl",
            &[
                ("LIGHT_BLOCK", valgi::negative::LIGHT_BLOCK),
                ("COLUMN", valgi::negative::COLUMN),
            ],
        ),
        (
            "brute_vals.wgsl",
            &[("COLUMN", valgi::peers::brute::WINDOW_COLUMN)],
        ),
    ];
    let expected = per_file
        .iter()
        .flat_map(|(file, constants)| constants.iter().map(move |(name, v)| (*file, *name, *v)));
    for (file, name, value) in expected {
        let module = shaders::validate(file).unwrap_or_else(|e| panic!("{file}: {e}"));
        let constant = module
            .constants
            .iter()
            .find(|(_, c)| c.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("{file} declares no {name}"))
            .1;
        let found = match module.global_expressions[constant.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => v,
            ref other => panic!("{file}: {name} is {other:?}, not a u32 literal"),
        };
        assert_eq!(found, value, "{file}: {name}");
    }
}
