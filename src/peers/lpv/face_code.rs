//! The propagation's face tables written out as WGSL (`shaders/lpv/lpv_faces.wgsl`).
//!
//! Every number a propagation face needs (its neighbour's offset, the SH basis at ω_f, the
//! solid angle Ω_f, the normal axis it re-emits along, the geometry volume's corner weights
//! at the midpoint) follows from the neighbour's offset alone, so the shader gets them as
//! literals in straight-line code instead of a table read at a loop index. On a CPU device
//! (Mesa's llvmpipe) a uniform block read at a loop-varying index is one gathered load per
//! float, and the table's reads were most of LPV's propagation; written out, the compiler also
//! drops the per-axis selects, the zero corner weights and the SH terms that vanish.
//!
//! The file is checked in so that it can be read and validated like every other shader; a test
//! (`lpv_faces_wgsl_matches_the_face_tables`) regenerates it from [`math::faces6`] and
//! [`math::faces26`] and fails when it differs (`VALGI_UPDATE_REFERENCES=1` rewrites it).

use std::fmt::Write;

use super::math::{corner_weights, sh9, Face};
use super::Order;

/// Where the generated file lives, from the crate root.
pub const FACES_WGSL_PATH: &str = "shaders/lpv/lpv_faces.wgsl";

/// The text of `shaders/lpv/lpv_faces.wgsl`: one function per order, `lpv_faces` (6
/// neighbours, 30 faces, 4 SH terms) and `holpv_faces` (26 neighbours, 54 faces, 9 terms).
pub fn faces_wgsl() -> String {
    let mut out = String::new();
    out.push_str(
        "// GENERATED from the propagation face tables (`src/peers/lpv/face_code.rs`, from\n\
         // `math::faces6` and `math::faces26`): do not edit. `VALGI_UPDATE_REFERENCES=1 cargo test\n\
         // --lib lpv_faces` writes it anew. One function per order gathers every face of one\n\
         // destination cell, its numbers as literals (see face_code.rs why): per neighbour, the\n\
         // source's coefficients and the geometry volume at the midpoint (only the nonzero\n\
         // corner weights); per face, Φ_f = Ω_f·V_f·max(0, Σ_k c_k·Y_k(ω_f)) added to the sum\n\
         // of its normal axis (`face_flux`, `lpv_propagate_cell.wgsl`).\n\
         #include \"lpv_propagate_cell.wgsl\"\n",
    );
    for order in [Order::Lpv, Order::HoLpv] {
        out.push('\n');
        write_order(&mut out, order);
    }
    out
}

fn write_order(out: &mut String, order: Order) {
    let faces = order.faces();
    let sh = order.sh_count();
    let name = match order {
        Order::Lpv => "lpv_faces",
        Order::HoLpv => "holpv_faces",
    };
    let _ = writeln!(
        out,
        "// {} neighbours, {} faces, {sh} SH terms.",
        neighbour_offsets(&faces).len(),
        faces.len()
    );
    let _ = writeln!(out, "fn {name}(c: ptr<function, Cell>, occlusion: bool) {{");
    out.push_str("    var source: array<vec3<f32>, 9>;\n");
    out.push_str("    var blocker = vec4<f32>(0.0);\n");
    for offset in neighbour_offsets(&faces) {
        let [x, y, z] = offset.to_array();
        let _ = writeln!(
            out,
            "    source = read_source((*c).d - vec3<i32>({x}, {y}, {z}));"
        );
        let _ = writeln!(
            out,
            "    if (occlusion) {{\n        blocker = {};\n    }}",
            blocker_expression(offset)
        );
        for face in faces.iter().filter(|f| f.offset == offset) {
            write_face(out, face, sh);
        }
    }
    out.push_str("}\n");
}

/// The neighbours in the order the shader visits them (sorted by offset).
fn neighbour_offsets(faces: &[Face]) -> Vec<glam::IVec3> {
    let mut offsets: Vec<glam::IVec3> = faces.iter().map(|f| f.offset).collect();
    offsets.sort_by_key(|o| o.to_array());
    offsets.dedup();
    offsets
}

/// The geometry volume at the midpoint between the destination and the source `offset` away:
/// the mean of the corners whose trilinear weight is not zero (`math::blocker`; the nonzero
/// weights of one offset are equal, 1, ½ or ¼, so the mean is the weighted sum to the bit).
fn blocker_expression(offset: glam::IVec3) -> String {
    let weights = corner_weights(offset);
    let corners: Vec<String> = weights
        .iter()
        .enumerate()
        .filter(|(_, w)| **w != 0.0)
        .map(|(i, _)| format!("(*c).corners[{i}]"))
        .collect();
    let weight = weights.iter().copied().find(|w| *w != 0.0).unwrap_or(0.0);
    debug_assert!(weights.iter().all(|w| *w == 0.0 || *w == weight));
    if corners.len() == 1 {
        corners[0].clone()
    } else {
        format!("({}) * {}", corners.join(" + "), literal(weight))
    }
}

fn write_face(out: &mut String, face: &Face, sh: usize) {
    let y = sh9(face.direction);
    let terms: Vec<String> = (0..sh)
        .filter(|&k| y[k] != 0.0)
        .map(|k| format!("source[{k}] * {}", literal(y[k])))
        .collect();
    let intensity = if terms.is_empty() {
        "vec3<f32>(0.0)".to_string()
    } else {
        terms.join("\n        + ")
    };
    // The blocker is read toward the source, along −ω_f: Y at −ω flips the odd band.
    let back = format!(
        "vec4<f32>({}, {}, {}, {})",
        literal(y[0]),
        literal(-y[1]),
        literal(-y[2]),
        literal(-y[3])
    );
    let _ = writeln!(
        out,
        "    (*c).f{} += face_flux(\n        {intensity},\n        blocker, {back}, {}, occlusion);",
        face.axis,
        literal(face.solid_angle)
    );
}

/// A WGSL float literal that reads back as the same f32 (Rust's shortest round-trip form;
/// −0 as 0, which no sum or product here tells apart).
fn literal(v: f32) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    let text = format!("{v:?}");
    if text.contains(['.', 'e', 'E']) {
        text
    } else {
        format!("{text}.0")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::peers::lpv::math;

    /// The checked-in shader is what the face tables say; `VALGI_UPDATE_REFERENCES=1`
    /// rewrites it after a change to them.
    #[test]
    fn lpv_faces_wgsl_matches_the_face_tables() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(FACES_WGSL_PATH);
        let generated = faces_wgsl();
        if std::env::var("VALGI_UPDATE_REFERENCES").is_ok_and(|v| v == "1") {
            std::fs::write(&path, &generated).expect("write lpv_faces.wgsl");
        }
        let checked_in = std::fs::read_to_string(&path).expect("read lpv_faces.wgsl");
        assert!(
            checked_in == generated,
            "{} is not what the face tables generate; run with VALGI_UPDATE_REFERENCES=1",
            path.display()
        );
    }

    #[test]
    fn every_face_is_written_once_with_its_own_literals() {
        let text = faces_wgsl();
        let lpv = text.split("fn holpv_faces").next().unwrap();
        assert_eq!(lpv.matches("face_flux(").count(), math::faces6().len());
        assert_eq!(text.matches("face_flux(").count(), 30 + 54);
        assert_eq!(lpv.matches("read_source(").count(), 6);
        assert_eq!(text.matches("read_source(").count(), 6 + 26);
        // A corner neighbour's midpoint is one GV corner, a face neighbour's the mean of four.
        assert!(text.contains("blocker = (*c).corners[7];"));
        for face in math::faces26() {
            assert!(text.contains(&literal(face.solid_angle)));
        }
    }

    #[test]
    fn literals_read_back_as_the_same_f32() {
        for v in [0.25f32, 1.0, -0.488_602_5, 1e-8, 0.282_094_8, 3.0] {
            let text = literal(v);
            assert!(text.contains(['.', 'e']), "{text}");
            assert_eq!(text.parse::<f32>().unwrap(), v);
        }
    }
}
