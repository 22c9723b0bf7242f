//! glTF 2.0 import (`.gltf` with external or embedded buffers, and `.glb`) into [`Scene`].
//!
//! The `gltf` crate parses and validates the JSON document, but everything that touches bytes is
//! done here: the GLB container, buffer and image loading, and accessor reads. The crate's own
//! helpers assume well-formed input (they `unwrap` and index slices after only partial checks),
//! and this importer must turn *any* bad file into a [`SceneError`] that names the file and the
//! problem, never a panic.
//!
//! What is read: the node forest of the default scene (flattened, parents first), triangle
//! primitives with positions, normals, tangents, TEXCOORD_0/1, metallic-roughness materials with
//! KHR_materials_emissive_strength and KHR_materials_specular, textures (decoded to RGBA8),
//! KHR_lights_punctual lights, perspective cameras and TRS animations. Lights keep the file's
//! numbers: `intensity × color` is taken as W/sr or W/m² (DESIGN §3), no photometric conversion.

use super::files::{self, ReadPolicy};
use super::mesh::{
    compute_normals, compute_tangents, remove_degenerate_triangles, validate_positions,
};
use super::sanitize;
use super::{
    Animation, Camera, Channel, ColorSpace, FovAxis, Instance, Interpolation, Light, LightKind,
    Material, Mesh, Node, Property, Scene, SceneError, Texture, Trs,
};
use glam::{Mat4, Quat, Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Extensions whose data valgi reads. Anything else that a file *requires* is refused; anything
/// else it merely *uses* is ignored with a warning (the file still renders, minus that feature).
pub const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_specular",
];

/// Most elements an accessor without a buffer view (zeros plus sparse substitutions) may
/// declare: its memory is not backed by the file, so the count alone would size the
/// allocation (2²⁴ VEC4 floats are 256 MiB).
pub const MAX_VIEWLESS_ELEMENTS: usize = 1 << 24;

/// Loads a `.gltf` or `.glb` file with the default [`ReadPolicy`]: external buffers and
/// images must be regular files inside the file's folder. The scene is named after the file
/// stem.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    load_with(path, ReadPolicy::default())
}

/// Loads a `.gltf` or `.glb` file; external buffers and images resolve relative to the file's
/// folder under `policy`.
pub fn load_with(path: &Path, policy: ReadPolicy) -> Result<Scene, SceneError> {
    let file = files::read_scene_file(path, |path, message| SceneError::Gltf { path, message })?;
    load_from_slice_with(&file.bytes, Some(&file.base_dir), &file.display, policy)
}

/// Loads glTF from memory. `base_dir` resolves relative buffer / image URIs (`None`: only
/// embedded `data:` URIs and the GLB binary chunk are allowed); `display_path` names the source
/// in errors and warnings, and its file stem names the scene.
pub fn load_from_slice(
    bytes: &[u8],
    base_dir: Option<&Path>,
    display_path: &str,
) -> Result<Scene, SceneError> {
    load_from_slice_with(bytes, base_dir, display_path, ReadPolicy::default())
}

/// [`load_from_slice`] with an explicit policy for external references.
pub fn load_from_slice_with(
    bytes: &[u8],
    base_dir: Option<&Path>,
    display_path: &str,
    policy: ReadPolicy,
) -> Result<Scene, SceneError> {
    let mut importer = Importer::new(bytes, base_dir, display_path)?;
    importer.policy = policy;
    importer.import()?;
    let mut scene = importer.scene;
    sanitize::sanitize(&mut scene, display_path);
    scene.warnings = collapse_repeats(std::mem::take(&mut scene.warnings));
    Ok(scene)
}

/// Splits a GLB container into its JSON and optional BIN chunks (glTF 2.0 §4.4), checking every
/// length against the data actually present.
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), String> {
    let u32_at = |offset: usize| -> Option<u32> {
        bytes
            .get(offset..offset + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let version = u32_at(4).ok_or("GLB header truncated")?;
    if version != 2 {
        return Err(format!("GLB version {version} is not supported (only 2)"));
    }
    let declared = u32_at(8).ok_or("GLB header truncated")? as usize;
    if declared > bytes.len() {
        return Err(format!(
            "GLB truncated: header declares {declared} bytes, file has {}",
            bytes.len()
        ));
    }
    let data = &bytes[..declared.max(12).min(bytes.len())];
    let mut offset = 12;
    let mut json = None;
    let mut bin = None;
    while offset + 8 <= data.len() {
        let length = u32::from_le_bytes([
            data[offset],
            data[offset + 1],
            data[offset + 2],
            data[offset + 3],
        ]) as usize;
        let kind = &data[offset + 4..offset + 8];
        let start = offset + 8;
        let end = start
            .checked_add(length)
            .filter(|&e| e <= data.len())
            .ok_or_else(|| {
                format!(
                    "GLB chunk at byte {offset} declares {length} bytes past the end of the file"
                )
            })?;
        match kind {
            b"JSON" if json.is_none() => json = Some(&data[start..end]),
            b"BIN\0" if bin.is_none() => bin = Some(&data[start..end]),
            _ => {} // Unknown chunks must be ignored (spec).
        }
        offset = (end + 3) & !3;
    }
    let json = json.ok_or("GLB has no JSON chunk")?;
    Ok((json, bin))
}

/// Decodes standard base64 (with or without padding, ignoring whitespace).
fn decode_base64(text: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    let mut acc: u32 = 0;
    let mut bits = 0;
    for (i, c) in text.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return Err(format!("invalid base64 character at offset {i}")),
        };
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

/// Percent-decodes a relative URI (glTF URIs are RFC 3986 encoded: "my%20file.bin").
fn percent_decode(uri: &str) -> Result<String, String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("bad percent escape in URI '{uri}'"))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| format!("URI '{uri}' does not decode to UTF-8"))
}

/// Splits a `data:` URI into its payload bytes; `None` if `uri` is not a data URI.
fn data_uri(uri: &str) -> Option<Result<Vec<u8>, String>> {
    let rest = uri.strip_prefix("data:")?;
    Some(match rest.split_once(";base64,") {
        Some((_, payload)) => decode_base64(payload),
        None => Err("only base64 data URIs are supported".to_string()),
    })
}

fn json_error_message(e: &serde_json::Error) -> String {
    use serde_json::error::Category;
    match e.classify() {
        Category::Eof => format!(
            "truncated JSON (input ends at line {} column {})",
            e.line(),
            e.column()
        ),
        Category::Syntax => format!(
            "malformed JSON at line {} column {}: {e}",
            e.line(),
            e.column()
        ),
        Category::Data | Category::Io => format!("JSON does not match the glTF schema: {e}"),
    }
}

/// Which of a material's texture slots an image serves; decides its colour space.
fn slot_color_space(srgb: bool) -> ColorSpace {
    if srgb {
        ColorSpace::Srgb
    } else {
        ColorSpace::Linear
    }
}

struct Importer<'a> {
    display: String,
    base_dir: Option<PathBuf>,
    policy: ReadPolicy,
    raw: Value,
    document: gltf::Document,
    bin: Option<&'a [u8]>,
    buffers: Vec<Vec<u8>>,
    scene: Scene,
    /// glTF node index → index in `scene.nodes`.
    node_map: HashMap<usize, usize>,
    /// glTF mesh index → our meshes (one per triangle primitive), built on first use.
    mesh_map: HashMap<usize, Vec<usize>>,
    /// (glTF image index, colour space) → index in `scene.textures` (None: failed to load).
    texture_map: HashMap<(usize, bool), Option<usize>>,
    /// Index of the default material in `scene.materials`, appended on first use.
    default_material: Option<usize>,
}

impl<'a> Importer<'a> {
    fn new(bytes: &'a [u8], base_dir: Option<&Path>, display: &str) -> Result<Self, SceneError> {
        let gltf_err = |message: String| SceneError::Gltf {
            path: display.to_string(),
            message,
        };
        let (json, bin) = if bytes.starts_with(b"glTF") {
            split_glb(bytes).map_err(|m| gltf_err(format!("malformed GLB container: {m}")))?
        } else {
            (bytes, None)
        };
        if json.iter().all(|b| b.is_ascii_whitespace()) {
            return Err(gltf_err("empty file (no JSON)".into()));
        }
        let raw: Value =
            serde_json::from_slice(json).map_err(|e| gltf_err(json_error_message(&e)))?;
        if !raw.is_object() {
            return Err(gltf_err("top-level JSON value is not an object".into()));
        }

        // Extensions are checked on the raw JSON because the gltf crate refuses required
        // extensions it does not know (KHR_materials_specular among them) with a generic
        // validation error, and knows nothing of what valgi supports.
        let names = |key: &str| -> Vec<String> {
            raw.get(key)
                .and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_str().map(str::to_string))
                        .collect()
                })
                .unwrap_or_default()
        };
        let required = names("extensionsRequired");
        let unsupported: Vec<&str> = required
            .iter()
            .map(String::as_str)
            .filter(|e| !SUPPORTED_EXTENSIONS.contains(e))
            .collect();
        if !unsupported.is_empty() {
            return Err(SceneError::UnsupportedRequiredExtension {
                path: display.to_string(),
                extensions: unsupported.join(", "),
            });
        }
        let mut warnings = Vec::new();
        for ext in names("extensionsUsed") {
            if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
                warnings.push(format!(
                    "{display}: extension {ext} is not supported by valgi and is ignored"
                ));
            }
        }

        let mut root: gltf::json::Root = gltf::json::deserialize::from_slice(json)
            .map_err(|e| gltf_err(format!("JSON does not match the glTF schema: {e}")))?;
        // Already checked above against valgi's own list.
        root.extensions_required.clear();
        // gltf-json's primitive validation indexes `accessors[POSITION]` without a bounds check
        // (a panic on a dangling index) and rejects POSITION accessors without min/max, which
        // valgi does not need. Check the index here and fill in missing bounds so both cases
        // get the treatment they deserve: a clear error, and a successful load.
        let accessor_count = root.accessors.len();
        for (m, mesh) in root.meshes.iter().enumerate() {
            for (p, primitive) in mesh.primitives.iter().enumerate() {
                let position = primitive
                    .attributes
                    .get(&gltf::json::validation::Checked::Valid(
                        gltf::json::mesh::Semantic::Positions,
                    ));
                if let Some(index) = position {
                    if index.value() >= accessor_count {
                        return Err(gltf_err(format!(
                            "accessor {} out of range: meshes[{m}].primitives[{p}] POSITION \
                             refers to it but the file has {accessor_count} accessor(s)",
                            index.value()
                        )));
                    }
                }
            }
        }
        let position_accessors: Vec<usize> = root
            .meshes
            .iter()
            .flat_map(|mesh| mesh.primitives.iter())
            .filter_map(|primitive| {
                primitive
                    .attributes
                    .get(&gltf::json::validation::Checked::Valid(
                        gltf::json::mesh::Semantic::Positions,
                    ))
                    .map(|index| index.value())
            })
            .collect();
        for index in position_accessors {
            let accessor = &mut root.accessors[index];
            if accessor.min.is_none() || accessor.max.is_none() {
                accessor.min = Some(serde_json::json!([0.0, 0.0, 0.0]));
                accessor.max = Some(serde_json::json!([0.0, 0.0, 0.0]));
            }
        }
        let document = gltf::Document::from_json(root).map_err(|e| {
            gltf_err(match e {
                gltf::Error::Validation(errors) => {
                    let shown: Vec<String> = errors
                        .iter()
                        .take(5)
                        .map(|(path, err)| format!("{path}: {}", validation_message(err)))
                        .collect();
                    let more = errors.len().saturating_sub(shown.len());
                    format!(
                        "invalid glTF: {}{}",
                        shown.join("; "),
                        if more > 0 {
                            format!(" (and {more} more)")
                        } else {
                            String::new()
                        }
                    )
                }
                other => format!("invalid glTF: {other}"),
            })
        })?;

        let stem = Path::new(display)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| display.to_string());
        let scene = Scene {
            name: stem,
            warnings,
            ..Scene::default()
        };
        Ok(Self {
            display: display.to_string(),
            base_dir: base_dir.map(Path::to_path_buf),
            policy: ReadPolicy::default(),
            raw,
            document,
            bin,
            buffers: Vec::new(),
            scene,
            node_map: HashMap::new(),
            mesh_map: HashMap::new(),
            texture_map: HashMap::new(),
            default_material: None,
        })
    }

    fn err(&self, message: impl Into<String>) -> SceneError {
        SceneError::Gltf {
            path: self.display.clone(),
            message: message.into(),
        }
    }

    fn geometry_err(&self, what: &str, message: impl Into<String>) -> SceneError {
        SceneError::InvalidGeometry {
            path: self.display.clone(),
            what: what.to_string(),
            message: message.into(),
        }
    }

    /// Records a warning; the caller decides whether to print them (`valgi render` does).
    fn warn(&mut self, message: impl Into<String>) {
        let message = format!("{}: {}", self.display, message.into());
        self.scene.warnings.push(message);
    }

    fn import(&mut self) -> Result<(), SceneError> {
        self.load_buffers()?;
        self.load_materials();
        self.load_nodes()?;
        self.load_animations()?;
        if self.scene.instances.is_empty() {
            self.warn("the scene contains no triangle geometry");
        }
        Ok(())
    }

    /// Reads every buffer: the GLB binary chunk, embedded `data:` URIs, or files next to the
    /// glTF.
    fn load_buffers(&mut self) -> Result<(), SceneError> {
        let mut buffers = Vec::new();
        for buffer in self.document.buffers() {
            let index = buffer.index();
            let data = match buffer.source() {
                gltf::buffer::Source::Bin => self.bin.map(<[u8]>::to_vec).ok_or_else(|| {
                    self.err(format!(
                        "buffer {index} refers to the GLB binary chunk, which is missing"
                    ))
                })?,
                gltf::buffer::Source::Uri(uri) => self.read_uri(uri, "buffer")?,
            };
            let mut data = data;
            if data.len() < buffer.length() {
                return Err(self.err(format!(
                    "buffer {index} has {} bytes but declares byteLength {}",
                    data.len(),
                    buffer.length()
                )));
            }
            // Bytes past byteLength are not part of the buffer (GLB pads its chunk).
            data.truncate(buffer.length());
            buffers.push(data);
        }
        self.buffers = buffers;
        Ok(())
    }

    /// Reads a `data:` URI or a file relative to the glTF's folder.
    fn read_uri(&self, uri: &str, kind: &str) -> Result<Vec<u8>, SceneError> {
        if let Some(decoded) = data_uri(uri) {
            return decoded.map_err(|m| self.err(format!("embedded {kind} data: {m}")));
        }
        if uri.contains("://") {
            return Err(self.err(format!("{kind} URI '{uri}' is not a local file")));
        }
        let relative = percent_decode(uri).map_err(|m| self.err(m))?;
        let relative = relative.strip_prefix("file:").unwrap_or(&relative);
        let Some(base) = &self.base_dir else {
            return Err(self.err(format!(
                "external {kind} file '{uri}' cannot be resolved without a base folder"
            )));
        };
        files::read_reference(base, relative, kind, self.policy).map_err(|m| self.err(m))
    }

    // ----- accessors -------------------------------------------------------------------------

    /// The bytes of a buffer view, bounds-checked against its buffer.
    fn view_bytes(&self, view: &gltf::buffer::View) -> Result<&[u8], SceneError> {
        let buffer = view.buffer().index();
        let data = self.buffers.get(buffer).ok_or_else(|| {
            self.err(format!(
                "bufferView {} refers to missing buffer {buffer}",
                view.index()
            ))
        })?;
        let start = view.offset();
        start
            .checked_add(view.length())
            .and_then(|end| data.get(start..end))
            .ok_or_else(|| {
                self.err(format!(
                    "bufferView {} out of range: bytes {start}..{} of buffer {buffer}, which has {} bytes",
                    view.index(),
                    start.saturating_add(view.length()),
                    data.len()
                ))
            })
    }

    /// Reads an accessor as `f32` components, `expected` dimensions per element, applying the
    /// glTF normalization rules to integer data. `what` names the use in error messages.
    fn read_floats(
        &self,
        accessor: &gltf::Accessor,
        expected: &[Dimensions],
        what: &str,
    ) -> Result<(Vec<f32>, usize), SceneError> {
        let index = accessor.index();
        let dims = accessor.dimensions();
        if !expected.contains(&dims) {
            return Err(self.err(format!(
                "accessor {index} ({what}) has type {dims:?}, expected {expected:?}"
            )));
        }
        let n = dims.multiplicity();
        let count = accessor.count();
        let data_type = accessor.data_type();
        let normalized = accessor.normalized();
        let decode = move |b: &[u8]| -> f32 {
            match data_type {
                DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                DataType::U8 => {
                    let v = b[0] as f32;
                    if normalized {
                        v / 255.0
                    } else {
                        v
                    }
                }
                DataType::I8 => {
                    let v = b[0] as i8 as f32;
                    if normalized {
                        (v / 127.0).max(-1.0)
                    } else {
                        v
                    }
                }
                DataType::U16 => {
                    let v = u16::from_le_bytes([b[0], b[1]]) as f32;
                    if normalized {
                        v / 65535.0
                    } else {
                        v
                    }
                }
                DataType::I16 => {
                    let v = i16::from_le_bytes([b[0], b[1]]) as f32;
                    if normalized {
                        (v / 32767.0).max(-1.0)
                    } else {
                        v
                    }
                }
                DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
            }
        };
        self.check_extent(accessor, n * data_type.size(), what)?;
        let mut out = vec![0.0f32; count * n];
        self.read_elements(
            accessor,
            n,
            data_type.size(),
            what,
            &mut |i, bytes, size| {
                for c in 0..n {
                    out[i * n + c] = decode(&bytes[c * size..]);
                }
            },
        )?;
        Ok((out, n))
    }

    /// Reads an index accessor (unsigned scalar).
    fn read_indices(&self, accessor: &gltf::Accessor, what: &str) -> Result<Vec<u32>, SceneError> {
        let index = accessor.index();
        let data_type = accessor.data_type();
        if accessor.dimensions() != Dimensions::Scalar
            || !matches!(data_type, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(self.err(format!(
                "accessor {index} ({what}) must be an unsigned integer SCALAR, found {:?} {:?}",
                data_type,
                accessor.dimensions()
            )));
        }
        self.check_extent(accessor, data_type.size(), what)?;
        let mut out = vec![0u32; accessor.count()];
        self.read_elements(accessor, 1, data_type.size(), what, &mut |i, b, _| {
            out[i] = match data_type {
                DataType::U8 => b[0] as u32,
                DataType::U16 => u16::from_le_bytes([b[0], b[1]]) as u32,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            };
        })?;
        Ok(out)
    }

    /// Checks, before anything is allocated, that the accessor's dense data lies inside its
    /// buffer view, so a corrupt `count` fails with a message instead of a huge allocation.
    /// View-less accessors (all zeros plus sparse values) are capped at
    /// [`MAX_VIEWLESS_ELEMENTS`].
    fn check_extent(
        &self,
        accessor: &gltf::Accessor,
        element: usize,
        what: &str,
    ) -> Result<(), SceneError> {
        let index = accessor.index();
        let count = accessor.count();
        if count == 0 {
            return Ok(());
        }
        match accessor.view() {
            Some(view) => {
                let available = self.view_bytes(&view)?.len();
                let stride = view.stride().unwrap_or(element).max(element);
                let end = (count - 1)
                    .checked_mul(stride)
                    .and_then(|x| x.checked_add(accessor.offset()))
                    .and_then(|x| x.checked_add(element));
                match end {
                    Some(end) if end <= available => Ok(()),
                    _ => Err(self.err(format!(
                        "accessor {index} ({what}) out of range: {count} elements of {element} \
                         bytes (stride {stride}) from offset {} do not fit in bufferView {} of \
                         {available} bytes",
                        accessor.offset(),
                        view.index()
                    ))),
                }
            }
            None if count <= MAX_VIEWLESS_ELEMENTS => Ok(()),
            None => Err(self.err(format!(
                "accessor {index} ({what}) has no bufferView and an implausible count {count}"
            ))),
        }
    }

    /// Walks an accessor's elements (dense data, then sparse substitutions), calling
    /// `sink(element index, element bytes, component size)`. Every byte range is checked
    /// before it is touched; an accessor with no buffer view reads as zeros (glTF spec).
    fn read_elements(
        &self,
        accessor: &gltf::Accessor,
        components: usize,
        component_size: usize,
        what: &str,
        sink: &mut dyn FnMut(usize, &[u8], usize),
    ) -> Result<(), SceneError> {
        let index = accessor.index();
        let count = accessor.count();
        let element = components * component_size;
        if count == 0 {
            return Ok(());
        }
        let range_err =
            |detail: String| self.err(format!("accessor {index} ({what}) out of range: {detail}"));
        if let Some(view) = accessor.view() {
            let bytes = self.view_bytes(&view)?;
            let stride = view.stride().unwrap_or(element).max(element);
            let start = accessor.offset();
            let end = (count - 1)
                .checked_mul(stride)
                .and_then(|x| x.checked_add(start))
                .and_then(|x| x.checked_add(element));
            match end {
                Some(end) if end <= bytes.len() => {
                    for i in 0..count {
                        let at = start + i * stride;
                        sink(i, &bytes[at..at + element], component_size);
                    }
                }
                _ => {
                    return Err(range_err(format!(
                        "{count} elements of {element} bytes (stride {stride}) from offset {start} \
                         do not fit in bufferView {} of {} bytes",
                        view.index(),
                        bytes.len()
                    )))
                }
            }
        } else {
            let zeros = vec![0u8; element];
            for i in 0..count {
                sink(i, &zeros, component_size);
            }
        }
        if let Some(sparse) = accessor.sparse() {
            let n = sparse.count();
            if n == 0 {
                return Ok(());
            }
            let indices = sparse.indices();
            let index_size = indices.index_type().size();
            let index_bytes = self.view_bytes(&indices.view())?;
            let index_start = indices.offset();
            let values = sparse.values();
            let value_bytes = self.view_bytes(&values.view())?;
            let value_start = values.offset();
            let fits = |start: usize, size: usize, len: usize| {
                n.checked_mul(size)
                    .and_then(|x| x.checked_add(start))
                    .is_some_and(|end| end <= len)
            };
            if !fits(index_start, index_size, index_bytes.len())
                || !fits(value_start, element, value_bytes.len())
            {
                return Err(range_err(format!(
                    "sparse data for {n} elements does not fit its buffer views"
                )));
            }
            for k in 0..n {
                let b = &index_bytes[index_start + k * index_size..];
                let target = match index_size {
                    1 => b[0] as usize,
                    2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                    _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
                };
                if target >= count {
                    return Err(range_err(format!("sparse index {target} ≥ count {count}")));
                }
                let at = value_start + k * element;
                sink(target, &value_bytes[at..at + element], component_size);
            }
        }
        Ok(())
    }

    fn read_vec3s(&self, a: &gltf::Accessor, what: &str) -> Result<Vec<Vec3>, SceneError> {
        let (f, _) = self.read_floats(a, &[Dimensions::Vec3], what)?;
        Ok(f.chunks_exact(3).map(Vec3::from_slice).collect())
    }

    /// Texture coordinates may be float or normalized unsigned integers (glTF §3.7.2.1);
    /// [`Self::read_floats`] handles both.
    fn read_vec2s(&self, a: &gltf::Accessor, what: &str) -> Result<Vec<Vec2>, SceneError> {
        let (f, _) = self.read_floats(a, &[Dimensions::Vec2], what)?;
        Ok(f.chunks_exact(2).map(Vec2::from_slice).collect())
    }

    fn read_vec4s(&self, a: &gltf::Accessor, what: &str) -> Result<Vec<Vec4>, SceneError> {
        let (f, _) = self.read_floats(a, &[Dimensions::Vec4], what)?;
        Ok(f.chunks_exact(4).map(Vec4::from_slice).collect())
    }

    // ----- materials and textures ------------------------------------------------------------

    fn load_materials(&mut self) {
        let document = self.document.clone();
        for m in document.materials() {
            let name = m
                .name()
                .map(str::to_string)
                .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
            let pbr = m.pbr_metallic_roughness();
            let mut texture = |info: Option<(gltf::texture::Texture, u32)>,
                               srgb: bool,
                               slot: &str| {
                let (tex, tex_coord) = info?;
                if tex_coord != 0 {
                    self.warn(format!(
                        "material '{name}' {slot} texture uses TEXCOORD_{tex_coord}; valgi samples TEXCOORD_0"
                    ));
                }
                self.texture(tex.source().index(), srgb)
            };
            let base_color_texture = texture(
                pbr.base_color_texture()
                    .map(|i| (i.texture(), i.tex_coord())),
                true,
                "base colour",
            );
            let metallic_roughness_texture = texture(
                pbr.metallic_roughness_texture()
                    .map(|i| (i.texture(), i.tex_coord())),
                false,
                "metallic-roughness",
            );
            let normal = m.normal_texture();
            let normal_scale = normal.as_ref().map_or(1.0, |n| n.scale());
            let normal_texture = texture(
                normal.map(|n| (n.texture(), n.tex_coord())),
                false,
                "normal",
            );
            let emissive_texture = texture(
                m.emissive_texture().map(|i| (i.texture(), i.tex_coord())),
                true,
                "emissive",
            );
            let strength = m.emissive_strength().unwrap_or(1.0);
            let material = Material {
                name,
                base_color: Vec4::from(pbr.base_color_factor()),
                base_color_texture,
                metallic: pbr.metallic_factor(),
                roughness: pbr.roughness_factor(),
                metallic_roughness_texture,
                normal_texture,
                normal_scale,
                emissive: Vec3::from(m.emissive_factor()) * strength,
                emissive_texture,
                specular_factor: m.specular().map_or(1.0, |s| s.specular_factor()),
                double_sided: m.double_sided(),
            };
            self.scene.materials.push(material);
        }
    }

    /// Our texture for glTF image `image` in the given colour space, decoding it on first use.
    /// An image used both as colour (sRGB) and as data (linear) becomes two textures. A texture
    /// that cannot be read is a warning, not an error: the material falls back to its factors.
    fn texture(&mut self, image: usize, srgb: bool) -> Option<usize> {
        if let Some(known) = self.texture_map.get(&(image, srgb)) {
            return *known;
        }
        let result = self.decode_image(image, srgb);
        let index = match result {
            Ok(texture) => {
                self.scene.textures.push(texture);
                Some(self.scene.textures.len() - 1)
            }
            Err(message) => {
                self.warn(format!("image {image} ignored: {message}"));
                None
            }
        };
        self.texture_map.insert((image, srgb), index);
        index
    }

    fn decode_image(&self, index: usize, srgb: bool) -> Result<Texture, String> {
        let image = self
            .document
            .images()
            .nth(index)
            .ok_or_else(|| format!("image {index} does not exist"))?;
        let name = image
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("image{index}"));
        // The source is read from the raw JSON: `gltf::Image::source` unwraps a missing
        // `mimeType` or `uri`, which a malformed file must not turn into a panic.
        let json = &self.raw["images"][index];
        let encoded: Vec<u8> = if let Some(view_index) = json["bufferView"].as_u64() {
            let view = self
                .document
                .views()
                .nth(view_index as usize)
                .ok_or_else(|| format!("bufferView {view_index} does not exist"))?;
            self.view_bytes(&view).map_err(problem)?.to_vec()
        } else if let Some(uri) = json["uri"].as_str() {
            self.read_uri(uri, "image").map_err(problem)?
        } else {
            return Err("image has neither a uri nor a bufferView".into());
        };
        // `decode_rgba8` converts every pixel format (grey, grey-alpha, RGB, 16-bit, float with
        // clamping) to 8-bit RGBA, which is all the GPU side samples.
        let rgba =
            files::decode_rgba8(&encoded).map_err(|e| format!("cannot decode '{name}': {e}"))?;
        Ok(Texture {
            name,
            width: rgba.width(),
            height: rgba.height(),
            rgba8: rgba.into_raw(),
            color_space: slot_color_space(srgb),
        })
    }

    /// Material index for a primitive, appending the glTF default material on first need.
    fn material_index(&mut self, material: Option<usize>) -> usize {
        match material {
            Some(i) if i < self.scene.materials.len() => i,
            _ => *self.default_material.get_or_insert_with(|| {
                // glTF's default material: white, metallic 1, roughness 1.
                self.scene.materials.push(Material::default());
                self.scene.materials.len() - 1
            }),
        }
    }

    // ----- nodes, meshes, lights, cameras ----------------------------------------------------

    fn load_nodes(&mut self) -> Result<(), SceneError> {
        let document = self.document.clone();
        let roots: Vec<usize> = match document
            .default_scene()
            .or_else(|| document.scenes().next())
        {
            Some(scene) => scene.nodes().map(|n| n.index()).collect(),
            None => {
                let mut is_child = vec![false; document.nodes().len()];
                for node in document.nodes() {
                    for child in node.children() {
                        if let Some(flag) = is_child.get_mut(child.index()) {
                            *flag = true;
                        }
                    }
                }
                (0..is_child.len()).filter(|&i| !is_child[i]).collect()
            }
        };
        let nodes: Vec<gltf::Node> = document.nodes().collect();
        // Depth-first with an explicit stack (no recursion limit on deep files); a node is
        // pushed to `scene.nodes` before any of its children, so parents come first.
        let mut stack: Vec<(usize, Option<usize>)> =
            roots.into_iter().rev().map(|r| (r, None)).collect();
        while let Some((gltf_index, parent)) = stack.pop() {
            let Some(node) = nodes.get(gltf_index) else {
                continue;
            };
            if self.node_map.contains_key(&gltf_index) {
                self.warn(format!(
                    "node {gltf_index} is reachable twice (shared child or cycle); using its first placement"
                ));
                continue;
            }
            let ours = self.scene.nodes.len();
            let name = node
                .name()
                .map(str::to_string)
                .unwrap_or_else(|| format!("node{gltf_index}"));
            let local = self.node_trs(node, &name);
            self.scene.nodes.push(Node {
                name: name.clone(),
                parent,
                local,
            });
            self.node_map.insert(gltf_index, ours);

            if let Some(mesh) = node.mesh() {
                if node.skin().is_some() {
                    self.warn(format!(
                        "node '{name}': skinning is not supported; mesh drawn in bind pose"
                    ));
                }
                for mesh_index in self.mesh(&mesh)? {
                    self.scene.instances.push(Instance {
                        mesh: mesh_index,
                        node: ours,
                    });
                }
            }
            if let Some(camera) = node.camera() {
                self.camera(&camera, ours, &name);
            }
            self.light(gltf_index, ours, &name);
            for child in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push((child.index(), Some(ours)));
            }
        }
        Ok(())
    }

    fn node_trs(&mut self, node: &gltf::Node, name: &str) -> Trs {
        let trs = match node.transform() {
            gltf::scene::Transform::Matrix { matrix } => {
                let m = Mat4::from_cols_array_2d(&matrix);
                let (scale, rotation, translation) = m.to_scale_rotation_translation();
                Trs {
                    translation,
                    rotation: rotation.normalize(),
                    scale,
                }
            }
            gltf::scene::Transform::Decomposed {
                translation,
                rotation,
                scale,
            } => Trs {
                translation: Vec3::from(translation),
                rotation: Quat::from_array(rotation).normalize(),
                scale: Vec3::from(scale),
            },
        };
        if trs.translation.is_finite() && trs.rotation.is_finite() && trs.scale.is_finite() {
            trs
        } else {
            self.warn(format!(
                "node '{name}' has a non-finite transform; using identity"
            ));
            Trs::default()
        }
    }

    fn camera(&mut self, camera: &gltf::Camera, node: usize, node_name: &str) {
        let name = camera
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| node_name.to_string());
        // The gltf crate's projection() unwraps the object its `type` names; a file whose type
        // and object disagree would panic there.
        let raw = &self.raw["cameras"][camera.index()];
        let kind = raw["type"].as_str().unwrap_or("");
        if !raw[kind].is_object() {
            self.warn(format!(
                "camera '{name}' has type '{kind}' but no '{kind}' object; skipped"
            ));
            return;
        }
        match camera.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let yfov = p.yfov();
                if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f32::consts::PI) {
                    self.warn(format!(
                        "camera '{name}' has an invalid yfov {yfov}; skipped"
                    ));
                    return;
                }
                self.scene.cameras.push(Camera {
                    name,
                    node,
                    yfov,
                    fov_axis: FovAxis::Vertical,
                    aspect: p.aspect_ratio().filter(|a| a.is_finite() && *a > 0.0),
                    znear: p.znear(),
                    zfar: p.zfar(),
                });
            }
            gltf::camera::Projection::Orthographic(_) => {
                self.warn(format!(
                    "camera '{name}' is orthographic, which valgi does not support; skipped"
                ));
            }
        }
    }

    /// KHR_lights_punctual, read from the raw JSON so the file's values come through exactly
    /// and a malformed light is a warning rather than a panic in the gltf crate's accessors.
    fn light(&mut self, gltf_node: usize, node: usize, node_name: &str) {
        let Some(light_index) =
            self.raw["nodes"][gltf_node]["extensions"]["KHR_lights_punctual"]["light"].as_u64()
        else {
            return;
        };
        let light =
            self.raw["extensions"]["KHR_lights_punctual"]["lights"][light_index as usize].clone();
        if !light.is_object() {
            self.warn(format!(
                "node '{node_name}' refers to missing light {light_index}; skipped"
            ));
            return;
        }
        let number = |v: &Value, default: f32| v.as_f64().map_or(default, |x| x as f32);
        let kind = match light["type"].as_str() {
            Some("point") => LightKind::Point,
            Some("directional") => LightKind::Directional,
            Some("spot") => LightKind::Spot {
                inner_cone_angle: number(&light["spot"]["innerConeAngle"], 0.0),
                outer_cone_angle: number(
                    &light["spot"]["outerConeAngle"],
                    std::f32::consts::FRAC_PI_4,
                ),
            },
            other => {
                self.warn(format!(
                    "light {light_index} has unknown type {other:?}; skipped"
                ));
                return;
            }
        };
        let color = match light["color"].as_array() {
            Some(c) if c.len() == 3 => {
                Vec3::new(number(&c[0], 1.0), number(&c[1], 1.0), number(&c[2], 1.0))
            }
            _ => Vec3::ONE,
        };
        self.scene.lights.push(Light {
            name: light["name"]
                .as_str()
                .map(str::to_string)
                .unwrap_or_else(|| node_name.to_string()),
            node,
            kind,
            color,
            intensity: number(&light["intensity"], 1.0),
            range: light["range"].as_f64().map(|r| r as f32),
        });
    }

    /// Our meshes for a glTF mesh (one per triangle primitive), built once and shared by every
    /// node that instances it.
    fn mesh(&mut self, mesh: &gltf::Mesh) -> Result<Vec<usize>, SceneError> {
        if let Some(known) = self.mesh_map.get(&mesh.index()) {
            return Ok(known.clone());
        }
        let mesh_name = mesh
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("mesh{}", mesh.index()));
        let mut ours = Vec::new();
        for primitive in mesh.primitives() {
            let what = format!("{mesh_name}/prim{}", primitive.index());
            if let Some(built) = self.primitive(&primitive, &what)? {
                self.scene.meshes.push(built);
                ours.push(self.scene.meshes.len() - 1);
            }
        }
        self.mesh_map.insert(mesh.index(), ours.clone());
        Ok(ours)
    }

    fn primitive(
        &mut self,
        primitive: &gltf::Primitive,
        what: &str,
    ) -> Result<Option<Mesh>, SceneError> {
        use gltf::mesh::Mode;
        let mode = primitive.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            self.warn(format!(
                "{what}: {mode:?} primitives are not rendered; skipped"
            ));
            return Ok(None);
        }
        let Some(position_accessor) = primitive.get(&gltf::Semantic::Positions) else {
            return Err(self.geometry_err(what, "primitive has no POSITION attribute"));
        };
        let positions = self.read_vec3s(&position_accessor, &format!("POSITION of {what}"))?;
        validate_positions(&positions).map_err(|m| self.geometry_err(what, m))?;
        let vertex_count = positions.len();
        if vertex_count > u32::MAX as usize {
            return Err(self.geometry_err(what, "more than 2³² vertices"));
        }
        let check_count = |importer: &Self, n: usize, attribute: &str| {
            if n == vertex_count {
                Ok(())
            } else {
                Err(importer.geometry_err(
                    what,
                    format!("{attribute} has {n} elements but POSITION has {vertex_count}"),
                ))
            }
        };

        // Indices: validated against the vertex count before anything uses them.
        let raw_indices = match primitive.indices() {
            Some(a) => {
                let indices = self.read_indices(&a, &format!("indices of {what}"))?;
                if let Some((at, &bad)) = indices
                    .iter()
                    .enumerate()
                    .find(|(_, &i)| i as usize >= vertex_count)
                {
                    return Err(self.geometry_err(
                        what,
                        format!("index {bad} (at position {at}) is out of range: the primitive has {vertex_count} vertices"),
                    ));
                }
                indices
            }
            None => (0..vertex_count as u32).collect(),
        };
        let mut indices = match mode {
            Mode::TriangleStrip => strip_to_list(&raw_indices),
            Mode::TriangleFan => fan_to_list(&raw_indices),
            _ => raw_indices,
        };
        if indices.len() % 3 != 0 {
            self.warn(format!(
                "{what}: {} indices is not a multiple of 3; the incomplete triangle is dropped",
                indices.len()
            ));
            indices.truncate(indices.len() / 3 * 3);
        }
        let removed = remove_degenerate_triangles(&positions, &mut indices);
        if removed > 0 {
            self.warn(format!("{what}: removed {removed} degenerate triangle(s)"));
        }

        let material = self.material_index(primitive.material().index());
        let (has_textures, has_normal_map) = {
            let m = &self.scene.materials[material];
            (m.has_textures(), m.normal_texture.is_some())
        };

        let normals = match primitive.get(&gltf::Semantic::Normals) {
            Some(a) => {
                let mut normals = self.read_vec3s(&a, &format!("NORMAL of {what}"))?;
                check_count(self, normals.len(), "NORMAL")?;
                // Repair unusable normals (zero, NaN) from the geometry instead of failing.
                let bad = normals
                    .iter()
                    .filter(|n| n.try_normalize().is_none())
                    .count();
                if bad > 0 {
                    let computed = compute_normals(&positions, &indices);
                    for (n, c) in normals.iter_mut().zip(&computed) {
                        if n.try_normalize().is_none() {
                            *n = *c;
                        }
                    }
                    self.warn(format!(
                        "{what}: replaced {bad} zero or non-finite normal(s)"
                    ));
                }
                normals
                    .into_iter()
                    .map(|n| n.normalize_or(Vec3::Y))
                    .collect()
            }
            None => {
                self.warn(format!("computed normals for {what} (the file has none)"));
                compute_normals(&positions, &indices)
            }
        };

        let uv0 = match primitive.get(&gltf::Semantic::TexCoords(0)) {
            Some(a) => {
                let uv = self.read_vec2s(&a, &format!("TEXCOORD_0 of {what}"))?;
                check_count(self, uv.len(), "TEXCOORD_0")?;
                uv
            }
            None => {
                if has_textures {
                    self.warn(format!(
                        "{what}: material has textures but the primitive has no TEXCOORD_0"
                    ));
                }
                vec![Vec2::ZERO; vertex_count]
            }
        };
        let uv1 = match primitive.get(&gltf::Semantic::TexCoords(1)) {
            Some(a) => {
                let uv = self.read_vec2s(&a, &format!("TEXCOORD_1 of {what}"))?;
                check_count(self, uv.len(), "TEXCOORD_1")?;
                Some(uv)
            }
            None => None,
        };
        let tangents = if has_normal_map {
            match primitive.get(&gltf::Semantic::Tangents) {
                Some(a) => {
                    let t = self.read_vec4s(&a, &format!("TANGENT of {what}"))?;
                    check_count(self, t.len(), "TANGENT")?;
                    let computed_if_bad = t
                        .iter()
                        .any(|t| !t.is_finite() || t.truncate().try_normalize().is_none());
                    if computed_if_bad {
                        self.warn(format!("{what}: TANGENT has unusable values; recomputed"));
                        compute_tangents(&positions, &normals, &uv0, &indices)
                    } else {
                        t.into_iter()
                            .map(|t| {
                                t.truncate()
                                    .normalize()
                                    .extend(if t.w < 0.0 { -1.0 } else { 1.0 })
                            })
                            .collect()
                    }
                }
                None => {
                    log::info!("{}: computed tangents for {what}", self.display);
                    compute_tangents(&positions, &normals, &uv0, &indices)
                }
            }
        } else {
            Vec::new()
        };
        if primitive.morph_targets().next().is_some() {
            self.warn(format!(
                "{what}: morph targets are not supported; base shape used"
            ));
        }
        Ok(Some(Mesh {
            name: what.to_string(),
            positions,
            normals,
            tangents,
            uv0,
            uv1,
            indices,
            material,
        }))
    }

    // ----- animations ------------------------------------------------------------------------

    /// TRS animations. Channels and samplers are read from the raw JSON: the gltf crate does
    /// not validate animation targets and unwraps them (a dangling node index or an unknown
    /// `path` would panic), so every index is checked here instead.
    fn load_animations(&mut self) -> Result<(), SceneError> {
        let animations = self.raw["animations"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        for (a, animation) in animations.iter().enumerate() {
            let name = animation["name"]
                .as_str()
                .map(str::to_string)
                .unwrap_or_else(|| format!("animation{a}"));
            let samplers = animation["samplers"]
                .as_array()
                .cloned()
                .unwrap_or_default();
            let mut channels = Vec::new();
            let raw_channels = animation["channels"]
                .as_array()
                .cloned()
                .unwrap_or_default();
            for (c, channel) in raw_channels.iter().enumerate() {
                let what = format!("animation '{name}' channel {c}");
                let target = &channel["target"];
                let property = match target["path"].as_str() {
                    Some("translation") => Property::Translation,
                    Some("rotation") => Property::Rotation,
                    Some("scale") => Property::Scale,
                    Some("weights") => {
                        self.warn(format!("{what}: morph-weight channel skipped"));
                        continue;
                    }
                    other => {
                        self.warn(format!("{what}: unknown target path {other:?}; skipped"));
                        continue;
                    }
                };
                let Some(gltf_node) = target["node"].as_u64() else {
                    self.warn(format!("{what}: no target node; skipped"));
                    continue;
                };
                let Some(&node) = self.node_map.get(&(gltf_node as usize)) else {
                    self.warn(format!(
                        "{what}: node {gltf_node} is not in the loaded scene; skipped"
                    ));
                    continue;
                };
                let sampler = channel["sampler"]
                    .as_u64()
                    .and_then(|s| samplers.get(s as usize));
                let Some(sampler) = sampler else {
                    self.warn(format!("{what}: missing sampler; skipped"));
                    continue;
                };
                let interpolation = match sampler["interpolation"].as_str() {
                    None | Some("LINEAR") => Interpolation::Linear,
                    Some("STEP") => Interpolation::Step,
                    Some("CUBICSPLINE") => Interpolation::CubicSpline,
                    Some(other) => {
                        self.warn(format!("{what}: unknown interpolation '{other}'; skipped"));
                        continue;
                    }
                };
                let accessor = |key: &str| {
                    sampler[key]
                        .as_u64()
                        .and_then(|i| self.document.accessors().nth(i as usize))
                };
                let (Some(input), Some(output)) = (accessor("input"), accessor("output")) else {
                    self.warn(format!(
                        "{what}: sampler input/output accessor missing; skipped"
                    ));
                    continue;
                };
                let (times, _) =
                    self.read_floats(&input, &[Dimensions::Scalar], &format!("input of {what}"))?;
                let expected = if property == Property::Rotation {
                    Dimensions::Vec4
                } else {
                    Dimensions::Vec3
                };
                let (flat, n) =
                    self.read_floats(&output, &[expected], &format!("output of {what}"))?;
                let values: Vec<Vec4> = flat
                    .chunks_exact(n)
                    .map(|c| {
                        if n == 4 {
                            Vec4::from_slice(c)
                        } else {
                            Vec3::from_slice(c).extend(0.0)
                        }
                    })
                    .collect();
                let per_key = if interpolation == Interpolation::CubicSpline {
                    3
                } else {
                    1
                };
                if times.is_empty() || values.len() != times.len() * per_key {
                    self.warn(format!(
                        "{what}: {} keys but {} values; skipped",
                        times.len(),
                        values.len()
                    ));
                    continue;
                }
                let increasing =
                    times.iter().all(|t| t.is_finite()) && times.windows(2).all(|w| w[0] <= w[1]);
                if !increasing || values.iter().any(|v| !v.is_finite()) {
                    self.warn(format!("{what}: non-finite or decreasing keys; skipped"));
                    continue;
                }
                channels.push(Channel {
                    node,
                    property,
                    interpolation,
                    times,
                    values,
                });
            }
            if !channels.is_empty() {
                self.scene.animations.push(Animation { name, channels });
            }
        }
        Ok(())
    }
}

/// The problem in an importer error without the file name, for messages nested in a warning
/// that already names the file.
fn problem(e: SceneError) -> String {
    match e {
        SceneError::Gltf { message, .. } => message,
        other => other.to_string(),
    }
}

fn validation_message(err: &gltf::json::validation::Error) -> &'static str {
    use gltf::json::validation::Error;
    match err {
        Error::IndexOutOfBounds => "index out of range",
        Error::Invalid => "invalid value",
        Error::Missing => "required value missing",
        Error::Oversize => "size exceeds system limits",
        Error::Unsupported => "unsupported",
    }
}

/// Triangle strip → list, alternating winding so every triangle keeps the strip's orientation.
fn strip_to_list(strip: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(strip.len().saturating_sub(2) * 3);
    for i in 0..strip.len().saturating_sub(2) {
        if i % 2 == 0 {
            out.extend_from_slice(&[strip[i], strip[i + 1], strip[i + 2]]);
        } else {
            out.extend_from_slice(&[strip[i + 1], strip[i], strip[i + 2]]);
        }
    }
    out
}

/// Triangle fan → list around the first vertex.
fn fan_to_list(fan: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(fan.len().saturating_sub(2) * 3);
    for i in 1..fan.len().saturating_sub(1) {
        out.extend_from_slice(&[fan[0], fan[i], fan[i + 1]]);
    }
    out
}

/// Identical warnings (one per primitive of a large file, say) become one line with a count,
/// in first-seen order.
fn collapse_repeats(warnings: Vec<String>) -> Vec<String> {
    // Indexed so that a file with many distinct warnings stays linear.
    let mut counts: Vec<(String, usize)> = Vec::new();
    let mut index: HashMap<String, usize> = HashMap::new();
    for w in warnings {
        match index.get(&w) {
            Some(&i) => counts[i].1 += 1,
            None => {
                index.insert(w.clone(), counts.len());
                counts.push((w, 1));
            }
        }
    }
    counts
        .into_iter()
        .map(|(w, n)| if n > 1 { format!("{w} ({n} times)") } else { w })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_roundtrip() {
        assert_eq!(decode_base64("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(decode_base64("aGVsbG8").unwrap(), b"hello");
        assert_eq!(decode_base64("AAECAw==").unwrap(), vec![0, 1, 2, 3]);
        assert!(decode_base64("a$b").is_err());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("my%20file.bin").unwrap(), "my file.bin");
        assert!(percent_decode("bad%zz").is_err());
        assert!(percent_decode("bad%ff").is_err());
    }

    #[test]
    fn strips_and_fans() {
        assert_eq!(strip_to_list(&[0, 1, 2, 3]), vec![0, 1, 2, 2, 1, 3]);
        assert_eq!(fan_to_list(&[0, 1, 2, 3]), vec![0, 1, 2, 0, 2, 3]);
        assert!(strip_to_list(&[0, 1]).is_empty());
    }

    #[test]
    fn malformed_glb_never_panics() {
        for bytes in [
            &b"glTF"[..],
            b"glTF\x02\0\0\0\x04\0\0\0",
            b"glTF\x02\0\0\0\x20\0\0\0\xff\xff\xff\xffJSON",
            b"glTF\x01\0\0\0\x0c\0\0\0",
        ] {
            assert!(load_from_slice(bytes, None, "x.glb").is_err());
        }
    }
}
