//! PLY triangle meshes (Turk's polygon file format): ASCII, binary little- and big-endian.
//!
//! Read: vertex `x y z` (any numeric type), optional normals `nx ny nz` and texture
//! coordinates (`u v`, `s t`, `texture_u texture_v` or `texture_s texture_t`); faces as a list
//! property (`vertex_indices`, `vertex_index`, or the face element's first list), polygons
//! fanned into triangles. Other elements and properties are parsed past and ignored.
//!
//! Nothing is allocated for what the header merely declares: storage grows with the elements
//! actually read (the declared count sizes the first allocation only when the body could hold
//! it), list lengths must fit in what remains of the file, elements without properties are not
//! iterated, and vertex and triangle counts are capped ([`MAX_VERTICES`], [`MAX_TRIANGLES`]).
//! Errors name the file, the element and the problem.

use super::files;
use super::mesh::{compute_normals, remove_degenerate_triangles};
use super::{Instance, Material, Mesh, Node, Scene, SceneError, Trs};
use glam::{Vec2, Vec3};
use std::path::Path;

/// Most vertices a PLY file may declare (positions, normals and UVs of 2²⁷ vertices are 4 GiB).
pub const MAX_VERTICES: u64 = 1 << 27;
/// Most triangles a PLY file may produce after fanning its polygons.
pub const MAX_TRIANGLES: u64 = 1 << 28;
/// Longest header read, bytes.
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Grey of the Lambertian material a PLY scene gets (the format carries no materials).
pub const DEFAULT_ALBEDO: f32 = 0.8;

/// Loads a PLY file as a scene: its mesh on one node with a grey Lambertian material
/// ([`DEFAULT_ALBEDO`]), no lights or cameras.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let mesh = load_mesh(path)?;
    let display = path.display().to_string();
    let mut scene = Scene {
        name: mesh.name.clone(),
        ..Scene::default()
    };
    scene.materials.push(Material::lambert(
        "PLY default (grey Lambertian)",
        Vec3::splat(DEFAULT_ALBEDO),
    ));
    scene.nodes.push(Node {
        name: mesh.name.clone(),
        parent: None,
        local: Trs::default(),
    });
    scene.meshes.push(mesh);
    scene.instances.push(Instance { mesh: 0, node: 0 });
    scene.warnings.push(format!(
        "{display}: PLY has no materials; grey Lambertian (albedo {DEFAULT_ALBEDO}) used"
    ));
    super::sanitize::sanitize(&mut scene, &display);
    Ok(scene)
}

/// Reads a PLY file's triangle mesh (named after the file stem, material 0).
pub fn load_mesh(path: &Path) -> Result<Mesh, SceneError> {
    let file = files::read_scene_file(path, files::other_error)?;
    let mut mesh = parse(&file.bytes, &file.display)?;
    mesh.name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("ply")
        .into();
    Ok(mesh)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLittle,
    BinaryBig,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }

    fn range(self) -> (f64, f64) {
        match self {
            Self::I8 => (i8::MIN as f64, i8::MAX as f64),
            Self::U8 => (0.0, u8::MAX as f64),
            Self::I16 => (i16::MIN as f64, i16::MAX as f64),
            Self::U16 => (0.0, u16::MAX as f64),
            Self::I32 => (i32::MIN as f64, i32::MAX as f64),
            Self::U32 => (0.0, u32::MAX as f64),
            Self::F32 | Self::F64 => (f64::NEG_INFINITY, f64::INFINITY),
        }
    }
}

#[derive(Clone, Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
}

impl Element {
    /// Fewest body bytes one element can take: binary, its scalars and list counts; ASCII, one
    /// character and one separator per scalar or list count.
    fn min_bytes(&self, format: Format) -> u64 {
        self.properties
            .iter()
            .map(|p| match (format, p) {
                (Format::Ascii, _) => 2,
                (_, Property::Scalar(_, t)) | (_, Property::List(_, t, _)) => t.size() as u64,
            })
            .sum()
    }
}

/// Parses PLY bytes; `display` names the source in errors.
pub fn parse(bytes: &[u8], display: &str) -> Result<Mesh, SceneError> {
    let fail = |message: String| SceneError::Other {
        path: display.to_string(),
        message,
    };
    let first_line_end = bytes.iter().position(|&b| b == b'\n');
    let magic = first_line_end.map(|e| bytes[..e].trim_ascii_end());
    if magic != Some(b"ply") {
        return Err(fail("not a PLY file (no 'ply' magic line)".into()));
    }
    let (header, body) = split_header(bytes).map_err(&fail)?;
    let (format, elements) = parse_header(header).map_err(&fail)?;

    let vertex = elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| fail("no vertex element".into()))?;
    let vertex_count = elements[vertex].count;
    if vertex_count > MAX_VERTICES {
        return Err(fail(format!(
            "{vertex_count} vertices exceed the limit of {MAX_VERTICES}"
        )));
    }
    let find = |names: &[&str]| {
        elements[vertex].properties.iter().position(|p| match p {
            Property::Scalar(n, _) => names.contains(&n.as_str()),
            Property::List(..) => false,
        })
    };
    let axis =
        |name: &str| find(&[name]).ok_or_else(|| fail(format!("vertex has no '{name}' property")));
    let position_at = [axis("x")?, axis("y")?, axis("z")?];
    let normal_at = match (find(&["nx"]), find(&["ny"]), find(&["nz"])) {
        (Some(x), Some(y), Some(z)) => Some([x, y, z]),
        _ => None,
    };
    let uv_at = [
        ("u", "v"),
        ("s", "t"),
        ("texture_u", "texture_v"),
        ("texture_s", "texture_t"),
    ]
    .iter()
    .find_map(|(u, v)| Some([find(&[u])?, find(&[v])?]));

    // Storage grows with what the body really holds: the declared count only sizes the first
    // allocation when the body is large enough to contain that many vertices.
    let fits = body.len() as u64 / elements[vertex].min_bytes(format).max(1) + 1;
    let capacity = vertex_count.min(fits) as usize;
    let vertex_count = vertex_count as usize;
    let mut positions = Vec::with_capacity(capacity);
    let mut normals = Vec::with_capacity(if normal_at.is_some() { capacity } else { 0 });
    let mut uvs = Vec::with_capacity(if uv_at.is_some() { capacity } else { 0 });
    let mut indices: Vec<u32> = Vec::new();
    let mut reader = Reader::new(format, body);
    let mut values: Vec<f64> = Vec::new();
    let mut polygon: Vec<u32> = Vec::new();
    let mut face_seen = false;

    for (element_index, element) in elements.iter().enumerate() {
        if element.properties.is_empty() {
            continue;
        }
        // Only the first 'vertex' element holds the vertices (its columns are the ones found
        // above); a later one is read past like any other element, as a later 'face' is.
        let is_vertex = element_index == vertex;
        let is_face = element.name == "face" && !face_seen;
        let face_list = if is_face {
            face_seen = true;
            let named = element.properties.iter().position(|p| {
                matches!(p, Property::List(n, _, _) if n == "vertex_indices" || n == "vertex_index")
            });
            named.or_else(|| {
                element
                    .properties
                    .iter()
                    .position(|p| matches!(p, Property::List(..)))
            })
        } else {
            None
        };
        for i in 0..element.count {
            values.clear();
            for (k, property) in element.properties.iter().enumerate() {
                let at = |what: &str| format!("{} {i}: {what}", element.name);
                let read_error = |m: String, what: &str| {
                    if m == END_OF_BODY {
                        format!("file ends at {} {i} of {}", element.name, element.count)
                    } else {
                        at(&format!("{what}: {m}"))
                    }
                };
                match property {
                    Property::Scalar(name, t) => {
                        let v = reader
                            .value(*t)
                            .map_err(|m| fail(read_error(m, &format!("property '{name}'"))))?;
                        values.push(v);
                    }
                    Property::List(name, count_type, item_type) => {
                        // A slot per property keeps `values` indexed like the properties
                        // (`position_at` and the rest count lists too); a list is never one.
                        values.push(f64::NAN);
                        let n = reader
                            .value(*count_type)
                            .map_err(|m| fail(read_error(m, &format!("list '{name}' length"))))?;
                        let n = n as u64;
                        let room = reader.remaining_items(*item_type);
                        if n > room {
                            return Err(fail(at(&format!(
                                "list '{name}' declares {n} items but only {room} fit in the rest \
                                 of the file"
                            ))));
                        }
                        let keep = face_list == Some(k);
                        if keep {
                            polygon.clear();
                        }
                        for _ in 0..n {
                            let v = reader
                                .value(*item_type)
                                .map_err(|m| fail(read_error(m, &format!("list '{name}'"))))?;
                            if keep {
                                if !(v >= 0.0 && (v as u64) < vertex_count as u64) {
                                    return Err(fail(at(&format!(
                                        "vertex index {v} out of range (0..{vertex_count})"
                                    ))));
                                }
                                polygon.push(v as u32);
                            }
                        }
                        if keep {
                            if polygon.len() < 3 {
                                return Err(fail(at(&format!(
                                    "bad vertex list: {} vertices, a face needs at least 3",
                                    polygon.len()
                                ))));
                            }
                            let added = 3 * (polygon.len() as u64 - 2);
                            if indices.len() as u64 + added > 3 * MAX_TRIANGLES {
                                return Err(fail(format!(
                                    "more than {MAX_TRIANGLES} triangles after fanning polygons"
                                )));
                            }
                            for j in 1..polygon.len() - 1 {
                                indices.extend([polygon[0], polygon[j], polygon[j + 1]]);
                            }
                        }
                    }
                }
            }
            if is_vertex {
                let p = Vec3::new(
                    values[position_at[0]] as f32,
                    values[position_at[1]] as f32,
                    values[position_at[2]] as f32,
                );
                if !p.is_finite() {
                    return Err(fail(format!("vertex {i}: non-finite position {p}")));
                }
                positions.push(p);
                if let Some([x, y, z]) = normal_at {
                    normals.push(Vec3::new(
                        values[x] as f32,
                        values[y] as f32,
                        values[z] as f32,
                    ));
                }
                if let Some([u, v]) = uv_at {
                    uvs.push(Vec2::new(values[u] as f32, values[v] as f32));
                }
            }
        }
    }
    if !face_seen {
        return Err(fail(
            "no face element (point clouds are not rendered)".into(),
        ));
    }
    let removed = remove_degenerate_triangles(&positions, &mut indices);
    if indices.is_empty() {
        return Err(fail(format!(
            "no triangles ({removed} degenerate face triangle(s) removed)"
        )));
    }
    let computed = compute_normals(&positions, &indices);
    let normals = if normals.len() == positions.len() {
        normals
            .into_iter()
            .zip(&computed)
            .map(|(n, c)| n.try_normalize().unwrap_or(*c))
            .collect()
    } else {
        computed
    };
    let uv0 = if uvs.len() == positions.len() {
        uvs
    } else {
        vec![Vec2::ZERO; positions.len()]
    };
    Ok(Mesh {
        name: "ply".into(),
        positions,
        normals,
        tangents: vec![],
        uv0,
        uv1: None,
        indices,
        material: 0,
    })
}

/// Writes `mesh` as binary PLY (positions, normals, uvs in valgi's top-left convention, and
/// triangles), little- or big-endian. [`parse`] reads it back.
pub fn to_binary(mesh: &Mesh, big_endian: bool) -> Vec<u8> {
    let order = if big_endian { "big" } else { "little" };
    let mut out = format!(
        "ply\nformat binary_{order}_endian 1.0\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nproperty float nx\nproperty float ny\n\
         property float nz\nproperty float u\nproperty float v\nelement face {}\n\
         property list uchar uint vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangle_count()
    )
    .into_bytes();
    let put = |out: &mut Vec<u8>, bytes: [u8; 4]| {
        out.extend(if big_endian {
            [bytes[3], bytes[2], bytes[1], bytes[0]]
        } else {
            bytes
        })
    };
    for (i, p) in mesh.positions.iter().enumerate() {
        let n = mesh.normals.get(i).copied().unwrap_or(Vec3::Y);
        let uv = mesh.uv0.get(i).copied().unwrap_or(Vec2::ZERO);
        for v in [p.x, p.y, p.z, n.x, n.y, n.z, uv.x, uv.y] {
            put(&mut out, v.to_le_bytes());
        }
    }
    for t in mesh.indices.chunks_exact(3) {
        out.push(3);
        for &i in t {
            put(&mut out, i.to_le_bytes());
        }
    }
    out
}

/// Splits at the line `end_header`, returning the header text (after the magic line) and the
/// body bytes.
fn split_header(bytes: &[u8]) -> Result<(&str, &[u8]), String> {
    let window = &bytes[..bytes.len().min(MAX_HEADER_BYTES)];
    let mut start = 0;
    while start < window.len() {
        let end = window[start..]
            .iter()
            .position(|&b| b == b'\n')
            .map(|p| start + p);
        let Some(end) = end else {
            break;
        };
        if window[start..end].trim_ascii() == b"end_header" {
            let header = std::str::from_utf8(&bytes[..start])
                .map_err(|_| "header is not text".to_string())?;
            let header = header.split_once('\n').map_or("", |(_, rest)| rest);
            return Ok((header, &bytes[end + 1..]));
        }
        start = end + 1;
    }
    Err(if bytes.len() > MAX_HEADER_BYTES {
        format!("header has no end_header within its first {MAX_HEADER_BYTES} bytes")
    } else {
        "header has no end_header".into()
    })
}

fn parse_header(header: &str) -> Result<(Format, Vec<Element>), String> {
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (number, line) in header.lines().enumerate() {
        let line_no = number + 2;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", kind, version] => {
                if *version != "1.0" {
                    return Err(format!("PLY version '{version}' not supported (only 1.0)"));
                }
                format = Some(match *kind {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLittle,
                    "binary_big_endian" => Format::BinaryBig,
                    other => {
                        return Err(format!(
                            "PLY format '{other}' not supported (ascii, binary_little_endian, \
                             binary_big_endian)"
                        ))
                    }
                });
            }
            ["element", name, count] => {
                let count = count
                    .parse::<u64>()
                    .map_err(|_| format!("bad {name} count '{count}' (line {line_no})"))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: vec![],
                });
            }
            ["property", "list", count_type, item_type, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| format!("property before any element (line {line_no})"))?;
                let count = Scalar::parse(count_type)
                    .filter(|t| t.is_integer())
                    .ok_or_else(|| {
                        format!("bad list length type '{count_type}' (line {line_no})")
                    })?;
                let item = Scalar::parse(item_type)
                    .ok_or_else(|| format!("unknown type '{item_type}' (line {line_no})"))?;
                element
                    .properties
                    .push(Property::List(name.to_string(), count, item));
            }
            ["property", kind, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| format!("property before any element (line {line_no})"))?;
                let t = Scalar::parse(kind)
                    .ok_or_else(|| format!("unknown type '{kind}' (line {line_no})"))?;
                element
                    .properties
                    .push(Property::Scalar(name.to_string(), t));
            }
            _ => {
                return Err(format!(
                    "unrecognized header line {line_no}: '{}'",
                    line.chars().take(80).collect::<String>()
                ))
            }
        }
    }
    let format = format.ok_or("header has no format line")?;
    Ok((format, elements))
}

/// [`Reader::value`]'s error when the body has no more values.
const END_OF_BODY: &str = "end of body";

/// Sequential reader of body values, ASCII tokens or binary scalars.
struct Reader<'a> {
    format: Format,
    body: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn new(format: Format, body: &'a [u8]) -> Self {
        Self {
            format,
            body,
            at: 0,
        }
    }

    /// An upper bound on the items of type `t` left in the body.
    fn remaining_items(&self, t: Scalar) -> u64 {
        let left = (self.body.len() - self.at) as u64;
        match self.format {
            Format::Ascii => left.div_ceil(2),
            _ => left / t.size() as u64,
        }
    }

    fn value(&mut self, t: Scalar) -> Result<f64, String> {
        match self.format {
            Format::Ascii => {
                let rest = &self.body[self.at..];
                let start = rest
                    .iter()
                    .position(|b| !b.is_ascii_whitespace())
                    .ok_or(END_OF_BODY)?;
                let len = rest[start..]
                    .iter()
                    .position(|b| b.is_ascii_whitespace())
                    .unwrap_or(rest.len() - start);
                let token = &rest[start..start + len];
                self.at += start + len;
                let text = std::str::from_utf8(token).map_err(|_| "not a number".to_string())?;
                let shown = || text.chars().take(40).collect::<String>();
                let v = if t.is_integer() {
                    text.parse::<i64>()
                        .map(|v| v as f64)
                        .or_else(|_| text.parse::<u64>().map(|v| v as f64))
                        .map_err(|_| format!("'{}' is not an integer", shown()))?
                } else {
                    text.parse::<f64>()
                        .map_err(|_| format!("'{}' is not a number", shown()))?
                };
                let (lo, hi) = t.range();
                if t.is_integer() && !(lo..=hi).contains(&v) {
                    return Err(format!("{} is out of range for {t:?}", shown()));
                }
                Ok(v)
            }
            Format::BinaryLittle | Format::BinaryBig => {
                let size = t.size();
                let bytes = self.body.get(self.at..self.at + size).ok_or(END_OF_BODY)?;
                self.at += size;
                let mut b = [0u8; 8];
                b[..size].copy_from_slice(bytes);
                if self.format == Format::BinaryBig {
                    b[..size].reverse();
                }
                Ok(match t {
                    Scalar::I8 => b[0] as i8 as f64,
                    Scalar::U8 => b[0] as f64,
                    Scalar::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
                    Scalar::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
                    Scalar::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                    Scalar::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                    Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                    Scalar::F64 => f64::from_le_bytes(b),
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A second 'vertex' element with other columns (found by cargo-fuzz: its rows were read
    /// with the first one's column indices).
    #[test]
    fn a_second_vertex_element_is_skipped_not_read_with_the_first_ones_columns() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
            property float y\nproperty float z\nelement vertex 1\nproperty float x\n\
            element face 1\nproperty list uchar int vertex_indices\nend_header\n\
            0 0 0\n1 0 0\n0 1 0\n7\n3 0 1 2\n";
        let mesh = parse(text.as_bytes(), "twice.ply").unwrap();
        assert_eq!(mesh.positions, vec![Vec3::ZERO, Vec3::X, Vec3::Y]);
        assert_eq!(mesh.indices, vec![0, 1, 2]);
    }

    /// A list property before the position (found by cargo-fuzz: it shifted every scalar's
    /// index and read past the row).
    #[test]
    fn a_vertex_list_before_the_position_does_not_shift_it() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty list uchar int tags\n\
            property float x\nproperty float y\nproperty float z\nelement face 1\n\
            property list uchar int vertex_indices\nend_header\n\
            2 7 8 0 0 0\n0 1 0 0\n1 5 0 1 0\n3 0 1 2\n";
        let mesh = parse(text.as_bytes(), "tags.ply").unwrap();
        assert_eq!(
            mesh.positions,
            vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            "positions read from the wrong columns"
        );
    }

    const QUAD_HEADER: &str = "element vertex 4\nproperty float x\nproperty float y\n\
        property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
        property float u\nproperty float v\nelement face 1\n\
        property list uchar int vertex_indices\nend_header\n";

    fn quad_ascii() -> String {
        format!(
            "ply\nformat ascii 1.0\ncomment a unit quad\n{QUAD_HEADER}\
             0 0 0 0 0 1 0 0\n1 0 0 0 0 1 1 0\n1 1 0 0 0 1 1 1\n0 1 0 0 0 1 0 1\n4 0 1 2 3\n"
        )
    }

    fn quad_binary(big: bool) -> Vec<u8> {
        let order = if big { "big" } else { "little" };
        let mut out = format!("ply\nformat binary_{order}_endian 1.0\n{QUAD_HEADER}").into_bytes();
        let f = |v: f32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let i = |v: i32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            for v in [x, y, 0.0, 0.0, 0.0, 1.0, x, y] {
                out.extend(f(v));
            }
        }
        out.push(4);
        for k in 0..4 {
            out.extend(i(k));
        }
        out
    }

    #[test]
    fn ascii_and_binary_give_the_same_mesh() {
        let a = parse(quad_ascii().as_bytes(), "a.ply").unwrap();
        for big in [false, true] {
            let b = parse(&quad_binary(big), "b.ply").unwrap();
            assert_eq!(a.positions, b.positions);
            assert_eq!(a.indices, b.indices);
            assert_eq!(a.uv0, b.uv0);
            assert_eq!(a.normals, b.normals);
        }
        assert_eq!(a.triangle_count(), 2);
        assert_eq!(a.uv0[2], Vec2::new(1.0, 1.0));
        assert_eq!(a.normals[0], Vec3::Z);
    }

    #[test]
    fn absurd_counts_fail_before_allocating() {
        for count in ["4000000000", "4611686018427387904", "18446744073709551615"] {
            let text = quad_ascii().replace("element vertex 4", &format!("element vertex {count}"));
            let err = parse(text.as_bytes(), "big.ply").unwrap_err().to_string();
            assert!(
                err.starts_with("big.ply: ") && err.contains("exceed the limit"),
                "{err}"
            );
            let text = quad_ascii().replace("element face 1", &format!("element face {count}"));
            let err = parse(text.as_bytes(), "big.ply").unwrap_err().to_string();
            assert!(
                err.contains(&format!("file ends at face 1 of {count}")),
                "{err}"
            );
            let mut bytes = quad_binary(true);
            let text = String::from_utf8_lossy(&bytes).into_owned();
            let header_len = text.find("end_header").unwrap();
            let header =
                text[..header_len].replace("element face 1", &format!("element face {count}"));
            bytes.splice(..header_len, header.into_bytes());
            let err = parse(&bytes, "big.ply").unwrap_err().to_string();
            assert!(
                err.contains(&format!("file ends at face 1 of {count}")),
                "{err}"
            );
        }
        let text = quad_ascii().replace("element vertex 4", "element vertex 100000");
        let err = parse(text.as_bytes(), "v.ply").unwrap_err().to_string();
        assert!(err.contains("file ends at vertex 4 of 100000"), "{err}");
        let err = parse(
            quad_ascii()
                .replace("element vertex 4", "element vertex 18446744073709551616")
                .as_bytes(),
            "big.ply",
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("bad vertex count"), "{err}");
        // A face list whose length is 2⁶⁴ − 1.
        let text = quad_ascii()
            .replace("list uchar int", "list uint64 int")
            .replace("4 0 1 2 3", "18446744073709551615 0 1 2");
        assert!(parse(text.as_bytes(), "f.ply").is_err());
        let text = quad_ascii()
            .replace("list uchar int", "list uint int")
            .replace("4 0 1 2 3", "18446744073709551615 0 1 2");
        let err = parse(text.as_bytes(), "f.ply").unwrap_err().to_string();
        assert!(
            err.contains("face 0") && err.contains("out of range"),
            "{err}"
        );
        let text = quad_ascii()
            .replace("list uchar int", "list uint int")
            .replace("4 0 1 2 3", "4000000 0 1 2");
        let err = parse(text.as_bytes(), "f.ply").unwrap_err().to_string();
        assert!(err.contains("declares 4000000 items"), "{err}");
        // Binary: a list length of 255 with 16 bytes left.
        let mut bytes = quad_binary(false);
        let at = bytes.len() - 17;
        bytes[at] = 255;
        let err = parse(&bytes, "b.ply").unwrap_err().to_string();
        assert!(err.contains("declares 255 items"), "{err}");
    }

    #[test]
    fn elements_without_properties_are_not_iterated() {
        let text = quad_ascii().replace(
            "element face 1",
            "element nothing 18446744073709551615\nelement face 1",
        );
        assert_eq!(parse(text.as_bytes(), "e.ply").unwrap().triangle_count(), 2);
    }

    #[test]
    fn malformed_bodies_name_the_element() {
        let cases = [
            (
                quad_ascii().replace("4 0 1 2 3", "4 0 1 2 9"),
                "out of range",
            ),
            (quad_ascii().replace("4 0 1 2 3", "2 0 1"), "at least 3"),
            (
                quad_ascii().replace("1 1 0 0 0 1 1 1", "1 1 x 0 0 1 1 1"),
                "vertex 2",
            ),
            (
                quad_ascii().replace("1 1 0 0 0 1 1 1", "1 1 nan 0 0 1 1 1"),
                "non-finite",
            ),
            (
                quad_ascii().replace("format ascii 1.0", "format ascii 2.0"),
                "version",
            ),
            (
                quad_ascii().replace("format ascii 1.0", "format utf8 1.0"),
                "not supported",
            ),
            (
                quad_ascii().replace("property float y", "property quux y"),
                "unknown type",
            ),
            (
                quad_ascii().replace("end_header", "end_headr"),
                "end_header",
            ),
            (
                quad_ascii().replace("4 0 1 2 3\n", ""),
                "file ends at face 0 of 1",
            ),
            (quad_ascii().replace("4 0 1 2 3\n", "4 0 1"), "face 0: list"),
            (
                quad_ascii().replace("4 0 1 2 3", "300 0 1 2"),
                "out of range for U8",
            ),
        ];
        for (text, needle) in cases {
            let err = parse(text.as_bytes(), "m.ply").unwrap_err().to_string();
            assert!(
                err.starts_with("m.ply: ") && err.contains(needle),
                "{needle}: {err}"
            );
        }
        let mut truncated = quad_binary(true);
        truncated.truncate(truncated.len() - 3);
        let err = parse(&truncated, "t.ply").unwrap_err().to_string();
        assert!(err.contains("face 0"), "{err}");
    }
}
