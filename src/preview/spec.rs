//! What the preview shows: materials from a glTF file (`FILE.glb[#NAME|#INDEX]`) and parameter
//! sweeps (`roughness=0..1:5,metallic=0,1`), each expanded into labelled cells of a grid.

use std::path::Path;

use glam::{Vec3, Vec4};

use crate::scene::{Material, Texture};

use super::PreviewError;

/// One ball of the grid: its material (texture indices refer to `textures`) and its label.
#[derive(Clone, Debug)]
pub struct PreviewMaterial {
    pub label: String,
    pub material: Material,
    /// The textures `material` samples (its indices point into this list).
    pub textures: Vec<Texture>,
}

impl PreviewMaterial {
    /// A material without textures.
    pub fn plain(label: &str, material: Material) -> Self {
        Self {
            label: label.into(),
            material,
            textures: vec![],
        }
    }
}

/// The sweep's starting material: a neutral grey dielectric of medium roughness, so that the
/// red and green walls show in its reflections.
pub fn default_material() -> Material {
    Material {
        name: "preview".into(),
        base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
        metallic: 0.0,
        roughness: 0.5,
        specular_factor: 1.0,
        ..Material::default()
    }
}

/// A swept material parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepParam {
    Roughness,
    Metallic,
    /// `KHR_materials_specular`'s factor on ρ_s.
    Specular,
    /// Base colour, `R/G/B` or one grey value.
    Base,
}

impl SweepParam {
    const ALL: [(&'static str, SweepParam); 4] = [
        ("roughness", SweepParam::Roughness),
        ("metallic", SweepParam::Metallic),
        ("specular", SweepParam::Specular),
        ("base", SweepParam::Base),
    ];

    fn parse(name: &str) -> Option<Self> {
        Self::ALL.iter().find(|(n, _)| *n == name).map(|(_, p)| *p)
    }

    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(_, p)| *p == self).unwrap().0
    }

    /// Short label prefix.
    fn short(self) -> &'static str {
        match self {
            SweepParam::Roughness => "r",
            SweepParam::Metallic => "m",
            SweepParam::Specular => "s",
            SweepParam::Base => "base",
        }
    }

    fn apply(self, material: &mut Material, value: Vec3) {
        match self {
            SweepParam::Roughness => material.roughness = value.x,
            SweepParam::Metallic => material.metallic = value.x,
            SweepParam::Specular => material.specular_factor = value.x,
            SweepParam::Base => material.base_color = value.extend(material.base_color.w),
        }
    }
}

/// Most balls one grid may hold (a typo like `roughness=0..1:1000` is refused, not rendered
/// for an hour).
pub const MAX_CELLS: usize = 256;

/// A parsed `--sweep`: parameters in the order given, each with its values. The first
/// parameter runs along the grid's columns, the others down its rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    pub params: Vec<(SweepParam, Vec<Vec3>)>,
}

impl Sweep {
    /// Parses `name=values[,name=values...]` where values are a comma-separated list of
    /// numbers, ranges `a..b:n` (n evenly spaced values from a to b) and, for `base`, `R/G/B`
    /// triples. A comma followed by a token without `=` continues the previous parameter's list.
    pub fn parse(spec: &str) -> Result<Sweep, PreviewError> {
        let bad = |why: String| PreviewError::Spec(format!("--sweep '{spec}': {why}"));
        let mut params: Vec<(SweepParam, Vec<Vec3>)> = vec![];
        for token in spec.split(',').map(str::trim) {
            if token.is_empty() {
                return Err(bad(
                    "empty item (two commas in a row, or a trailing comma)".into()
                ));
            }
            let (param, value) = match token.split_once('=') {
                Some((name, value)) => {
                    let name = name.trim();
                    let param = SweepParam::parse(name).ok_or_else(|| {
                        bad(format!(
                            "unknown parameter '{name}' (sweepable: {})",
                            SweepParam::ALL.map(|(n, _)| n).join(", ")
                        ))
                    })?;
                    if params.iter().any(|(p, _)| *p == param) {
                        return Err(bad(format!("parameter '{name}' given twice")));
                    }
                    params.push((param, vec![]));
                    (param, value.trim())
                }
                None => match params.last() {
                    Some((param, _)) => (*param, token),
                    None => {
                        return Err(bad(format!(
                            "'{token}' is not name=values (e.g. roughness=0..1:5)"
                        )))
                    }
                },
            };
            let values = parse_values(param, value).map_err(&bad)?;
            params.last_mut().expect("pushed above").1.extend(values);
        }
        if params.is_empty() {
            return Err(bad("no parameter given".into()));
        }
        let cells: usize = params.iter().map(|(_, v)| v.len()).product();
        if cells > MAX_CELLS {
            return Err(bad(format!(
                "{cells} combinations; at most {MAX_CELLS} balls per grid"
            )));
        }
        Ok(Sweep { params })
    }

    /// Values along the grid's columns (the first parameter's count).
    pub fn columns(&self) -> usize {
        self.params[0].1.len()
    }

    /// The swept materials, row-major (the first parameter varies fastest), each `base` with
    /// the combination applied and labelled with the values.
    pub fn materials(&self, base: &PreviewMaterial) -> Vec<PreviewMaterial> {
        let total: usize = self.params.iter().map(|(_, v)| v.len()).product();
        (0..total)
            .map(|index| {
                let mut cell = base.clone();
                let mut rest = index;
                let mut parts = vec![];
                for (param, values) in &self.params {
                    let value = values[rest % values.len()];
                    rest /= values.len();
                    param.apply(&mut cell.material, value);
                    parts.push(format!("{}={}", param.short(), format_value(*param, value)));
                }
                let values = parts.join(" ");
                cell.label = if base.label.is_empty() {
                    values
                } else {
                    format!("{} {values}", base.label)
                };
                cell.material.name = cell.label.clone();
                cell
            })
            .collect()
    }
}

fn format_value(param: SweepParam, v: Vec3) -> String {
    let short = |x: f32| {
        let text = format!("{x:.3}");
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    };
    match param {
        SweepParam::Base if v.x == v.y && v.y == v.z => short(v.x),
        SweepParam::Base => format!("{}/{}/{}", short(v.x), short(v.y), short(v.z)),
        _ => short(v.x),
    }
}

fn parse_number(text: &str) -> Result<f32, String> {
    let value: f32 = text
        .trim()
        .parse()
        .map_err(|_| format!("'{text}' is not a number"))?;
    if !value.is_finite() {
        return Err(format!("'{text}' is not a finite number"));
    }
    Ok(value)
}

/// One item of a parameter's list: a number, a range `a..b:n`, or (base) `R/G/B`.
fn parse_values(param: SweepParam, text: &str) -> Result<Vec<Vec3>, String> {
    let in_range = |v: f32| -> Result<f32, String> {
        if (0.0..=1.0).contains(&v) {
            Ok(v)
        } else {
            Err(format!("{} {v} is outside 0..=1", param.name()))
        }
    };
    if text.is_empty() {
        return Err(format!("{} has an empty value", param.name()));
    }
    if let Some((range, count)) = text.split_once(':') {
        let Some((a, b)) = range.split_once("..") else {
            return Err(format!(
                "'{text}': a range is a..b:n (e.g. 0..1:5), ':' without '..'"
            ));
        };
        let (a, b) = (in_range(parse_number(a)?)?, in_range(parse_number(b)?)?);
        let n: usize = count
            .trim()
            .parse()
            .map_err(|_| format!("'{text}': the count '{count}' is not a whole number"))?;
        if n == 0 || n > MAX_CELLS {
            return Err(format!("'{text}': the count must be 1..={MAX_CELLS}"));
        }
        if n == 1 && a != b {
            return Err(format!(
                "'{text}': one value cannot span {a}..{b}; give a count of 2 or more"
            ));
        }
        return Ok((0..n)
            .map(|i| {
                let t = if n == 1 {
                    0.0
                } else {
                    i as f32 / (n - 1) as f32
                };
                Vec3::splat(a + (b - a) * t)
            })
            .collect());
    }
    if text.contains("..") {
        return Err(format!("'{text}': a range needs a count, a..b:n"));
    }
    if param == SweepParam::Base && text.contains('/') {
        let channels: Vec<&str> = text.split('/').collect();
        if channels.len() != 3 {
            return Err(format!("base colour '{text}' is not R/G/B"));
        }
        let mut rgb = [0.0; 3];
        for (c, t) in rgb.iter_mut().zip(channels) {
            *c = in_range(parse_number(t)?)?;
        }
        return Ok(vec![Vec3::from(rgb)]);
    }
    Ok(vec![Vec3::splat(in_range(parse_number(text)?)?)])
}

/// The materials `FILE.glb[#NAME|#INDEX]` selects: all of the file's own materials without a
/// selector, else the one whose name is NAME (tried first) or whose index is INDEX.
pub fn load_materials(spec: &str) -> Result<Vec<PreviewMaterial>, PreviewError> {
    let (file, selector) = match spec.rsplit_once('#') {
        Some((file, selector)) => (file, Some(selector)),
        None => (spec, None),
    };
    let path = Path::new(file);
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if !matches!(extension.as_deref(), Some("glb" | "gltf")) {
        return Err(PreviewError::Spec(format!(
            "--material '{spec}': expected FILE.glb or FILE.gltf, optionally #NAME or #INDEX"
        )));
    }
    if !path.is_file() {
        return Err(PreviewError::Spec(format!(
            "--material {file}: file not found"
        )));
    }
    // The document's own materials come first in the imported list; the importer appends a
    // default material after them only for primitives that name none.
    let own = gltf::Gltf::open(path)
        .map_err(|e| PreviewError::Spec(format!("--material {file}: cannot read glTF: {e}")))?
        .document
        .materials()
        .len();
    let scene = crate::scene::gltf_import::load(path)?;
    if own == 0 {
        return Err(PreviewError::Spec(format!(
            "--material {file}: the file defines no materials"
        )));
    }
    let names: Vec<&str> = scene.materials[..own]
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    let chosen: Vec<usize> = match selector {
        None => (0..own).collect(),
        Some(selector) => {
            if let Some(i) = names.iter().position(|n| *n == selector) {
                vec![i]
            } else if let Ok(i) = selector.parse::<usize>() {
                if i >= own {
                    return Err(PreviewError::Spec(format!(
                        "--material {spec}: index {i} is out of range: {file} has {own} \
                         material(s), 0..={}",
                        own - 1
                    )));
                }
                vec![i]
            } else {
                return Err(PreviewError::Spec(format!(
                    "--material {spec}: {file} has no material named '{selector}' (it has: {})",
                    names.join(", ")
                )));
            }
        }
    };
    Ok(chosen
        .into_iter()
        .map(|i| {
            let mut material = scene.materials[i].clone();
            // Only the textures this material samples travel with it, renumbered.
            let mut textures = vec![];
            for slot in [
                &mut material.base_color_texture,
                &mut material.metallic_roughness_texture,
                &mut material.normal_texture,
                &mut material.emissive_texture,
            ] {
                if let Some(t) = slot.as_mut() {
                    textures.push(scene.textures[*t].clone());
                    *t = textures.len() - 1;
                }
            }
            let label = if selector.is_some() || own == 1 {
                material.name.clone()
            } else {
                format!("{i}: {}", material.name)
            };
            PreviewMaterial {
                label,
                material,
                textures,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_and_lists_expand() {
        let sweep = Sweep::parse("roughness=0..1:5,metallic=0,1").unwrap();
        assert_eq!(sweep.params.len(), 2);
        let r: Vec<f32> = sweep.params[0].1.iter().map(|v| v.x).collect();
        assert_eq!(r, vec![0.0, 0.25, 0.5, 0.75, 1.0]);
        let m: Vec<f32> = sweep.params[1].1.iter().map(|v| v.x).collect();
        assert_eq!(m, vec![0.0, 1.0]);
        assert_eq!(sweep.columns(), 5);
        let cells = sweep.materials(&PreviewMaterial::plain("", default_material()));
        assert_eq!(cells.len(), 10);
        assert_eq!(cells[1].label, "r=0.25 m=0");
        assert_eq!(cells[1].material.roughness, 0.25);
        assert_eq!(cells[7].material.metallic, 1.0);
        assert_eq!(cells[7].material.roughness, 0.5);
    }

    #[test]
    fn base_colour_and_specular() {
        let sweep = Sweep::parse("base=0.9/0.1/0.1,0.5, specular=0,1").unwrap();
        let cells = sweep.materials(&PreviewMaterial::plain("", default_material()));
        assert_eq!(cells.len(), 4);
        assert_eq!(cells[0].material.base_color, Vec4::new(0.9, 0.1, 0.1, 1.0));
        assert_eq!(cells[1].material.base_color, Vec4::new(0.5, 0.5, 0.5, 1.0));
        assert_eq!(cells[2].material.specular_factor, 1.0);
        assert_eq!(cells[0].label, "base=0.9/0.1/0.1 s=0");
    }

    #[test]
    fn bad_specs_are_clear_errors() {
        for (spec, expected) in [
            ("", "empty item"),
            ("gloss=0..1:3", "unknown parameter 'gloss'"),
            ("roughness=0..1", "needs a count"),
            ("roughness=0..1:0", "count must be"),
            ("roughness=0..1:x", "not a whole number"),
            ("roughness=0..2:3", "outside 0..=1"),
            ("roughness=abc", "'abc' is not a number"),
            ("roughness=NaN", "not a finite number"),
            ("roughness=0.5,", "empty item"),
            ("0.5", "is not name=values"),
            ("roughness=0,roughness=1", "given twice"),
            ("base=1/0", "is not R/G/B"),
            ("metallic=0:3", "':' without '..'"),
            ("roughness=0..1:20,metallic=0..1:20", "at most"),
            ("roughness=", "empty value"),
            ("roughness=0..1:1", "give a count of 2"),
        ] {
            let e = Sweep::parse(spec).unwrap_err().to_string();
            assert!(e.contains(expected), "{spec}: {e}");
            assert!(
                e.contains(&format!("'{spec}'")),
                "{spec}: names the spec: {e}"
            );
        }
    }

    #[test]
    fn bad_material_specs() {
        let e = load_materials("model.obj").unwrap_err().to_string();
        assert!(e.contains("expected FILE.glb"), "{e}");
        let e = load_materials("missing/none.glb#0")
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing/none.glb: file not found"), "{e}");
    }
}
