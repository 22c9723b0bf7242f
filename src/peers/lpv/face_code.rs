//! The propagation's face tables written out as WGSL (`shaders/lpv/lpv_faces.wgsl`).
//!
//! Every number a propagation face needs (its neighbour's offset, the SH basis at ω_f, the
//! solid angle Ω_f, the normal axis it re-emits along, the geometry volume's corner weights
//! at the midpoint) follows from the neighbour's offset alone, so the shader gets them as
//! literals in straight-line code instead of a table read at a loop index. On a CPU device
//! (Mesa's llvmpipe) a uniform block read at a loop-varying index is one gathered load per
//! float, and the table's reads were most of LPV's propagation; written out, the compiler also
//! drops the per-axis selects, the zero corner weights and the SH terms that vanish. The end
//! of a cell's step, the six per-axis fluxes re-emitted as clamped-cosine lobes and stored, is
//! written out the same way (`write_end`), and a step volume keeps only the coefficients a
//! step writes ([`step_layout`]), which HO-LPV's later steps read (`{order}_step_faces`).
//!
//! The file is checked in so that it can be read and validated like every other shader; a test
//! (`lpv_faces_wgsl_matches_the_face_tables`) regenerates it from [`super::math::faces6`] and
//! [`super::math::faces26`] and fails when it differs (`VALGI_UPDATE_REFERENCES=1` rewrites it).

use std::fmt::Write;

use super::math::{axis_vector, corner_weights, sh9, Face, BAND, CLAMPED_COSINE};
use super::Order;

/// Where the generated file lives, from the crate root.
pub const FACES_WGSL_PATH: &str = "shaders/lpv/lpv_faces.wgsl";

/// The text of `shaders/lpv/lpv_faces.wgsl`: per order the faces, `lpv_faces` (6 neighbours,
/// 30 faces, 4 SH terms) and `holpv_faces` (26 neighbours, 54 faces, 9 terms), and the end of
/// a cell's step, `lpv_end` and `holpv_end`.
pub fn faces_wgsl() -> String {
    let mut out = String::new();
    out.push_str(
        "// GENERATED from the propagation face tables (`src/peers/lpv/face_code.rs`, from\n\
         // `math::faces6` and `math::faces26`): do not edit. `VALGI_UPDATE_REFERENCES=1 cargo test\n\
         // --lib lpv_faces` writes it anew. One function per order gathers every face of one\n\
         // destination cell, its numbers as literals (see face_code.rs why): per neighbour, the\n\
         // source's coefficients and the geometry volume at the midpoint (only the nonzero\n\
         // corner weights); per face, Φ_f = Ω_f·V_f·max(0, Σ_k c_k·Y_k(ω_f)) added to the sum\n\
         // of its normal axis (`face_flux`, `lpv_propagate_cell.wgsl`). One more per order ends\n\
         // the cell's step: the six axes' fluxes re-emitted as clamped-cosine lobes, stored.\n\
         #include \"lpv_propagate_cell.wgsl\"\n",
    );
    for order in [Order::Lpv, Order::HoLpv] {
        out.push('\n');
        write_order(&mut out, order, SourceForm::Full);
        if steps_read_fewer_coefficients(order) {
            out.push('\n');
            write_step_source(&mut out, order);
            out.push('\n');
            write_order(&mut out, order, SourceForm::Step);
        }
    }
    for order in [Order::Lpv, Order::HoLpv] {
        out.push('\n');
        write_end(&mut out, order);
    }
    out
}

/// Coefficient k of the lobe re-emitted along `axis` per unit flux, Â_l·Y_lm(n_a)/π
/// (`math::clamped_cosine` over π), rounded once from f64.
fn lobe_coefficient(axis: usize, k: usize) -> f32 {
    let y = f64::from(sh9(axis_vector(axis))[k]);
    (f64::from(CLAMPED_COSINE[BAND[k]]) * y / std::f64::consts::PI) as f32
}

/// The end of a cell's step: the six per-axis fluxes re-emitted into it as clamped-cosine
/// lobes about their axes, Φ_a/π·Â_l·Y_lm(n_a) per coefficient (`math::propagate`'s
/// reprojection), written to the step's texels and added to the accumulation. The axes'
/// coefficients are literals, and most are zero: an axis has one band-1 term and two band-2
/// terms, so HO-LPV's Y2−2, Y2−1 and Y21 stay zero and are not added to the accumulation.
/// Written as loops over the axes and coefficients, the private arrays they indexed were a
/// fifth of HO-LPV's propagation on llvmpipe.
fn write_end(out: &mut String, order: Order) {
    let sh = order.sh_count();
    let _ = writeln!(out, "fn {}_end(c: Cell) {{", order.name());
    let written = step_coefficients(order);
    for &k in &written {
        let terms: Vec<String> = (0..6)
            .filter_map(|axis| {
                let coefficient = lobe_coefficient(axis, k);
                (coefficient != 0.0).then(|| format!("c.f{axis} * {}", literal(coefficient)))
            })
            .collect();
        let _ = writeln!(out, "    let l{k} = {};", terms.join(" + "));
    }
    // [channel][coefficient], as `Volume` and the injected buffer lay a cell out.
    let floats: Vec<Option<String>> = (0..3)
        .flat_map(|ch| (0..sh).map(move |k| (ch, k)))
        .map(|(ch, k)| {
            written
                .contains(&k)
                .then(|| format!("l{k}.{}", ["x", "y", "z"][ch]))
        })
        .collect();
    let _ = writeln!(
        out,
        "    let cell = lpv_cell_index(c.d, params.dims.xyz) * {}u;",
        3 * sh
    );
    for (i, f) in floats.iter().enumerate() {
        if let Some(f) = f {
            let _ = writeln!(out, "    accum[cell + {i}u] += {f};");
        }
    }
    // The step volume keeps only the coefficients a step writes ([`step_layout`]).
    let texels = step_texels(order) as usize;
    let layout = step_layout(order);
    for t in 0..texels {
        let texel: Vec<String> = (4 * t..4 * t + 4)
            .map(|i| {
                layout.get(i).map_or("0.0".to_string(), |&(ch, k)| {
                    format!("l{k}.{}", ["x", "y", "z"][ch])
                })
            })
            .collect();
        let _ = writeln!(
            out,
            "    textureStore(dst, vec3<i32>(c.d.x * {texels} + {t}, c.d.y, c.d.z), vec4<f32>({}));",
            texel.join(", ")
        );
    }
    out.push_str("}\n");
}

/// Which layout a propagation step reads its sources in.
#[derive(Clone, Copy, PartialEq, Eq)]
enum SourceForm {
    /// Every coefficient (`lpv_texel_cell`): the first step reads the injected volume.
    Full,
    /// Only the coefficients a step writes ([`step_coefficients`], `{order}_step_source`):
    /// every later step reads the one before.
    Step,
}

fn write_order(out: &mut String, order: Order, form: SourceForm) {
    let faces = order.faces();
    let sh = order.sh_count();
    let base = order.name();
    let (name, reader, coefficients) = match form {
        SourceForm::Full => (
            format!("{base}_faces"),
            "read_source".to_string(),
            (0..sh).collect(),
        ),
        SourceForm::Step => (
            format!("{base}_step_faces"),
            format!("{base}_step_source"),
            step_coefficients(order),
        ),
    };
    let _ = writeln!(
        out,
        "// {} neighbours, {} faces, {} SH terms{}.",
        neighbour_offsets(&faces).len(),
        faces.len(),
        coefficients.len(),
        if form == SourceForm::Step {
            " (the sources a step wrote)"
        } else {
            ""
        }
    );
    let _ = writeln!(out, "fn {name}(c: ptr<function, Cell>, occlusion: bool) {{");
    out.push_str("    var source: array<vec3<f32>, 9>;\n");
    out.push_str("    var blocker = vec4<f32>(0.0);\n");
    for offset in neighbour_offsets(&faces) {
        let [x, y, z] = offset.to_array();
        let _ = writeln!(
            out,
            "    source = {reader}((*c).d - vec3<i32>({x}, {y}, {z}));"
        );
        let _ = writeln!(
            out,
            "    if (occlusion) {{\n        blocker = {};\n    }}",
            blocker_expression(offset)
        );
        for face in faces.iter().filter(|f| f.offset == offset) {
            write_face(out, face, &coefficients);
        }
    }
    out.push_str("}\n");
}

/// The coefficients a propagation step writes: those of the clamped-cosine lobes about the six
/// axes that are not zero for every axis. All four of LPV's; six of HO-LPV's nine (Y2−2, Y2−1
/// and Y21 vanish on every axis), so from the second step on HO-LPV's sources hold 18 floats,
/// not 27.
pub fn step_coefficients(order: Order) -> Vec<usize> {
    (0..order.sh_count())
        .filter(|&k| (0..6).any(|axis| lobe_coefficient(axis, k) != 0.0))
        .collect()
}

/// rgba32float texels a cell takes in a step volume ([`step_layout`]), the last one padded (3
/// for LPV, 5 for HO-LPV).
pub fn step_texels(order: Order) -> u32 {
    (step_layout(order).len() as u32).div_ceil(4)
}

/// True when a step writes fewer coefficients than the injected volume holds, so that later
/// steps read their sources in a layout of their own (HO-LPV).
pub fn steps_read_fewer_coefficients(order: Order) -> bool {
    step_coefficients(order).len() < order.sh_count()
}

/// A step volume's cell, float by float: (channel, coefficient), channel-major over the
/// [`step_coefficients`], four floats a texel. The stores (`{order}_end`), the reads
/// (`{order}_step_source`) and `LpvMethod::read_volume` all follow it.
pub fn step_layout(order: Order) -> Vec<(usize, usize)> {
    let coefficients = step_coefficients(order);
    (0..3)
        .flat_map(|ch| coefficients.iter().map(move |&k| (ch, k)))
        .collect()
}

/// The float of channel `ch` and coefficient `k` in a cell of the step layout, as
/// (texel, component).
fn step_slot(order: Order, ch: usize, k: usize) -> Option<(usize, usize)> {
    let i = step_layout(order).iter().position(|&f| f == (ch, k))?;
    Some((i / 4, i % 4))
}

/// `{order}_step_source`: a source cell's coefficients read from a step volume (zero outside
/// the grid and for the coefficients a step does not write).
fn write_step_source(out: &mut String, order: Order) {
    let base = order.name();
    let texels = step_texels(order);
    let _ = writeln!(
        out,
        "fn {base}_step_source(c: vec3<i32>) -> array<vec3<f32>, 9> {{\n    \
         if (!lpv_inside(c, params.dims.xyz)) {{\n        return array<vec3<f32>, 9>();\n    }}"
    );
    for t in 0..texels {
        let _ = writeln!(
            out,
            "    let t{t} = textureLoad(src, vec3<i32>(c.x * {texels} + {t}, c.y, c.z), 0);"
        );
    }
    out.push_str("    return array<vec3<f32>, 9>(\n");
    for k in 0..9 {
        let channels: Option<Vec<String>> = (0..3)
            .map(|ch| {
                step_slot(order, ch, k).map(|(t, i)| format!("t{t}.{}", ["x", "y", "z", "w"][i]))
            })
            .collect();
        let _ = match channels {
            Some(c) => writeln!(out, "        vec3<f32>({}),", c.join(", ")),
            None => writeln!(out, "        vec3<f32>(0.0),"),
        };
    }
    out.push_str("    );\n}\n");
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

fn write_face(out: &mut String, face: &Face, coefficients: &[usize]) {
    let y = sh9(face.direction);
    let terms: Vec<String> = coefficients
        .iter()
        .filter(|&&k| y[k] != 0.0)
        .map(|&k| format!("source[{k}] * {}", literal(y[k])))
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
        let lpv = function_body(&text, "lpv_faces");
        let holpv = function_body(&text, "holpv_faces");
        let holpv_steps = function_body(&text, "holpv_step_faces");
        assert_eq!(lpv.matches("face_flux(").count(), math::faces6().len());
        assert_eq!(lpv.matches("read_source(").count(), 6);
        assert_eq!(holpv.matches("face_flux(").count(), math::faces26().len());
        assert_eq!(holpv.matches("read_source(").count(), 26);
        // The later steps' faces read the step layout and leave out the coefficients no step
        // writes; LPV's steps write all of theirs, so LPV has one form.
        assert_eq!(holpv_steps.matches("face_flux(").count(), 54);
        assert_eq!(holpv_steps.matches("holpv_step_source(").count(), 26);
        for k in [4, 5, 7] {
            assert!(!holpv_steps.contains(&format!("source[{k}]")), "Y term {k}");
            assert!(holpv.contains(&format!("source[{k}]")), "Y term {k}");
        }
        assert!(!text.contains("fn lpv_step_faces"));
        // A corner neighbour's midpoint is one GV corner, a face neighbour's the mean of four.
        assert!(holpv.contains("blocker = (*c).corners[7];"));
        assert!(lpv.contains(
            "blocker = ((*c).corners[1] + (*c).corners[3] + (*c).corners[5] + (*c).corners[7]) * 0.25;"
        ));
        for face in math::faces26() {
            assert!(holpv.contains(&literal(face.solid_angle)));
        }
    }

    /// The text of WGSL function `name` in `text`, from its signature to its closing brace.
    fn function_body<'a>(text: &'a str, name: &str) -> &'a str {
        let start = text
            .find(&format!("fn {name}("))
            .unwrap_or_else(|| panic!("no fn {name}"));
        let end = text[start..].find("\n}\n").expect("closing brace") + start;
        &text[start..end]
    }

    #[test]
    fn steps_write_the_coefficients_the_axes_lobes_have_in_a_layout_read_back_whole() {
        // Y2−2 ∝ xy, Y2−1 ∝ yz and Y21 ∝ xz vanish on every axis.
        assert_eq!(step_coefficients(Order::Lpv), vec![0, 1, 2, 3]);
        assert_eq!(step_coefficients(Order::HoLpv), vec![0, 1, 2, 3, 6, 8]);
        assert_eq!(step_texels(Order::Lpv), crate::peers::lpv::cell_texels(4));
        assert_eq!(step_texels(Order::HoLpv), 5);
        for order in [Order::Lpv, Order::HoLpv] {
            let written = step_coefficients(order);
            let mut slots: Vec<(usize, usize)> = (0..3)
                .flat_map(|ch| written.iter().map(move |&k| (ch, k)))
                .map(|(ch, k)| step_slot(order, ch, k).unwrap())
                .collect();
            let count = slots.len();
            slots.sort();
            slots.dedup();
            assert_eq!(slots.len(), count, "{order:?}: two floats in one slot");
            assert!(slots.iter().all(|&(t, _)| t < step_texels(order) as usize));
            for k in (0..order.sh_count()).filter(|k| !written.contains(k)) {
                assert_eq!(step_slot(order, 0, k), None);
            }
        }
    }

    #[test]
    fn the_written_lobes_are_the_cpu_twins_and_skip_only_zero_coefficients() {
        let text = faces_wgsl();
        for (order, adds) in [(Order::Lpv, 12), (Order::HoLpv, 18)] {
            let sh = order.sh_count();
            for axis in 0..6 {
                let twin = math::clamped_cosine(axis_vector(axis), sh);
                for (k, c) in twin.iter().enumerate().take(sh) {
                    let written = lobe_coefficient(axis, k);
                    assert!(
                        (written - c / std::f32::consts::PI).abs() <= 1e-7,
                        "{order:?} axis {axis} k {k}: {written} vs {}",
                        c / std::f32::consts::PI
                    );
                }
            }
            let name = if order == Order::Lpv {
                "lpv_end"
            } else {
                "holpv_end"
            };
            let body = function_body(&text, name);
            assert_eq!(body.matches("accum[cell").count(), adds, "{order:?}");
            assert_eq!(
                body.matches("textureStore(").count(),
                step_texels(order) as usize
            );
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
