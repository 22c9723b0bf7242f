//! Mitsuba scene files (`scene.xml`): the subset of Mitsuba 0.5 and Mitsuba 3 that real-asset
//! scenes such as Bitterli's "Veach, Ajar" (0.5) and the measured Cornell box of mitsuba-data
//! (3.0) use. Property names match in either spelling (`toWorld` / `to_world`, `intIOR` /
//! `int_ior`, `fovAxis` / `fov_axis`).
//!
//! Read:
//! - the file level ([`super::mitsuba_xml`]): `<include>`, `<default>` parameters and `$name`
//!   substitution, with errors naming the file and line.
//! - shapes `obj`, `ply`, `rectangle`, `cube` and `sphere` with `toWorld` transforms (`matrix`,
//!   `translate`, `scale`, `rotate`, `lookat`), baked into world-space vertices (normals by the
//!   inverse transpose, winding kept outward under mirroring); `faceNormals` gives flat
//!   shading. A mesh file that is missing is skipped with a warning (the Veach room names two
//!   teapots it does not ship).
//! - BSDFs by reference (`<ref id>`) or inline, mapped to DESIGN §3's material model:
//!   `diffuse` → ρ_d = reflectance; `plastic` / `roughplastic` → ρ_d = diffuseReflectance and
//!   ρ_s = F0(intIOR/extIOR) · specularReflectance; `conductor` / `roughconductor` → a metal
//!   whose colour is the normal-incidence Fresnel reflectance from `eta` and `k` (or the named
//!   `material`) times specularReflectance; `twosided` → double-sided. Beckmann/GGX `alpha`
//!   becomes valgi's α = roughness², smooth variants α = 0 (the Phong exponent's cap).
//!   Textures are loaded when present (`bitmap`); a missing bitmap and a `checkerboard` fall
//!   back to a constant (0.5 grey, the checkerboard's mean colour) with a warning.
//!   `dielectric` has no transmission in valgi: it becomes a black surface with only the
//!   Fresnel specular lobe, with a warning.
//! - colours as `rgb` (linear), `srgb`, a single number, or a sampled `spectrum` ("λ:v, …",
//!   nm) converted with the CIE 1931 colour-matching functions ([`super::spectrum`]):
//!   reflectances (and η, k) white-balanced under D65 so a constant spectrum is its grey,
//!   emission keeping its own colour with Y the ȳ-weighted mean radiance.
//! - area emitters → emissive materials (radiance, W/(m²·sr)): nested in a shape, or at the
//!   top level with an `id` that shapes reference by `<ref id>` (Mitsuba 3); `point`, `spot`
//!   and `directional` emitters → punctual lights; other emitters are skipped with a warning.
//! - the `perspective` sensor: `fov` along `fovAxis` (x, y, smaller, larger, diagonal) of the
//!   rendered image, clip planes, `toWorld`. The film's size is checked, not used: the render's
//!   `--width`/`--height` set the image, and the angle stays on its axis at any aspect.
//!   Integrator, sampler, film and reconstruction-filter settings are valgi's command line's
//!   and are passed over silently.
//!
//! Referenced files go through [`super::files`]: inside the scene's folder unless external
//! paths are allowed.

use super::files::{self, ReadPolicy};
use super::mesh::{compute_normals, remove_degenerate_triangles};
use super::mitsuba_xml::{self, Document, Element};
use super::spectrum::{self, SampledSpectrum};
use super::{
    Camera, ColorSpace, FovAxis, Instance, Light, LightKind, Material, Mesh, Node, Scene,
    SceneError, Texture, Trs,
};
use glam::{Mat3, Mat4, Quat, Vec2, Vec3, Vec4};
use std::collections::HashMap;
use std::path::Path;

/// Most triangles the shapes of one scene file may place (each shape bakes its own copy).
pub const MAX_SCENE_TRIANGLES: usize = 1 << 26;

/// Loads a Mitsuba scene file; its references resolve relative to its folder under `policy`.
pub fn load(path: &Path, policy: ReadPolicy) -> Result<Scene, SceneError> {
    load_with_parameters(path, policy, &[])
}

/// [`load`] with scene parameters defined ahead of the file's `<default>`s (Mitsuba's
/// `-D name=value`).
pub fn load_with_parameters(
    path: &Path,
    policy: ReadPolicy,
    parameters: &[(String, String)],
) -> Result<Scene, SceneError> {
    let file = files::read_scene_file(path, files::other_error)?;
    let mut scene = parse_source(
        &file.bytes,
        &file.display,
        Some(&file.base_dir),
        std::fs::canonicalize(path).ok(),
        policy,
        parameters,
    )?;
    if let Some(stem) = path.parent().and_then(Path::file_name) {
        // "scene.xml" says little; the folder names the scene (veach-ajar).
        scene.name = stem.to_string_lossy().into_owned();
    }
    Ok(scene)
}

/// Builds a scene from Mitsuba XML bytes. `base_dir` resolves mesh, texture and include file
/// names (`None`: file-based shapes are skipped with a warning, includes are errors).
pub fn parse(
    bytes: &[u8],
    display: &str,
    base_dir: Option<&Path>,
    policy: ReadPolicy,
) -> Result<Scene, SceneError> {
    parse_source(bytes, display, base_dir, None, policy, &[])
}

/// [`parse`] with scene parameters defined ahead of the file's `<default>`s.
pub fn parse_with_parameters(
    bytes: &[u8],
    display: &str,
    base_dir: Option<&Path>,
    policy: ReadPolicy,
    parameters: &[(String, String)],
) -> Result<Scene, SceneError> {
    parse_source(bytes, display, base_dir, None, policy, parameters)
}

fn parse_source(
    bytes: &[u8],
    display: &str,
    base_dir: Option<&Path>,
    top_file: Option<std::path::PathBuf>,
    policy: ReadPolicy,
    parameters: &[(String, String)],
) -> Result<Scene, SceneError> {
    let document = mitsuba_xml::read(bytes, display, base_dir, top_file, policy, parameters)
        .map_err(|message| SceneError::Other {
            path: display.to_string(),
            message,
        })?;
    let mut reader = Reader {
        display: display.to_string(),
        document: &document,
        has_base_dir: base_dir.is_some(),
        policy,
        scene: Scene {
            name: Path::new(display)
                .file_stem()
                .map_or_else(|| display.to_string(), |s| s.to_string_lossy().into_owned()),
            ..Scene::default()
        },
        bsdfs: HashMap::new(),
        area_emitters: HashMap::new(),
        textures: HashMap::new(),
        mesh_files: HashMap::new(),
        triangles: 0,
    };
    reader.scene.nodes.push(Node {
        name: "world".into(),
        parent: None,
        local: Trs::default(),
    });
    // BSDFs and area emitters first: a shape may reference one written after it (Mitsuba
    // resolves references once the whole file is read; cbox-rgb.xml defines its emitter last).
    for child in document.root.children() {
        match child.tag() {
            "bsdf" => {
                let material = reader.bsdf(child)?;
                if let Some(id) = child.attribute("id") {
                    reader.bsdfs.insert(id.to_string(), material);
                }
            }
            "emitter" if child.attribute("type") == Some("area") => {
                let radiance = reader.area_radiance(child)?;
                match child.attribute("id") {
                    Some(id) => {
                        reader.area_emitters.insert(id.to_string(), radiance);
                    }
                    None => reader.warn(format!(
                        "{}: area emitter without an id, so no shape can reference it; ignored",
                        reader.at(child)
                    )),
                }
            }
            _ => {}
        }
    }
    for child in document.root.children() {
        match child.tag() {
            "bsdf" => {}
            "emitter" if child.attribute("type") == Some("area") => {}
            "shape" => reader.shape(child)?,
            "sensor" => reader.sensor(child)?,
            "emitter" => reader.emitter(child)?,
            // Rendering settings valgi takes from its command line.
            "integrator" | "sampler" | "film" | "rfilter" => {}
            other => reader.warn(format!("<{other}> is not read; ignored")),
        }
    }
    if reader.scene.instances.is_empty() {
        reader.warn("the scene contains no shapes valgi can read".to_string());
    }
    let mut scene = reader.scene;
    super::sanitize::sanitize(&mut scene, display);
    Ok(scene)
}

struct Reader<'a> {
    display: String,
    document: &'a Document,
    /// Whether the scene came with a folder (file references can be resolved).
    has_base_dir: bool,
    policy: ReadPolicy,
    scene: Scene,
    bsdfs: HashMap<String, Material>,
    /// Top-level area emitters by id: their radiance, for the shapes that reference them.
    area_emitters: HashMap<String, Vec3>,
    /// Bitmap file name → texture index (None: could not be loaded).
    textures: HashMap<String, Option<usize>>,
    /// Mesh files already read, by canonical path: a file is parsed once however many shapes
    /// place it.
    mesh_files: HashMap<std::path::PathBuf, Vec<Mesh>>,
    /// Triangles placed so far, against [`MAX_SCENE_TRIANGLES`].
    triangles: usize,
}

/// The child element `<tag name="name" …>` of `node`.
fn property<'a>(node: &'a Element, tag: &str, name: &str) -> Option<&'a Element> {
    node.children()
        .find(|c| c.tag() == tag && c.attribute("name").is_some_and(|n| same_name(n, name)))
}

/// Whether two property names are the same in Mitsuba 0.5's camelCase or Mitsuba 3's
/// snake_case (`toWorld` = `to_world`, `intIOR` = `int_ior`, `fovAxis` = `fov_axis`).
fn same_name(a: &str, b: &str) -> bool {
    let folded = |s: &str| {
        s.chars()
            .filter(|c| *c != '_')
            .map(|c| c.to_ascii_lowercase())
            .collect::<String>()
    };
    folded(a) == folded(b)
}

/// What a colour property measures, which decides how a sampled spectrum becomes linear sRGB
/// (see [`super::spectrum`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Quantity {
    /// A ratio (reflectance, η, k): white-balanced under D65, so a constant spectrum is its
    /// grey.
    Ratio,
    /// Emitted radiance, intensity or irradiance: the spectrum's own colour, with Y its
    /// ȳ-weighted mean.
    Emission,
}

/// Numbers separated by commas and/or whitespace.
fn numbers(text: &str) -> Result<Vec<f32>, String> {
    text.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|w| !w.is_empty())
        .map(|w| {
            w.parse::<f32>().map_err(|_| {
                format!(
                    "'{}' is not a number",
                    w.chars().take(40).collect::<String>()
                )
            })
        })
        .collect()
}

impl Reader<'_> {
    fn err(&self, message: String) -> SceneError {
        SceneError::Other {
            path: self.display.clone(),
            message,
        }
    }

    fn warn(&mut self, message: String) {
        self.scene
            .warnings
            .push(format!("{}: {message}", self.display));
    }

    /// `<tag name=… value=…>` parsed as one number, with the line for errors.
    fn float(&self, node: &Element, name: &str, default: f32) -> Result<f32, SceneError> {
        let Some(p) = property(node, "float", name).or_else(|| property(node, "integer", name))
        else {
            return Ok(default);
        };
        let value = p.attribute("value").unwrap_or("");
        match numbers(value).as_deref() {
            Ok([v]) => Ok(*v),
            _ => Err(self.err(format!(
                "{}: '{name}' value '{value}' is not one number",
                self.at(p)
            ))),
        }
    }

    fn string<'n>(&self, node: &'n Element, name: &str) -> Option<&'n str> {
        property(node, "string", name).and_then(|p| p.attribute("value"))
    }

    fn at(&self, node: &Element) -> String {
        self.document.at(node)
    }

    /// A colour property (`rgb`, `srgb`, `spectrum` or a constant `float`); `None` when absent
    /// or a texture (see [`Self::colour_or_texture`]). A sampled spectrum becomes linear sRGB
    /// as `quantity` says; a single number is that grey, whatever the tag.
    fn colour(
        &mut self,
        node: &Element,
        name: &str,
        quantity: Quantity,
    ) -> Result<Option<Vec3>, SceneError> {
        let Some(p) = node.children().find(|c| {
            c.attribute("name").is_some_and(|n| same_name(n, name))
                && matches!(c.tag(), "rgb" | "srgb" | "spectrum" | "float")
        }) else {
            return Ok(None);
        };
        let value = p.attribute("value").unwrap_or("");
        let tag = p.tag();
        if tag == "spectrum" && value.contains(':') {
            let spectrum = SampledSpectrum::parse(value)
                .map_err(|m| self.err(format!("{}: spectrum '{name}': {m}", self.at(p))))?;
            let rgb = match quantity {
                Quantity::Ratio => spectrum::reflectance_to_linear_srgb(&spectrum),
                Quantity::Emission => spectrum::emission_to_linear_srgb(&spectrum),
            };
            if rgb.min_element() < 0.0 {
                self.warn(format!(
                    "{}: spectrum '{name}' lies outside the sRGB gamut ({rgb}); negative \
                     channels clamped to 0",
                    self.at(p)
                ));
            }
            return Ok(Some(rgb.max(Vec3::ZERO)));
        }
        let v = numbers(value).map_err(|m| self.err(format!("{}: '{name}': {m}", self.at(p))))?;
        let rgb = match v.as_slice() {
            [x] => Vec3::splat(*x),
            [r, g, b] => Vec3::new(*r, *g, *b),
            _ => {
                return Err(self.err(format!(
                    "{}: '{name}' needs 1 or 3 numbers, found '{value}'",
                    self.at(p)
                )))
            }
        };
        Ok(Some(if tag == "srgb" {
            rgb.map(srgb_to_linear)
        } else {
            rgb
        }))
    }

    /// A colour property that may also be a `<texture>`: `bitmap` (loaded when the file is
    /// there) or `checkerboard` (its mean colour).
    fn colour_or_texture(
        &mut self,
        node: &Element,
        name: &str,
        default: Vec3,
    ) -> Result<(Vec3, Option<usize>), SceneError> {
        if let Some(c) = self.colour(node, name, Quantity::Ratio)? {
            return Ok((c, None));
        }
        let Some(texture) = property(node, "texture", name) else {
            return Ok((default, None));
        };
        match texture.attribute("type") {
            Some("bitmap") => {
                let file = self.string(texture, "filename").unwrap_or("").to_string();
                Ok(match self.bitmap(texture, &file) {
                    Some(index) => (Vec3::ONE, Some(index)),
                    None => (default, None),
                })
            }
            Some("checkerboard") => {
                let a = self
                    .colour(texture, "color0", Quantity::Ratio)?
                    .unwrap_or(Vec3::splat(0.4));
                let b = self
                    .colour(texture, "color1", Quantity::Ratio)?
                    .unwrap_or(Vec3::splat(0.2));
                self.warn(format!(
                    "{}: checkerboard '{name}' replaced by its mean colour",
                    self.at(texture)
                ));
                Ok(((a + b) * 0.5, None))
            }
            other => {
                self.warn(format!(
                    "{}: texture type {other:?} not supported; '{name}' uses {default}",
                    self.at(texture)
                ));
                Ok((default, None))
            }
        }
    }

    fn bitmap(&mut self, node: &Element, file: &str) -> Option<usize> {
        if let Some(known) = self.textures.get(file) {
            return *known;
        }
        let loaded = self
            .document
            .resolve(node, file, "texture", self.policy)
            .and_then(|path| {
                files::read_regular_file(&path)
                    .map_err(|m| format!("texture file '{}': {m}", path.display()))
            })
            .and_then(|bytes| files::decode_rgba8(&bytes));
        let index = match loaded {
            Ok(rgba) => {
                self.scene.textures.push(Texture {
                    name: file.to_string(),
                    width: rgba.width(),
                    height: rgba.height(),
                    rgba8: rgba.into_raw(),
                    color_space: ColorSpace::Srgb,
                });
                Some(self.scene.textures.len() - 1)
            }
            Err(m) => {
                self.warn(format!(
                    "bitmap '{file}' not loaded ({m}); constant colour used"
                ));
                None
            }
        };
        self.textures.insert(file.to_string(), index);
        index
    }

    /// The material model's reading of a `<bsdf>` element (see the module documentation).
    fn bsdf(&mut self, node: &Element) -> Result<Material, SceneError> {
        let kind = node.attribute("type").unwrap_or("");
        let name = node.attribute("id").unwrap_or(kind).to_string();
        // valgi's roughness from Beckmann/GGX alpha (α = roughness²); smooth variants have α = 0.
        let roughness = |r: &Self| -> Result<f32, SceneError> {
            if !kind.starts_with("rough") {
                return Ok(0.0);
            }
            let a = r.float(node, "alpha", f32::NAN)?;
            let a = if a.is_finite() {
                a
            } else {
                0.5 * (r.float(node, "alphaU", 0.1)? + r.float(node, "alphaV", 0.1)?)
            };
            Ok(a.max(0.0).sqrt())
        };
        let mut m = match kind {
            "twosided" => {
                let inner = node.children().find(|c| c.tag() == "bsdf");
                let mut m = match inner {
                    Some(inner) => self.bsdf(inner)?,
                    None => {
                        self.warn(format!("{}: twosided without an inner bsdf", self.at(node)));
                        Material::lambert(&name, Vec3::splat(0.5))
                    }
                };
                m.double_sided = true;
                m.name = name;
                return Ok(m);
            }
            "diffuse" | "roughdiffuse" => {
                let (rho, texture) =
                    self.colour_or_texture(node, "reflectance", Vec3::splat(0.5))?;
                let mut m = Material::lambert(&name, rho);
                m.base_color_texture = texture;
                m
            }
            "plastic" | "roughplastic" => {
                let (rho, texture) =
                    self.colour_or_texture(node, "diffuseReflectance", Vec3::splat(0.5))?;
                let specular = self
                    .colour(node, "specularReflectance", Quantity::Ratio)?
                    .unwrap_or(Vec3::ONE);
                let eta = self.ior(node, "intIOR", 1.49)? / self.ior(node, "extIOR", 1.000277)?;
                let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
                Material {
                    name: name.clone(),
                    base_color: rho.extend(1.0),
                    base_color_texture: texture,
                    metallic: 0.0,
                    roughness: roughness(self)?,
                    specular_factor: f0 * specular.element_sum() / 3.0 / 0.04,
                    ..Material::default()
                }
            }
            "conductor" | "roughconductor" => {
                let (specular, _) =
                    self.colour_or_texture(node, "specularReflectance", Vec3::ONE)?;
                let f0 = match (
                    self.colour(node, "eta", Quantity::Ratio)?,
                    self.colour(node, "k", Quantity::Ratio)?,
                ) {
                    (Some(eta), Some(k)) => fresnel_conductor(eta, k),
                    _ => {
                        let named = self.string(node, "material").unwrap_or("Cu").to_string();
                        match conductor_table(&named) {
                            Some((eta, k)) => fresnel_conductor(eta, k),
                            None => {
                                self.warn(format!(
                                    "{}: conductor material '{named}' unknown; grey metal used",
                                    self.at(node)
                                ));
                                Vec3::splat(0.9)
                            }
                        }
                    }
                };
                Material {
                    name: name.clone(),
                    base_color: (f0 * specular).extend(1.0),
                    metallic: 1.0,
                    roughness: roughness(self)?,
                    specular_factor: 1.0,
                    ..Material::default()
                }
            }
            "dielectric" | "roughdielectric" | "thindielectric" => {
                let eta = self.ior(node, "intIOR", 1.5046)? / self.ior(node, "extIOR", 1.000277)?;
                let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
                self.warn(format!(
                    "{}: bsdf '{name}' ({kind}) transmits light, which valgi does not render; \
                     drawn as its reflection only",
                    self.at(node)
                ));
                Material {
                    name: name.clone(),
                    base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
                    metallic: 0.0,
                    roughness: roughness(self)?,
                    specular_factor: f0 / 0.04,
                    ..Material::default()
                }
            }
            other => {
                self.warn(format!(
                    "{}: bsdf type '{other}' not supported; grey diffuse used",
                    self.at(node)
                ));
                Material::lambert(&name, Vec3::splat(0.5))
            }
        };
        m.name = name;
        Ok(m)
    }

    /// An index of refraction given as a number or a Mitsuba material name.
    fn ior(&mut self, node: &Element, name: &str, default: f32) -> Result<f32, SceneError> {
        if let Some(text) = self.string(node, name) {
            let known = match text.to_ascii_lowercase().as_str() {
                "vacuum" => Some(1.0),
                "air" => Some(1.000277),
                "water" => Some(1.333),
                "acrylic glass" | "polypropylene" => Some(1.49),
                "bk7" => Some(1.5046),
                "diamond" => Some(2.419),
                _ => None,
            };
            return Ok(known.unwrap_or_else(|| {
                self.warn(format!(
                    "index of refraction '{text}' unknown; {default} used"
                ));
                default
            }));
        }
        let v = self.float(node, name, default)?;
        Ok(if v.is_finite() && v > 0.0 { v } else { default })
    }

    fn transform(&self, node: &Element, name: &str) -> Result<Mat4, SceneError> {
        let Some(t) = node.children().find(|c| {
            c.tag() == "transform" && c.attribute("name").is_some_and(|n| same_name(n, name))
        }) else {
            return Ok(Mat4::IDENTITY);
        };
        let mut m = Mat4::IDENTITY;
        for op in t.children() {
            let bad = |message: String| self.err(format!("{}: {message}", self.at(op)));
            let xyz = |default: f32| -> Result<Vec3, SceneError> {
                if let Some(value) = op.attribute("value") {
                    let v = numbers(value).map_err(&bad)?;
                    return match v.as_slice() {
                        [s] => Ok(Vec3::splat(*s)),
                        [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                        _ => Err(bad(format!("'{value}' needs 1 or 3 numbers"))),
                    };
                }
                let get = |k: &str| -> Result<f32, SceneError> {
                    op.attribute(k).map_or(Ok(default), |s| {
                        s.trim()
                            .parse()
                            .map_err(|_| bad(format!("{k}='{s}' is not a number")))
                    })
                };
                Ok(Vec3::new(get("x")?, get("y")?, get("z")?))
            };
            let vector = |key: &str| -> Result<Vec3, SceneError> {
                let text = op.attribute(key).unwrap_or("");
                match numbers(text).map_err(&bad)?.as_slice() {
                    [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                    _ => Err(bad(format!("{key}='{text}' needs 3 numbers"))),
                }
            };
            let step = match op.tag() {
                "matrix" => {
                    let value = op.attribute("value").unwrap_or("");
                    let v = numbers(value).map_err(&bad)?;
                    if v.len() != 16 {
                        return Err(bad(format!("matrix needs 16 numbers, found {}", v.len())));
                    }
                    // Row-major in the file.
                    Mat4::from_cols_array(&[
                        v[0], v[4], v[8], v[12], v[1], v[5], v[9], v[13], v[2], v[6], v[10], v[14],
                        v[3], v[7], v[11], v[15],
                    ])
                }
                "translate" => Mat4::from_translation(xyz(0.0)?),
                "scale" => Mat4::from_scale(xyz(1.0)?),
                "rotate" => {
                    let axis = xyz(0.0)?;
                    let angle: f32 = op
                        .attribute("angle")
                        .unwrap_or("0")
                        .trim()
                        .parse()
                        .map_err(|_| bad("rotate angle is not a number".into()))?;
                    let axis = axis
                        .try_normalize()
                        .ok_or_else(|| bad("rotate axis is zero".into()))?;
                    Mat4::from_axis_angle(axis, angle.to_radians())
                }
                "lookat" => {
                    let origin = vector("origin")?;
                    let target = vector("target")?;
                    let up = if op.attribute("up").is_some() {
                        vector("up")?
                    } else {
                        Vec3::Y
                    };
                    // Mitsuba's frame: columns left, up, forward (z looks at the target).
                    let forward = (target - origin)
                        .try_normalize()
                        .ok_or_else(|| bad("lookat target equals origin".into()))?;
                    let left = up
                        .cross(forward)
                        .try_normalize()
                        .ok_or_else(|| bad("lookat up is parallel to the view".into()))?;
                    let up = forward.cross(left);
                    Mat4::from_cols(
                        left.extend(0.0),
                        up.extend(0.0),
                        forward.extend(0.0),
                        origin.extend(1.0),
                    )
                }
                other => return Err(bad(format!("transform step <{other}> not supported"))),
            };
            m = step * m;
        }
        if !m.is_finite() || m.determinant().abs() < 1e-20 {
            return Err(self.err(format!(
                "{}: transform '{name}' is singular or not finite",
                self.at(t)
            )));
        }
        Ok(m)
    }

    fn shape(&mut self, node: &Element) -> Result<(), SceneError> {
        let kind = node.attribute("type").unwrap_or("");
        let at = self.at(node);
        let world_from_model = self.transform(node, "toWorld")?;
        // A shape names its BSDF and, in Mitsuba 3, its area emitter by `<ref id>` (either
        // order) or nests them.
        let mut material = None;
        let mut radiance = None;
        for child in node.children() {
            match child.tag() {
                "bsdf" if material.is_none() => material = Some(self.bsdf(child)?),
                "emitter" => {
                    if child.attribute("type") == Some("area") {
                        radiance = Some(self.area_radiance(child)?);
                    } else {
                        self.warn(format!(
                            "{at}: shape emitter type {:?} not supported; ignored",
                            child.attribute("type")
                        ));
                    }
                }
                "ref" => {
                    let id = child.attribute("id").unwrap_or("");
                    if let Some(r) = self.area_emitters.get(id) {
                        radiance = Some(*r);
                    } else if material.is_none() {
                        material = Some(match self.bsdfs.get(id) {
                            Some(m) => m.clone(),
                            None => {
                                self.warn(format!(
                                    "{}: '{id}' is not a bsdf or area emitter of the scene; \
                                     grey diffuse used",
                                    self.at(child)
                                ));
                                Material::lambert(id, Vec3::splat(0.5))
                            }
                        });
                    }
                }
                _ => {}
            }
        }
        let mut material =
            material.unwrap_or_else(|| Material::lambert("default diffuse", Vec3::splat(0.5)));
        if let Some(radiance) = radiance {
            material.emissive = radiance;
            material.name = format!("{} (emitter)", material.name);
        }
        let face_normals = property(node, "boolean", "faceNormals")
            .and_then(|p| p.attribute("value"))
            == Some("true");
        let mut meshes: Vec<Mesh> = match kind {
            "obj" | "ply" => {
                let file = self.string(node, "filename").unwrap_or("").to_string();
                if !self.has_base_dir {
                    self.warn(format!("{at}: mesh '{file}' skipped (no base folder)"));
                    return Ok(());
                }
                let path = match self.document.resolve(node, &file, "mesh", self.policy) {
                    Ok(p) => p,
                    Err(m) if m.starts_with("missing") => {
                        self.warn(format!("{at}: {m}; shape skipped"));
                        return Ok(());
                    }
                    Err(m) => return Err(self.err(format!("{at}: {m}"))),
                };
                if let Some(known) = self.mesh_files.get(&path) {
                    known.clone()
                } else {
                    // A referenced mesh's own error is reported inside this file's, at its
                    // shape.
                    let nested = |e: SceneError| self.err(format!("{at}: {e}"));
                    let loaded: Vec<Mesh> = if kind == "ply" {
                        vec![super::ply::load_mesh(&path).map_err(nested)?]
                    } else {
                        let shown = path.display().to_string();
                        let bytes = files::read_regular_file(&path)
                            .map_err(|m| self.err(format!("{at}: {shown}: {m}")))?;
                        let geometry = super::obj::read_geometry(&bytes, &shown).map_err(nested)?;
                        self.scene.warnings.extend(geometry.warnings);
                        geometry.meshes.into_iter().map(|(_, m)| m).collect()
                    };
                    self.mesh_files.insert(path.clone(), loaded.clone());
                    loaded
                }
            }
            "rectangle" => vec![quad_mesh(
                [
                    Vec3::new(-1.0, -1.0, 0.0),
                    Vec3::new(1.0, -1.0, 0.0),
                    Vec3::new(1.0, 1.0, 0.0),
                    Vec3::new(-1.0, 1.0, 0.0),
                ],
                "rectangle",
            )],
            "cube" => vec![cube_mesh()],
            "sphere" => {
                let centre = property(node, "point", "center")
                    .map(|p| {
                        let get = |k: &str| p.attribute(k).and_then(|s| s.trim().parse().ok());
                        Vec3::new(
                            get("x").unwrap_or(0.0),
                            get("y").unwrap_or(0.0),
                            get("z").unwrap_or(0.0),
                        )
                    })
                    .unwrap_or(Vec3::ZERO);
                let radius = self.float(node, "radius", 1.0)?;
                if !(radius.is_finite() && radius > 0.0) {
                    return Err(self.err(format!("{at}: sphere radius {radius} is not positive")));
                }
                let mut sphere =
                    super::builtin::procedural::icosphere("sphere", 0, radius, radius * 0.3, false);
                for p in &mut sphere.positions {
                    *p += centre;
                }
                vec![sphere]
            }
            other => {
                self.warn(format!("{at}: shape type '{other}' not supported; skipped"));
                return Ok(());
            }
        };
        self.scene.materials.push(material);
        let material = self.scene.materials.len() - 1;
        let stem = match self.string(node, "filename") {
            Some(f) => f.to_string(),
            None => kind.to_string(),
        };
        self.triangles += meshes.iter().map(Mesh::triangle_count).sum::<usize>();
        if self.triangles > MAX_SCENE_TRIANGLES {
            return Err(self.err(format!(
                "{at}: the shapes place more than {MAX_SCENE_TRIANGLES} triangles"
            )));
        }
        for mut mesh in meshes.drain(..) {
            bake_transform(&mut mesh, world_from_model, face_normals);
            if mesh.indices.is_empty() {
                continue;
            }
            mesh.material = material;
            mesh.name = stem.clone();
            self.scene.meshes.push(mesh);
            self.scene.instances.push(Instance {
                mesh: self.scene.meshes.len() - 1,
                node: 0,
            });
        }
        Ok(())
    }

    fn sensor(&mut self, node: &Element) -> Result<(), SceneError> {
        let at = self.at(node);
        if node.attribute("type") != Some("perspective") {
            self.warn(format!(
                "{at}: sensor type {:?} not supported; skipped",
                node.attribute("type")
            ));
            return Ok(());
        }
        let world_from_camera = self.transform(node, "toWorld")?;
        // The film's size is checked but does not size the render: `--width`/`--height` do,
        // as for every scene format, and the field of view keeps its angle along `fov_axis`
        // of that image (at the film's aspect this is Mitsuba's framing exactly).
        if let Some(film) = node.children().find(|c| c.tag() == "film") {
            let width = self.float(film, "width", 768.0)?;
            let height = self.float(film, "height", 576.0)?;
            if !(width >= 1.0 && height >= 1.0 && width.is_finite() && height.is_finite()) {
                return Err(self.err(format!("{at}: film size {width} × {height} is not valid")));
            }
        }
        let fov = self.float(node, "fov", f32::NAN)?;
        let (fov_degrees, fov_axis) = if fov.is_finite() {
            let axis = self.string(node, "fovAxis").unwrap_or("x");
            let fov_axis = match axis {
                "x" => FovAxis::Horizontal,
                "y" => FovAxis::Vertical,
                "smaller" => FovAxis::Smaller,
                "larger" => FovAxis::Larger,
                "diagonal" => FovAxis::Diagonal,
                other => {
                    return Err(self.err(format!(
                        "{at}: fov_axis '{other}' unknown (x, y, smaller, larger, diagonal)"
                    )))
                }
            };
            (fov, fov_axis)
        } else {
            // Mitsuba also accepts a 35 mm-equivalent focal length.
            let focal = self
                .string(node, "focalLength")
                .and_then(|s| s.trim_end_matches("mm").parse::<f32>().ok())
                .unwrap_or(50.0);
            let diagonal = 2.0 * (43.266_f32 / (2.0 * focal)).atan().to_degrees();
            self.warn(format!(
                "{at}: focal length {focal} mm read as a {diagonal:.1}° diagonal fov"
            ));
            (diagonal, FovAxis::Diagonal)
        };
        if !(fov_degrees > 0.0 && fov_degrees < 180.0) {
            return Err(self.err(format!(
                "{at}: fov {fov_degrees}° is outside (0, 180) degrees"
            )));
        }
        let znear = self.float(node, "nearClip", 1e-2)?;
        let zfar = self.float(node, "farClip", 1e4)?;
        // Mitsuba's camera looks down +z with +x to the left; valgi's looks down −z with +x to
        // the right: a half turn about y.
        let world_from_view = world_from_camera * Mat4::from_rotation_y(std::f32::consts::PI);
        let (_, rotation, translation) = world_from_view.to_scale_rotation_translation();
        let node_index = self.scene.nodes.len();
        let name = format!("camera{}", self.scene.cameras.len());
        self.scene.nodes.push(Node {
            name: name.clone(),
            parent: None,
            local: Trs {
                translation,
                rotation: rotation.normalize(),
                scale: Vec3::ONE,
            },
        });
        self.scene.cameras.push(Camera {
            name,
            node: node_index,
            yfov: fov_degrees.to_radians(),
            fov_axis,
            aspect: None,
            znear,
            zfar: Some(zfar),
        });
        Ok(())
    }

    /// The radiance of an `area` emitter, W/(m²·sr) (1 when absent, Mitsuba's default).
    fn area_radiance(&mut self, node: &Element) -> Result<Vec3, SceneError> {
        Ok(self
            .colour(node, "radiance", Quantity::Emission)?
            .unwrap_or(Vec3::ONE))
    }

    fn emitter(&mut self, node: &Element) -> Result<(), SceneError> {
        let at = self.at(node);
        let kind = node.attribute("type").unwrap_or("").to_string();
        let world_from_light = self.transform(node, "toWorld")?;
        let position = property(node, "point", "position").map(|p| {
            let get = |k: &str| {
                p.attribute(k)
                    .and_then(|s| s.trim().parse().ok())
                    .unwrap_or(0.0)
            };
            Vec3::new(get("x"), get("y"), get("z"))
        });
        let (light_kind, power, forward) = match kind.as_str() {
            "point" => (
                LightKind::Point,
                self.colour(node, "intensity", Quantity::Emission)?
                    .unwrap_or(Vec3::ONE),
                Vec3::NEG_Z,
            ),
            "spot" => {
                let cutoff = self.float(node, "cutoffAngle", 20.0)?;
                let beam = self.float(node, "beamWidth", cutoff * 0.75)?;
                (
                    LightKind::Spot {
                        inner_cone_angle: beam.to_radians(),
                        outer_cone_angle: cutoff.to_radians(),
                    },
                    self.colour(node, "intensity", Quantity::Emission)?
                        .unwrap_or(Vec3::ONE),
                    world_from_light.transform_vector3(Vec3::Z),
                )
            }
            "directional" => {
                let direction = property(node, "vector", "direction")
                    .map(|p| {
                        let get = |k: &str| {
                            p.attribute(k)
                                .and_then(|s| s.trim().parse().ok())
                                .unwrap_or(0.0)
                        };
                        Vec3::new(get("x"), get("y"), get("z"))
                    })
                    .unwrap_or_else(|| world_from_light.transform_vector3(Vec3::Z));
                (
                    LightKind::Directional,
                    self.colour(node, "irradiance", Quantity::Emission)?
                        .unwrap_or(Vec3::ONE),
                    direction,
                )
            }
            other => {
                self.warn(format!(
                    "{at}: emitter type '{other}' not supported; skipped"
                ));
                return Ok(());
            }
        };
        let origin = position.unwrap_or_else(|| world_from_light.transform_point3(Vec3::ZERO));
        let Some(forward) = forward.try_normalize() else {
            self.warn(format!("{at}: emitter direction is zero; skipped"));
            return Ok(());
        };
        let node_index = self.scene.nodes.len();
        let name = format!("{kind}{}", self.scene.lights.len());
        self.scene.nodes.push(Node {
            name: name.clone(),
            parent: None,
            local: Trs {
                translation: origin,
                rotation: Quat::from_rotation_arc(Vec3::NEG_Z, forward),
                scale: Vec3::ONE,
            },
        });
        let peak = power.max_element().max(0.0);
        self.scene.lights.push(Light {
            name,
            node: node_index,
            kind: light_kind,
            color: if peak > 0.0 { power / peak } else { Vec3::ONE },
            intensity: peak,
            range: None,
        });
        Ok(())
    }
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Reflectance at normal incidence of a conductor with complex index η + ik, per channel.
pub fn fresnel_conductor(eta: Vec3, k: Vec3) -> Vec3 {
    let k2 = k * k;
    ((eta - 1.0) * (eta - 1.0) + k2) / ((eta + 1.0) * (eta + 1.0) + k2)
}

/// η and k (RGB) of a few of Mitsuba's named conductors (from its bundled spectral data).
fn conductor_table(name: &str) -> Option<(Vec3, Vec3)> {
    Some(match name {
        "Cu" => (
            Vec3::new(0.200, 0.924, 1.102),
            Vec3::new(3.912, 2.452, 2.142),
        ),
        "Au" => (
            Vec3::new(0.143, 0.374, 1.442),
            Vec3::new(3.983, 2.385, 1.603),
        ),
        "Ag" => (
            Vec3::new(0.155, 0.117, 0.138),
            Vec3::new(4.828, 3.122, 2.147),
        ),
        "Al" => (
            Vec3::new(1.657, 0.880, 0.521),
            Vec3::new(9.224, 6.270, 4.837),
        ),
        "none" => (Vec3::ZERO, Vec3::splat(1e6)),
        _ => return None,
    })
}

fn quad_mesh(corners: [Vec3; 4], name: &str) -> Mesh {
    let normal = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .normalize();
    Mesh {
        name: name.into(),
        positions: corners.to_vec(),
        normals: vec![normal; 4],
        tangents: vec![],
        uv0: vec![
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 0.0),
        ],
        uv1: None,
        indices: vec![0, 1, 2, 0, 2, 3],
        material: 0,
    }
}

/// [−1, 1]³ with outward faces.
fn cube_mesh() -> Mesh {
    let mut mesh = Mesh {
        name: "cube".into(),
        ..Mesh::default()
    };
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let n = Vec3::AXES[axis] * sign;
            let u = Vec3::AXES[(axis + 1) % 3];
            let v = Vec3::AXES[(axis + 2) % 3];
            let (u, v) = if sign > 0.0 { (u, v) } else { (v, u) };
            let base = mesh.positions.len() as u32;
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                mesh.positions.push(n + u * a + v * b);
                mesh.normals.push(n);
                mesh.uv0.push(Vec2::new((a + 1.0) * 0.5, (1.0 - b) * 0.5));
            }
            mesh.indices
                .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    mesh
}

/// Moves a model-space mesh into world space: positions by `m`, normals by its inverse
/// transpose, and the winding reversed when `m` mirrors, so faces keep facing the same way.
/// With `face_normals` every triangle gets its own vertices and its geometric normal.
fn bake_transform(mesh: &mut Mesh, m: Mat4, face_normals: bool) {
    let normal_matrix = Mat3::from_mat4(m).inverse().transpose();
    for p in &mut mesh.positions {
        *p = m.transform_point3(*p);
    }
    for n in &mut mesh.normals {
        *n = (normal_matrix * *n).normalize_or(Vec3::Y);
    }
    if m.determinant() < 0.0 {
        for t in mesh.indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
    }
    remove_degenerate_triangles(&mesh.positions, &mut mesh.indices);
    if face_normals {
        let mut flat = Mesh {
            name: mesh.name.clone(),
            material: mesh.material,
            ..Mesh::default()
        };
        let has_uv = mesh.uv0.len() == mesh.positions.len();
        for t in mesh.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize);
            let (pa, pb, pc) = (mesh.positions[a], mesh.positions[b], mesh.positions[c]);
            let n = (pb - pa).cross(pc - pa).normalize_or(Vec3::Y);
            for i in [a, b, c] {
                flat.indices.push(flat.positions.len() as u32);
                flat.positions.push(mesh.positions[i]);
                flat.normals.push(n);
                flat.uv0.push(if has_uv { mesh.uv0[i] } else { Vec2::ZERO });
            }
        }
        *mesh = flat;
    } else if mesh.normals.len() != mesh.positions.len() {
        mesh.normals = compute_normals(&mesh.positions, &mesh.indices);
    }
    if mesh.uv0.len() != mesh.positions.len() {
        mesh.uv0 = vec![Vec2::ZERO; mesh.positions.len()];
    }
    mesh.tangents.clear();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aluminium_reflects_about_ninety_percent() {
        let f0 = fresnel_conductor(
            Vec3::new(1.65746, 0.880369, 0.521229),
            Vec3::new(9.22387, 6.26952, 4.837),
        );
        assert!(f0.min_element() > 0.85 && f0.max_element() < 0.97, "{f0}");
    }

    #[test]
    fn camera_frame_and_fov_follow_mitsuba_conventions() {
        let xml = br#"<scene version="0.5.0">
            <sensor type="perspective">
                <float name="fov" value="90"/>
                <transform name="toWorld"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
                <film type="ldrfilm"><integer name="width" value="200"/><integer name="height" value="100"/></film>
            </sensor>
            <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="2, 3, 4"/></emitter></shape>
        </scene>"#;
        let scene = parse(xml, "s.xml", None, ReadPolicy::default()).unwrap();
        let view = scene
            .camera_view(None, 2.0, &scene.world_from_node())
            .unwrap();
        assert!((view.position() - Vec3::new(0.0, 0.0, 5.0)).length() < 1e-5);
        // valgi looks down −z of the view: toward the target.
        let forward = view.world_from_view.transform_vector3(Vec3::NEG_Z);
        assert!((forward - Vec3::NEG_Z).length() < 1e-5, "{forward}");
        // Mitsuba's +x is the image's left: from +z looking at −z, the right is +x.
        let right = view.world_from_view.transform_vector3(Vec3::X);
        assert!((right - Vec3::X).length() < 1e-5, "{right}");
        // 90° horizontal at 2:1 → tan(yfov/2) = 0.5.
        assert!(
            ((view.yfov * 0.5).tan() - 0.5).abs() < 1e-5,
            "{}",
            view.yfov
        );
        let m = &scene.materials[scene.meshes[0].material];
        assert_eq!(m.emissive, Vec3::new(2.0, 3.0, 4.0));
        // The rectangle faces +z (toward the camera) and spans [−1, 1]².
        assert!(scene.meshes[0].normals.iter().all(|n| *n == Vec3::Z));
    }

    #[test]
    fn fov_axis_keeps_its_angle_on_its_axis_at_any_aspect() {
        for (axis, expected) in [
            ("x", FovAxis::Horizontal),
            ("y", FovAxis::Vertical),
            ("smaller", FovAxis::Smaller),
            ("larger", FovAxis::Larger),
            ("diagonal", FovAxis::Diagonal),
        ] {
            let xml = format!(
                r#"<scene version="3.0.0"><sensor type="perspective">
                    <float name="fov" value="40"/><string name="fov_axis" value="{axis}"/>
                    <film type="hdrfilm"><integer name="width" value="64"/></film>
                </sensor></scene>"#
            );
            let scene = parse(xml.as_bytes(), "s.xml", None, ReadPolicy::default()).unwrap();
            let camera = &scene.cameras[0];
            assert_eq!(camera.fov_axis, expected);
            let tan_fov = 20f32.to_radians().tan();
            for aspect in [0.5f32, 1.0, 16.0 / 9.0] {
                let tan_y = (camera.vertical_fov(aspect) * 0.5).tan();
                let tan_x = tan_y * aspect;
                let along = match expected {
                    FovAxis::Horizontal => tan_x,
                    FovAxis::Vertical => tan_y,
                    FovAxis::Smaller => tan_x.min(tan_y),
                    FovAxis::Larger => tan_x.max(tan_y),
                    FovAxis::Diagonal => (tan_x * tan_x + tan_y * tan_y).sqrt(),
                };
                assert!(
                    (along - tan_fov).abs() < 1e-5,
                    "{axis} at {aspect}: {along}"
                );
            }
        }
        let bad = br#"<scene><sensor type="perspective"><float name="fov" value="40"/>
            <string name="fov_axis" value="z"/></sensor></scene>"#;
        let err = parse(bad, "s.xml", None, ReadPolicy::default()).unwrap_err();
        assert!(err.to_string().contains("fov_axis 'z' unknown"), "{err}");
    }

    #[test]
    fn top_level_area_emitters_light_the_shapes_that_reference_them() {
        let xml = br#"<scene version="3.0.0">
            <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="0.3"/></bsdf>
            <emitter type="area"><rgb name="radiance" value="9"/></emitter>
            <shape type="rectangle"><ref id="lamp"/><ref id="grey"/></shape>
            <shape type="rectangle"><ref id="grey"/></shape>
            <shape type="rectangle"><ref id="nothing"/>
                <emitter type="area"><spectrum name="radiance" value="2"/></emitter></shape>
            <emitter type="area" id="lamp"><rgb name="radiance" value="1, 2, 3"/></emitter>
        </scene>"#;
        let scene = parse(xml, "s.xml", None, ReadPolicy::default()).unwrap();
        let material = |i: usize| &scene.materials[scene.meshes[i].material];
        // Either order of the references, the emitter defined after the shape; a single-number
        // spectrum is that grey.
        assert_eq!(material(0).emissive, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(material(0).base_color.truncate(), Vec3::splat(0.3));
        assert_eq!(material(1).emissive, Vec3::ZERO);
        assert_eq!(material(2).emissive, Vec3::splat(2.0));
        let warnings = scene.warnings.join("\n");
        assert!(warnings.contains("without an id"), "{warnings}");
        assert!(
            warnings.contains("'nothing' is not a bsdf or area emitter"),
            "{warnings}"
        );
    }

    #[test]
    fn sampled_spectra_become_linear_srgb_by_what_they_measure() {
        // A flat reflectance is its grey; the same flat spectrum as radiance is equal-energy
        // white, reddish in sRGB, with luminance equal to its value.
        let xml = br#"<scene version="3.0.0">
            <shape type="rectangle">
                <bsdf type="diffuse"><spectrum name="reflectance" value="400:0.5, 700:0.5"/></bsdf>
                <emitter type="area"><spectrum name="radiance" value="360:4, 830:4"/></emitter>
            </shape>
            <shape type="rectangle">
                <bsdf type="diffuse"><spectrum name="reflectance" value="400:0.5, 700:x"/></bsdf>
            </shape>
        </scene>"#;
        let err = parse(xml, "s.xml", None, ReadPolicy::default()).unwrap_err();
        assert!(
            err.to_string().contains("line 7: spectrum 'reflectance'"),
            "{err}"
        );
        let xml = String::from_utf8_lossy(xml).replace("700:x", "700:0.5");
        let scene = parse(xml.as_bytes(), "s.xml", None, ReadPolicy::default()).unwrap();
        let m = &scene.materials[scene.meshes[0].material];
        assert!(
            (m.base_color.truncate() - Vec3::splat(0.5))
                .abs()
                .max_element()
                < 1e-6
        );
        assert!(
            (spectrum::luminance(m.emissive) - 4.0).abs() < 0.01,
            "{}",
            m.emissive
        );
        assert!(m.emissive.x > m.emissive.y && m.emissive.y > m.emissive.z);
    }

    #[test]
    fn mitsuba_3_snake_case_names_read_like_mitsuba_0_5_ones() {
        let xml = br#"<scene version="3.0.0">
            <default name="dx" value="2"/>
            <shape type="rectangle">
                <transform name="to_world"><translate x="$dx" y="0" z="0"/></transform>
                <bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/>
                    <float name="int_ior" value="1.5"/></bsdf>
            </shape>
        </scene>"#;
        let scene = parse(xml, "s.xml", None, ReadPolicy::default()).unwrap();
        let xs: Vec<f32> = scene.meshes[0].positions.iter().map(|p| p.x).collect();
        assert_eq!(xs, vec![1.0, 3.0, 3.0, 1.0]);
        let m = &scene.materials[0];
        assert_eq!(m.base_color.truncate(), Vec3::new(0.1, 0.2, 0.3));
        // F0 of η = 1.5 / 1.000277.
        let f0 = ((1.5f32 / 1.000277 - 1.0) / (1.5 / 1.000277 + 1.0)).powi(2);
        assert!(
            (m.specular_factor - f0 / 0.04).abs() < 1e-4,
            "{}",
            m.specular_factor
        );
        // An override wins over the file's default.
        let scene = parse_with_parameters(
            xml,
            "s.xml",
            None,
            ReadPolicy::default(),
            &[("dx".into(), "10".into())],
        )
        .unwrap();
        assert_eq!(scene.meshes[0].positions[0].x, 9.0);
    }

    #[test]
    fn transforms_compose_in_order_and_mirroring_keeps_facing() {
        let xml = br#"<scene version="0.5.0">
            <shape type="rectangle">
                <transform name="toWorld">
                    <scale x="-2"/>
                    <translate x="1" y="0" z="0"/>
                </transform>
            </shape>
        </scene>"#;
        let scene = parse(xml, "t.xml", None, ReadPolicy::default()).unwrap();
        let mesh = &scene.meshes[0];
        let xs: Vec<f32> = mesh.positions.iter().map(|p| p.x).collect();
        assert_eq!(xs, vec![3.0, -1.0, -1.0, 3.0]);
        let t = &mesh.indices[..3];
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| mesh.positions[i as usize]);
        let geometric = (b - a).cross(c - a).normalize();
        assert!((geometric - Vec3::Z).length() < 1e-6, "{geometric}");
        assert!((mesh.normals[0] - Vec3::Z).length() < 1e-6);
    }

    #[test]
    fn malformed_files_are_errors_naming_the_line() {
        for (xml, needle) in [
            (&b"<scene><shape"[..], "malformed XML"),
            (b"<mesh/>", "not a Mitsuba scene"),
            (
                b"<scene>\n<shape type=\"cube\"><transform name=\"toWorld\"><matrix value=\"1 2\"/></transform></shape></scene>",
                "line 2: matrix needs 16 numbers",
            ),
            (
                b"<scene><shape type=\"cube\"><transform name=\"toWorld\"><scale value=\"0\"/></transform></shape></scene>",
                "singular",
            ),
            (
                b"<!DOCTYPE x [<!ENTITY a \"aaaa\">]><scene>&a;</scene>",
                "malformed XML",
            ),
        ] {
            let err = parse(xml, "bad.xml", None, ReadPolicy::default())
                .unwrap_err()
                .to_string();
            assert!(err.starts_with("bad.xml: ") && err.contains(needle), "{needle}: {err}");
        }
    }
}
