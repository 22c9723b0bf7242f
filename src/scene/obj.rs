//! Wavefront OBJ meshes with their MTL materials.
//!
//! Geometry: `v`, `vt`, `vn` and `f` (corners `v`, `v/vt`, `v//vn`, `v/vt/vn`, negative indices
//! counting back from the end), polygons fanned into triangles, one mesh per `usemtl` material.
//! Vertices are shared within a mesh when they repeat the same (v, vt, vn) triple. Corners
//! without a normal get the area-weighted normal of their triangles. OBJ's texture origin is
//! the bottom-left corner; valgi's (glTF's) is the top-left, so v is flipped.
//!
//! Materials (MTL, mapped to DESIGN §3's Lambert + normalized Phong as the README's
//! "OBJ and MTL" section documents): `Kd` → diffuse albedo ρ_d (base colour, metallic 0);
//! `Ks` → specular albedo ρ_s through the specular factor (ρ_s = 0.04 · factor, so factor =
//! mean(Ks)/0.04); `Ns` → the Phong exponent k (roughness chosen so that DESIGN's k(roughness)
//! gives Ns); `Ke` → emitted radiance, W/(m²·sr); `map_Kd` / `map_Ke` → base colour / emission
//! textures (sRGB). A material with black `Kd` and non-zero `Ks` is a metal: base colour Ks,
//! metallic 1. ρ_d + ρ_s is kept at or below 1 by lowering ρ_s, with a warning.
//!
//! Files referenced by `mtllib` and `map_*` go through [`super::files`] (inside the OBJ's
//! folder unless external paths are allowed). A missing MTL or texture is a warning.

use super::builtin::procedural::roughness_for_exponent;
use super::files::{self, ReadPolicy};
use super::mesh::{compute_normals, remove_degenerate_triangles};
use super::{ColorSpace, Instance, Material, Mesh, Node, Scene, SceneError, Texture, Trs};
use glam::{Vec2, Vec3};
use std::collections::HashMap;
use std::path::Path;

/// Most triangles one OBJ file may produce after fanning its polygons.
pub const MAX_TRIANGLES: usize = 1 << 28;

/// Most distinct `mtllib` files one OBJ file may name.
pub const MAX_MATERIAL_LIBRARIES: usize = 256;

/// Albedo of surfaces whose material is missing or names no `Kd`.
pub const DEFAULT_ALBEDO: f32 = 0.8;

/// One mesh per material used by the file, with the material's name (`None` before any
/// `usemtl`), plus the `mtllib` file names in order.
#[derive(Debug, Default)]
pub struct Geometry {
    pub meshes: Vec<(Option<String>, Mesh)>,
    pub mtllibs: Vec<String>,
    pub warnings: Vec<String>,
}

/// Loads an OBJ file and its MTL libraries as a scene: every mesh on one node, no lights or
/// cameras.
pub fn load(path: &Path, policy: ReadPolicy) -> Result<Scene, SceneError> {
    let file = files::read_scene_file(path, files::other_error)?;
    let mut scene = parse(&file.bytes, &file.display, Some(&file.base_dir), policy)?;
    if let Some(stem) = path.file_stem() {
        scene.name = stem.to_string_lossy().into_owned();
    }
    Ok(scene)
}

/// Builds a scene from OBJ bytes. `base_dir` resolves `mtllib` and texture names (`None`: the
/// materials are not read, with a warning); `display` names the source in messages.
pub fn parse(
    bytes: &[u8],
    display: &str,
    base_dir: Option<&Path>,
    policy: ReadPolicy,
) -> Result<Scene, SceneError> {
    let geometry = read_geometry(bytes, display)?;
    let mut scene = Scene {
        name: display.to_string(),
        warnings: geometry.warnings,
        ..Scene::default()
    };
    let mut library: HashMap<String, Mtl> = HashMap::new();
    for lib in &geometry.mtllibs {
        let Some(base) = base_dir else {
            scene.warnings.push(format!(
                "{display}: material library '{lib}' not read (no base folder)"
            ));
            continue;
        };
        let read = files::resolve_reference(base, lib, "material library", policy).and_then(|p| {
            files::read_regular_file(&p)
                .map(|b| (p.clone(), b))
                .map_err(|m| format!("{}: {m}", p.display()))
        });
        match read {
            Ok((mtl_path, mtl_bytes)) => {
                let mtl_display = mtl_path.display().to_string();
                for m in parse_mtl(&mtl_bytes, &mtl_display, &mut scene.warnings) {
                    library.entry(m.name.clone()).or_insert(m);
                }
            }
            Err(m) => scene
                .warnings
                .push(format!("{display}: {m}; its materials fall back to grey")),
        }
    }
    scene.nodes.push(Node {
        name: scene.name.clone(),
        parent: None,
        local: Trs::default(),
    });
    let mut material_index: HashMap<Option<String>, usize> = HashMap::new();
    for (name, mut mesh) in geometry.meshes {
        let index = match material_index.get(&name) {
            Some(&i) => i,
            None => {
                let material = match name.as_ref().and_then(|n| library.get(n)) {
                    Some(mtl) => mtl.to_material(base_dir, policy, &mut scene, display),
                    None => {
                        if let Some(n) = &name {
                            scene.warnings.push(format!(
                                "{display}: material '{n}' is not defined in any material \
                                 library; grey Lambertian used"
                            ));
                        }
                        let mut m = Material::lambert(
                            name.as_deref().unwrap_or("OBJ default"),
                            Vec3::splat(DEFAULT_ALBEDO),
                        );
                        m.double_sided = true;
                        m
                    }
                };
                scene.materials.push(material);
                let i = scene.materials.len() - 1;
                material_index.insert(name.clone(), i);
                i
            }
        };
        mesh.material = index;
        scene.meshes.push(mesh);
        scene.instances.push(Instance {
            mesh: scene.meshes.len() - 1,
            node: 0,
        });
    }
    if scene.instances.is_empty() {
        scene
            .warnings
            .push(format!("{display}: the file contains no faces"));
    }
    super::sanitize::sanitize(&mut scene, display);
    Ok(scene)
}

/// Reads the geometry of an OBJ file (no materials). Errors name `display` and the line.
pub fn read_geometry(bytes: &[u8], display: &str) -> Result<Geometry, SceneError> {
    let fail = |line: usize, message: String| SceneError::Other {
        path: display.to_string(),
        message: format!("line {line}: {message}"),
    };
    let text = String::from_utf8_lossy(bytes);
    let mut positions: Vec<Vec3> = Vec::new();
    let mut uvs: Vec<Vec2> = Vec::new();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut out = Geometry::default();
    let mut builders: Vec<(Option<String>, Builder)> = Vec::new();
    let mut builder_of: HashMap<Option<String>, usize> = HashMap::new();
    let mut current: Option<usize> = None;
    let mut current_name: Option<String> = None;
    let mut triangles = 0usize;
    let mut skipped: HashMap<String, usize> = HashMap::new();
    let mut corners: Vec<u32> = Vec::new();

    for (number, line) in text.lines().enumerate() {
        let line_no = number + 1;
        let line = line.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        let numbers = |words: std::str::SplitWhitespace, least: usize, what: &str| {
            let values: Vec<f32> = words
                .map(|w| w.parse::<f32>())
                .collect::<Result<_, _>>()
                .map_err(|_| fail(line_no, format!("{what}: not numbers: '{}'", shorten(line))))?;
            if values.len() < least {
                return Err(fail(
                    line_no,
                    format!("{what} needs {least} numbers: '{}'", shorten(line)),
                ));
            }
            if values.iter().any(|v| !v.is_finite()) {
                return Err(fail(
                    line_no,
                    format!("{what} is not finite: '{}'", shorten(line)),
                ));
            }
            Ok(values)
        };
        match keyword {
            "v" => {
                let v = numbers(words, 3, "vertex")?;
                positions.push(Vec3::new(v[0], v[1], v[2]));
            }
            "vt" => {
                let v = numbers(words, 1, "texture coordinate")?;
                uvs.push(Vec2::new(v[0], 1.0 - v.get(1).copied().unwrap_or(0.0)));
            }
            "vn" => {
                let v = numbers(words, 3, "normal")?;
                normals.push(Vec3::new(v[0], v[1], v[2]));
            }
            "f" => {
                let builder = match current {
                    Some(b) => b,
                    None => {
                        builders.push((current_name.clone(), Builder::default()));
                        builder_of.insert(current_name.clone(), builders.len() - 1);
                        current = Some(builders.len() - 1);
                        builders.len() - 1
                    }
                };
                corners.clear();
                for word in words {
                    let corner = parse_corner(word, positions.len(), uvs.len(), normals.len())
                        .map_err(|m| fail(line_no, m))?;
                    let b = &mut builders[builder].1;
                    corners.push(b.vertex(corner, &positions, &uvs, &normals));
                }
                if corners.len() < 3 {
                    return Err(fail(
                        line_no,
                        format!("a face needs at least 3 corners: '{}'", shorten(line)),
                    ));
                }
                triangles += corners.len() - 2;
                if triangles > MAX_TRIANGLES {
                    return Err(fail(
                        line_no,
                        format!("more than {MAX_TRIANGLES} triangles"),
                    ));
                }
                let b = &mut builders[builder].1;
                for k in 1..corners.len() - 1 {
                    b.indices.extend([corners[0], corners[k], corners[k + 1]]);
                }
            }
            "usemtl" => {
                let name = line["usemtl".len()..].trim().to_string();
                current_name = Some(name);
                current = builder_of.get(&current_name).copied();
            }
            "mtllib" => {
                for name in words {
                    if out.mtllibs.iter().any(|m| m == name) {
                        continue;
                    }
                    if out.mtllibs.len() >= MAX_MATERIAL_LIBRARIES {
                        return Err(fail(
                            line_no,
                            format!("more than {MAX_MATERIAL_LIBRARIES} material libraries"),
                        ));
                    }
                    out.mtllibs.push(name.to_string());
                }
            }
            "o" | "g" | "s" | "mg" => {}
            other => *skipped.entry(other.chars().take(16).collect()).or_default() += 1,
        }
    }
    let mut keys: Vec<_> = skipped.into_iter().collect();
    keys.sort();
    for (keyword, n) in keys {
        out.warnings.push(format!(
            "{display}: {n} '{keyword}' statement(s) not supported; ignored"
        ));
    }
    let stem = Path::new(display)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "obj".into());
    for (name, builder) in builders {
        let mesh_name = match &name {
            Some(n) => format!("{stem}/{n}"),
            None => stem.clone(),
        };
        let (mesh, removed) = builder.build(&mesh_name);
        if removed > 0 {
            out.warnings.push(format!(
                "{display}: {mesh_name}: removed {removed} degenerate triangle(s)"
            ));
        }
        if !mesh.indices.is_empty() {
            out.meshes.push((name, mesh));
        }
    }
    Ok(out)
}

fn shorten(line: &str) -> String {
    line.chars().take(60).collect()
}

/// 0-based (position, uv, normal) indices of one face corner such as `3/1/-2`.
fn parse_corner(
    word: &str,
    positions: usize,
    uvs: usize,
    normals: usize,
) -> Result<(usize, Option<usize>, Option<usize>), String> {
    let mut parts = word.split('/');
    let resolve = |text: &str, len: usize, what: &str| -> Result<usize, String> {
        let i: i64 = text
            .parse()
            .map_err(|_| format!("bad {what} index '{text}' in face corner '{word}'"))?;
        let resolved = if i > 0 {
            i - 1
        } else if i < 0 {
            len as i64 + i
        } else {
            -1
        };
        if resolved < 0 || resolved >= len as i64 {
            return Err(format!(
                "{what} index {i} in face corner '{word}' is out of range (the file has {len} \
                 so far)"
            ));
        }
        Ok(resolved as usize)
    };
    let p = resolve(parts.next().unwrap_or(""), positions, "vertex")?;
    let t = match parts.next() {
        None | Some("") => None,
        Some(t) => Some(resolve(t, uvs, "texture coordinate")?),
    };
    let n = match parts.next() {
        None | Some("") => None,
        Some(n) => Some(resolve(n, normals, "normal")?),
    };
    if parts.next().is_some() {
        return Err(format!("face corner '{word}' has more than three indices"));
    }
    Ok((p, t, n))
}

/// Accumulates one material's triangles with shared (v, vt, vn) vertices.
#[derive(Default)]
struct Builder {
    map: HashMap<(usize, Option<usize>, Option<usize>), u32>,
    positions: Vec<Vec3>,
    uvs: Vec<Vec2>,
    normals: Vec<Option<Vec3>>,
    indices: Vec<u32>,
}

impl Builder {
    fn vertex(
        &mut self,
        key: (usize, Option<usize>, Option<usize>),
        positions: &[Vec3],
        uvs: &[Vec2],
        normals: &[Vec3],
    ) -> u32 {
        if let Some(&i) = self.map.get(&key) {
            return i;
        }
        let i = self.positions.len() as u32;
        self.positions.push(positions[key.0]);
        self.uvs.push(key.1.map_or(Vec2::ZERO, |t| uvs[t]));
        self.normals
            .push(key.2.and_then(|n| normals[n].try_normalize()));
        self.map.insert(key, i);
        i
    }

    fn build(mut self, name: &str) -> (Mesh, usize) {
        let removed = remove_degenerate_triangles(&self.positions, &mut self.indices);
        let computed = compute_normals(&self.positions, &self.indices);
        let normals = self
            .normals
            .iter()
            .zip(&computed)
            .map(|(n, c)| n.unwrap_or(*c))
            .collect();
        (
            Mesh {
                name: name.to_string(),
                positions: self.positions,
                normals,
                tangents: vec![],
                uv0: self.uvs,
                uv1: None,
                indices: self.indices,
                material: 0,
            },
            removed,
        )
    }
}

/// One `newmtl` block of an MTL file, as written.
#[derive(Clone, Debug, Default)]
pub struct Mtl {
    pub name: String,
    pub kd: Option<Vec3>,
    pub ks: Option<Vec3>,
    pub ke: Option<Vec3>,
    pub ns: Option<f32>,
    pub dissolve: Option<f32>,
    pub map_kd: Option<String>,
    pub map_ke: Option<String>,
    /// The MTL file's folder, against which its maps resolve.
    pub folder: Option<std::path::PathBuf>,
}

/// Parses MTL bytes; unparsable statements are warnings (the material keeps its defaults).
pub fn parse_mtl(bytes: &[u8], display: &str, warnings: &mut Vec<String>) -> Vec<Mtl> {
    let text = String::from_utf8_lossy(bytes);
    let folder = Path::new(display).parent().map(Path::to_path_buf);
    let mut out: Vec<Mtl> = Vec::new();
    let mut ignored: HashMap<String, usize> = HashMap::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        if keyword == "newmtl" {
            out.push(Mtl {
                name: line["newmtl".len()..].trim().to_string(),
                folder: folder.clone(),
                ..Mtl::default()
            });
            continue;
        }
        let Some(m) = out.last_mut() else {
            warnings.push(format!(
                "{display}: line {}: '{keyword}' before any newmtl; ignored",
                number + 1
            ));
            continue;
        };
        let values: Vec<f32> = words.clone().filter_map(|w| w.parse().ok()).collect();
        let colour = |values: &[f32]| match values {
            [r, g, b, ..] => Some(Vec3::new(*r, *g, *b)),
            [v] => Some(Vec3::splat(*v)),
            _ => None,
        };
        let mut bad = || {
            warnings.push(format!(
                "{display}: line {}: cannot read '{}'; ignored",
                number + 1,
                shorten(line)
            ))
        };
        match keyword {
            "Kd" => {
                m.kd = colour(&values).or_else(|| {
                    bad();
                    None
                })
            }
            "Ks" => {
                m.ks = colour(&values).or_else(|| {
                    bad();
                    None
                })
            }
            "Ke" => {
                m.ke = colour(&values).or_else(|| {
                    bad();
                    None
                })
            }
            "Ns" => {
                m.ns = values.first().copied().or_else(|| {
                    bad();
                    None
                })
            }
            "d" => m.dissolve = values.first().copied(),
            "Tr" => m.dissolve = values.first().map(|t| 1.0 - t),
            // The file name is the last word: options such as `-s 1 1 1` come before it.
            "map_Kd" => m.map_kd = words.last().map(str::to_string),
            "map_Ke" => m.map_ke = words.last().map(str::to_string),
            "Ka" | "Ni" | "illum" | "Tf" => {}
            other => *ignored.entry(other.chars().take(16).collect()).or_default() += 1,
        }
    }
    let mut keys: Vec<_> = ignored.into_iter().collect();
    keys.sort();
    for (keyword, n) in keys {
        warnings.push(format!(
            "{display}: {n} '{keyword}' statement(s) not supported; ignored"
        ));
    }
    out
}

impl Mtl {
    /// The material model's reading of this MTL material (see the module documentation).
    fn to_material(
        &self,
        obj_dir: Option<&Path>,
        policy: ReadPolicy,
        scene: &mut Scene,
        display: &str,
    ) -> Material {
        let kd = self.kd.unwrap_or(Vec3::splat(DEFAULT_ALBEDO));
        let ks = self.ks.unwrap_or(Vec3::ZERO);
        let ns = self.ns.unwrap_or(1.0).max(1.0);
        let mut material = mtl_to_material(&self.name, kd, ks, ns, self.ke.unwrap_or(Vec3::ZERO));
        if let Some(warning) = energy_warning(&self.name, kd, ks) {
            scene.warnings.push(format!("{display}: {warning}"));
        }
        if self.dissolve.is_some_and(|d| d < 1.0) {
            scene.warnings.push(format!(
                "{display}: material '{}' is partly transparent (d < 1), which valgi does not \
                 render; drawn opaque",
                self.name
            ));
        }
        let folder = self.folder.as_deref().or(obj_dir);
        let mut texture = |map: &Option<String>, slot: &str| -> Option<usize> {
            let name = map.as_ref()?;
            let folder = folder?;
            let decoded = files::read_reference(folder, name, "texture", policy)
                .and_then(|bytes| files::decode_rgba8(&bytes));
            match decoded {
                Ok(rgba) => {
                    scene.textures.push(Texture {
                        name: name.clone(),
                        width: rgba.width(),
                        height: rgba.height(),
                        rgba8: rgba.into_raw(),
                        color_space: ColorSpace::Srgb,
                    });
                    Some(scene.textures.len() - 1)
                }
                Err(m) => {
                    scene.warnings.push(format!(
                        "{display}: material '{}' {slot} texture ignored: {m}",
                        self.name
                    ));
                    None
                }
            }
        };
        material.base_color_texture = texture(&self.map_kd, "map_Kd");
        if material.base_color_texture.is_some() {
            // The map replaces Kd, as in most OBJ renderers (glTF multiplies factor and map).
            material.base_color = Vec3::ONE.extend(1.0);
        }
        material.emissive_texture = texture(&self.map_ke, "map_Ke");
        if material.emissive_texture.is_some() && self.ke.is_none() {
            material.emissive = Vec3::ONE;
        }
        material
    }
}

/// Maps MTL's Kd, Ks, Ns, Ke onto the material model (see the module documentation).
pub fn mtl_to_material(name: &str, kd: Vec3, ks: Vec3, ns: f32, ke: Vec3) -> Material {
    let kd = kd.clamp(Vec3::ZERO, Vec3::ONE);
    let ks = ks.clamp(Vec3::ZERO, Vec3::ONE);
    let roughness = roughness_for_exponent(ns.max(1.0));
    let metal = kd.max_element() < 0.01 && ks.max_element() > 0.0;
    let (base, metallic, specular_factor) = if metal {
        (ks, 1.0, 1.0)
    } else {
        let rho_s = ks.element_sum().min(3.0 * (1.0 - kd.max_element())) / 3.0;
        (kd, 0.0, rho_s / 0.04)
    };
    Material {
        name: name.to_string(),
        base_color: base.extend(1.0),
        metallic,
        roughness,
        emissive: ke,
        specular_factor,
        double_sided: true,
        ..Material::default()
    }
}

fn energy_warning(name: &str, kd: Vec3, ks: Vec3) -> Option<String> {
    let kd = kd.clamp(Vec3::ZERO, Vec3::ONE);
    let ks = ks.clamp(Vec3::ZERO, Vec3::ONE);
    let metal = kd.max_element() < 0.01 && ks.max_element() > 0.0;
    (!metal && kd.max_element() + ks.element_sum() / 3.0 > 1.0 + 1e-6).then(|| {
        format!(
            "material '{name}': Kd {kd} + Ks {ks} reflect more than they receive; Ks lowered to \
             {:.3}",
            1.0 - kd.max_element()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Material as M;

    #[test]
    fn faces_corners_and_negative_indices() {
        let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
            vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\nusemtl other\nf -4//1 -2//1 -1//1\n";
        let g = read_geometry(obj, "q.obj").unwrap();
        assert_eq!(g.meshes.len(), 2);
        let (name, quad) = &g.meshes[0];
        assert_eq!(*name, None);
        assert_eq!(quad.triangle_count(), 2);
        assert_eq!(quad.positions.len(), 4);
        // v flipped: OBJ (1, 1) is the top-right texel, glTF-style (1, 0).
        assert_eq!(quad.uv0[2], Vec2::new(1.0, 0.0));
        assert!(quad.normals.iter().all(|n| *n == Vec3::Z));
        let (name, tri) = &g.meshes[1];
        assert_eq!(name.as_deref(), Some("other"));
        assert_eq!(
            tri.positions,
            vec![Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]
        );
    }

    #[test]
    fn bad_faces_name_the_line() {
        for (obj, needle) in [
            (&b"v 0 0 0\nf 1 2 3\n"[..], "line 2: vertex index 2"),
            (b"v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3 corners"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "index 0"),
            (
                b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2 3\n",
                "texture coordinate index 1",
            ),
            (b"v 0 0 nan\n", "not finite"),
            (b"v 0 0 1e39\n", "not finite"),
            (b"v 0 0\n", "needs 3 numbers"),
            (
                b"v 0 0 0\nf 1 1 -99999999999999999999\n",
                "bad vertex index",
            ),
            (b"v 0 0 0\nf 1/2/3/4 1 1\n", "out of range"),
        ] {
            let err = read_geometry(obj, "bad.obj").unwrap_err().to_string();
            assert!(
                err.starts_with("bad.obj: ") && err.contains(needle),
                "{needle}: {err}"
            );
        }
    }

    #[test]
    fn mtl_mapping_reproduces_the_phong_parameters() {
        let m = mtl_to_material(
            "plastic",
            Vec3::new(0.6, 0.3, 0.1),
            Vec3::splat(0.2),
            50.0,
            Vec3::ZERO,
        );
        let base = m.base_color.truncate();
        assert!((M::diffuse_albedo(base, m.metallic) - Vec3::new(0.6, 0.3, 0.1)).length() < 1e-6);
        let rho_s = M::specular_albedo(base, m.metallic, m.specular_factor);
        assert!((rho_s - Vec3::splat(0.2)).length() < 1e-5, "{rho_s}");
        assert!((M::phong_exponent(m.roughness) - 50.0).abs() < 0.5);
        // Energy: Kd 0.9 + Ks 0.5 → ρ_s lowered to 0.1.
        let m = mtl_to_material(
            "hot",
            Vec3::splat(0.9),
            Vec3::splat(0.5),
            10.0,
            Vec3::ONE * 5.0,
        );
        let rho_s = M::specular_albedo(m.base_color.truncate(), m.metallic, m.specular_factor);
        assert!((rho_s.x - 0.1).abs() < 1e-5, "{rho_s}");
        assert_eq!(m.emissive, Vec3::splat(5.0));
        assert!(energy_warning("hot", Vec3::splat(0.9), Vec3::splat(0.5)).is_some());
        // Black Kd with coloured Ks: a metal of that colour.
        let gold = Vec3::new(1.0, 0.8, 0.3);
        let m = mtl_to_material("gold", Vec3::ZERO, gold, 200.0, Vec3::ZERO);
        let rho_s = M::specular_albedo(m.base_color.truncate(), m.metallic, m.specular_factor);
        assert!((rho_s - gold).length() < 1e-6);
        assert_eq!(
            M::diffuse_albedo(m.base_color.truncate(), m.metallic),
            Vec3::ZERO
        );
    }

    #[test]
    fn mtl_statements_are_read() {
        let mut warnings = vec![];
        let mtl = parse_mtl(
            b"Kd 1 1 1\nnewmtl a b\nKd 0.5 0.25 0.125\nKs 0.1\nNs 20\nKe 1 2 3\nd 0.5\n\
              map_Kd -s 1 1 1 tex.png\nbump b.png\nnewmtl c\nKd x\n",
            "m.mtl",
            &mut warnings,
        );
        assert_eq!(mtl.len(), 2);
        assert_eq!(mtl[0].name, "a b");
        assert_eq!(mtl[0].kd, Some(Vec3::new(0.5, 0.25, 0.125)));
        assert_eq!(mtl[0].ks, Some(Vec3::splat(0.1)));
        assert_eq!(mtl[0].ke, Some(Vec3::new(1.0, 2.0, 3.0)));
        assert_eq!(mtl[0].ns, Some(20.0));
        assert_eq!(mtl[0].map_kd.as_deref(), Some("tex.png"));
        assert_eq!(mtl[1].kd, None);
        let all = warnings.join("\n");
        assert!(all.contains("before any newmtl"), "{all}");
        assert!(all.contains("'bump'"), "{all}");
        assert!(all.contains("line 11: cannot read 'Kd x'"), "{all}");
    }
}
