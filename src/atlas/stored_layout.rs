//! The light-map layout stored beside a baked atlas (`FILE.exr.layout`), so a render does not
//! unwrap and pack the scene again: on Sponza that rebuild was 23.5 s of a render's setup
//! against 0.66 s of passes.
//!
//! The file holds what the GPU lookup draws ([`LookupLayout`]: per light-map mesh its instance,
//! model-space positions, light-map UVs and triangles, whether it is one face of a sheet; the
//! texels that stand for a surface point; the contact cuts) and a [`LayoutKey`] naming the
//! geometry and settings it was made for. The atlas's EXR header carries the file's checksum
//! (`valgiLayoutChecksum`), so a layout file left over from another bake is never taken for
//! this atlas's.
//!
//! Format (every number little-endian, 32-bit words unless said otherwise): the magic
//! `VALGILYT`, the format version, the key, the scene's name and `--max-edge` (for messages),
//! the UV source, the counts, then per mesh its vertices and indices, the cut texels, a bit
//! mask of the surface texels, and last a CRC-32 of everything before it. Reading checks the
//! size against the file before every allocation and validates every index, so a damaged or
//! truncated file is an error naming it, never a panic or an absurd allocation.

use std::path::{Path, PathBuf};

use glam::{Mat4, Vec2, Vec3};

use super::cuts::{ContactCuts, CUTS_PER_TEXEL};
use super::layout::{AtlasLayout, LAYOUT_VERSION, MAX_RESOLUTION};
use crate::image_io::ImageError;
use crate::scene::Scene;

/// Appended to the atlas's file name: `out/a.exr` → `out/a.exr.layout`.
pub const LAYOUT_FILE_SUFFIX: &str = ".layout";
/// EXR header attribute of a baked atlas: the CRC-32 of its layout file (as `i32`).
pub const LAYOUT_CHECKSUM_ATTRIBUTE: &str = "valgiLayoutChecksum";

const MAGIC: [u8; 8] = *b"VALGILYT";
/// Version of this file format (not of the layout algorithm: that is [`LAYOUT_VERSION`]).
const FORMAT_VERSION: u32 = 1;
/// Longest scene name kept (bytes).
const MAX_NAME_BYTES: usize = 4096;
/// Largest layout file read: far above any layout that fits a 4096² atlas (Sponza at 2048²
/// is tens of MB), far below what would exhaust memory.
const MAX_FILE_BYTES: u64 = 2 << 30;

/// The layout file that belongs to the atlas at `atlas`.
pub fn layout_path(atlas: &Path) -> PathBuf {
    let mut name = atlas.as_os_str().to_owned();
    name.push(LAYOUT_FILE_SUFFIX);
    PathBuf::from(name)
}

/// What a layout was made for: the layout code's version, the atlas resolution, and the
/// scene's placed geometry (counts and a CRC-32 of every instance's mesh index and world
/// transform and of the meshes' model-space positions, normals, triangles and TEXCOORD_1).
/// `--max-edge` changes the built-in scenes' and imported scenes' triangles, so it is part of
/// the geometry; lights and cameras are not.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayoutKey {
    pub layout_version: u32,
    pub resolution: u32,
    pub instances: u32,
    pub triangles: u64,
    pub vertices: u64,
    pub geometry_crc: u32,
}

impl LayoutKey {
    /// The key of the layout `layout::layout(scene, world_from_node, resolution)` builds.
    pub fn of(scene: &Scene, world_from_node: &[Mat4], resolution: u32) -> Self {
        // Raw bytes of f32 and u32 arrays: little-endian on every target valgi builds for.
        let mut crc = crc32fast::Hasher::new();
        let mut used = vec![false; scene.meshes.len()];
        let (mut triangles, mut vertices) = (0u64, 0u64);
        for inst in &scene.instances {
            let mesh = &scene.meshes[inst.mesh];
            used[inst.mesh] = true;
            triangles += mesh.indices.len() as u64 / 3;
            vertices += mesh.positions.len() as u64;
            crc.update(&(inst.mesh as u64).to_le_bytes());
            let transform = world_from_node
                .get(inst.node)
                .copied()
                .unwrap_or(Mat4::IDENTITY);
            crc.update(bytemuck::cast_slice(&transform.to_cols_array()));
        }
        for (mesh, _) in scene.meshes.iter().zip(&used).filter(|(_, &u)| u) {
            for len in [mesh.positions.len(), mesh.normals.len(), mesh.indices.len()] {
                crc.update(&(len as u64).to_le_bytes());
            }
            crc.update(bytemuck::cast_slice(&mesh.positions));
            crc.update(bytemuck::cast_slice(&mesh.normals));
            crc.update(bytemuck::cast_slice(&mesh.indices));
            match &mesh.uv1 {
                Some(uv1) => {
                    crc.update(&(uv1.len() as u64).to_le_bytes());
                    crc.update(bytemuck::cast_slice(uv1));
                }
                None => crc.update(&u64::MAX.to_le_bytes()),
            }
        }
        Self {
            layout_version: LAYOUT_VERSION,
            resolution,
            instances: scene.instances.len() as u32,
            triangles,
            vertices,
            geometry_crc: crc.finalize(),
        }
    }

    /// Whether the scene's geometry and the resolution agree (the layout code's version may
    /// differ: see [`LayoutKey::differences`]).
    pub fn same_geometry(&self, other: &Self) -> bool {
        Self {
            layout_version: other.layout_version,
            ..*self
        } == *other
    }

    /// What differs between the key a layout was stored under (`self`) and the one the scene
    /// at hand has (`scene`), in words; empty when they are equal.
    pub fn differences(&self, scene: &Self) -> Vec<String> {
        let mut out = Vec::new();
        if self.resolution != scene.resolution {
            out.push(format!(
                "atlas resolution {} against {}",
                self.resolution, scene.resolution
            ));
        }
        if (self.instances, self.triangles, self.vertices)
            != (scene.instances, scene.triangles, scene.vertices)
        {
            out.push(format!(
                "{} instances, {} triangles, {} vertices against the scene's {}, {}, {}",
                self.instances,
                self.triangles,
                self.vertices,
                scene.instances,
                scene.triangles,
                scene.vertices
            ));
        } else if self.geometry_crc != scene.geometry_crc {
            out.push(format!(
                "geometry checksum {:08x} against the scene's {:08x} (same counts, other \
                 positions, transforms or triangles)",
                self.geometry_crc, scene.geometry_crc
            ));
        }
        if self.layout_version != scene.layout_version {
            out.push(format!(
                "layout version {} against this build's {}",
                self.layout_version, scene.layout_version
            ));
        }
        out
    }
}

/// One light-map mesh as the lookup draws it: the scene instance whose transform places it,
/// model-space positions, light-map UVs (v down) and triangles.
#[derive(Clone, Debug, PartialEq)]
pub struct LookupMesh {
    pub instance: u32,
    /// One face of a two-sided sheet: drawn with back faces culled.
    pub sheet_face: bool,
    pub model_positions: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub indices: Vec<u32>,
}

/// What the GPU lookup of an atlas needs of its layout: the meshes it draws, the texels that
/// stand for a surface point (to check the atlas covers them) and the contact cuts.
#[derive(Clone, Debug, PartialEq)]
pub struct LookupLayout {
    pub resolution: u32,
    /// `"texcoord1"` or `"generated"`.
    pub source: &'static str,
    pub meshes: Vec<LookupMesh>,
    /// Row-major indices of the surface texels, ascending.
    pub texels: Vec<u32>,
    /// Per cut texel (ascending), its packed pieces.
    pub cuts: Vec<(u32, [u32; CUTS_PER_TEXEL])>,
}

impl LookupLayout {
    pub fn of(layout: &AtlasLayout) -> Self {
        let mut texels: Vec<u32> = layout.texels.iter().map(|t| t.index).collect();
        texels.sort_unstable();
        let mut cuts: Vec<(u32, [u32; CUTS_PER_TEXEL])> =
            layout.cuts.texels.iter().map(|(&i, &c)| (i, c)).collect();
        cuts.sort_unstable_by_key(|&(i, _)| i);
        Self {
            resolution: layout.resolution,
            source: layout.source,
            meshes: layout
                .meshes
                .iter()
                .map(|m| LookupMesh {
                    instance: m.instance as u32,
                    sheet_face: m.sheet_face,
                    model_positions: m.model_positions.clone(),
                    uvs: m.uvs.clone(),
                    indices: m.indices.clone(),
                })
                .collect(),
            texels,
            cuts,
        }
    }

    /// Row-major `R × R` cut texture for the GPU (an `Rg32Uint` texture).
    pub fn dense_cuts(&self) -> Vec<[u32; CUTS_PER_TEXEL]> {
        ContactCuts {
            texels: self.cuts.iter().copied().collect(),
            ..Default::default()
        }
        .dense(self.resolution)
    }
}

/// A layout file's content.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredLayout {
    pub key: LayoutKey,
    /// The scene it was baked for (messages only).
    pub scene_name: String,
    /// The `--max-edge` of the bake (messages only; `None` when not known).
    pub max_edge: Option<f32>,
    pub lookup: LookupLayout,
}

impl StoredLayout {
    /// The layout `bake` used, keyed by the scene it baked (placed at `world_from_node`).
    pub fn of_bake(
        bake: &super::Bake,
        scene: &Scene,
        world_from_node: &[Mat4],
        max_edge: Option<f32>,
    ) -> Self {
        Self {
            key: LayoutKey::of(scene, world_from_node, bake.layout.resolution),
            scene_name: scene.name.clone(),
            max_edge,
            lookup: LookupLayout::of(&bake.layout),
        }
    }

    /// "scene 'cornell', --max-edge 0.05, 256²" for messages.
    pub fn describe(&self) -> String {
        let edge = self
            .max_edge
            .map(|e| format!(", --max-edge {e}"))
            .unwrap_or_default();
        format!(
            "scene '{}'{edge}, {res}²",
            self.scene_name,
            res = self.key.resolution
        )
    }
}

fn push_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn push_words(out: &mut Vec<u8>, words: impl IntoIterator<Item = u32>) {
    for w in words {
        push_u32(out, w);
    }
}

/// The file's bytes, checksum last; returns them with the checksum.
pub fn encode(stored: &StoredLayout) -> (Vec<u8>, u32) {
    let lookup = &stored.lookup;
    let mut out = Vec::new();
    out.extend_from_slice(&MAGIC);
    push_u32(&mut out, FORMAT_VERSION);
    let k = &stored.key;
    push_words(
        &mut out,
        [k.layout_version, k.resolution, k.instances, k.geometry_crc],
    );
    out.extend_from_slice(&k.triangles.to_le_bytes());
    out.extend_from_slice(&k.vertices.to_le_bytes());
    let name = stored.scene_name.as_bytes();
    let name = &name[..name.len().min(MAX_NAME_BYTES)];
    push_u32(&mut out, name.len() as u32);
    out.extend_from_slice(name);
    push_u32(&mut out, stored.max_edge.unwrap_or(f32::NAN).to_bits());
    push_u32(&mut out, u32::from(lookup.source == "texcoord1"));
    push_u32(&mut out, lookup.meshes.len() as u32);
    for m in &lookup.meshes {
        push_words(
            &mut out,
            [
                m.instance,
                u32::from(m.sheet_face),
                m.model_positions.len() as u32,
                m.indices.len() as u32,
            ],
        );
        push_words(
            &mut out,
            m.model_positions
                .iter()
                .flat_map(|p| p.to_array())
                .map(f32::to_bits),
        );
        push_words(
            &mut out,
            m.uvs.iter().flat_map(|t| t.to_array()).map(f32::to_bits),
        );
        push_words(&mut out, m.indices.iter().copied());
    }
    push_u32(&mut out, lookup.cuts.len() as u32);
    for (texel, pieces) in &lookup.cuts {
        push_u32(&mut out, *texel);
        push_words(&mut out, pieces.iter().copied());
    }
    let mut mask = vec![0u32; mask_words(lookup.resolution)];
    for &t in &lookup.texels {
        mask[(t / 32) as usize] |= 1 << (t % 32);
    }
    push_words(&mut out, mask);
    let checksum = crc32fast::hash(&out);
    push_u32(&mut out, checksum);
    (out, checksum)
}

fn mask_words(resolution: u32) -> usize {
    (resolution as usize * resolution as usize).div_ceil(32)
}

/// Writes the layout file for the atlas at `atlas` (through a temporary file renamed into
/// place); returns its checksum for the atlas's header.
pub fn write(atlas: &Path, stored: &StoredLayout) -> Result<u32, ImageError> {
    let path = layout_path(atlas);
    let (bytes, checksum) = encode(stored);
    crate::image_io::write_whole(&path, |partial| {
        std::fs::write(partial, &bytes).map_err(|e| e.to_string())
    })?;
    Ok(checksum)
}

/// Reads the layout file at `path` (see [`layout_path`]) and its checksum; every problem is an
/// error naming it.
pub fn read(path: &Path) -> Result<(StoredLayout, u32), String> {
    let fail = |message: String| format!("{}: {message}", path.display());
    let size = std::fs::metadata(path)
        .map_err(|e| fail(format!("cannot read: {e}")))?
        .len();
    if size > MAX_FILE_BYTES {
        return Err(fail(format!(
            "{size} bytes, more than any light-map layout ({MAX_FILE_BYTES} at most)"
        )));
    }
    let bytes = std::fs::read(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    decode(&bytes).map_err(fail)
}

/// Reads a little-endian stream, checking the length before every read.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let left = self.bytes.len() - self.at;
        if n > left {
            return Err(format!(
                "truncated or damaged: {what} needs {n} bytes at offset {}, {left} left",
                self.at
            ));
        }
        let out = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(out)
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().expect("4 bytes"),
        ))
    }

    fn u64(&mut self, what: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(
            self.take(8, what)?.try_into().expect("8 bytes"),
        ))
    }

    /// `count` words, refused before allocating when the rest of the file is shorter.
    fn words(&mut self, count: u64, what: &str) -> Result<Vec<u32>, String> {
        let n = count
            .checked_mul(4)
            .filter(|&n| n <= (self.bytes.len() - self.at) as u64)
            .ok_or_else(|| {
                format!(
                    "truncated or damaged: {count} words of {what} at offset {}, {} bytes left",
                    self.at,
                    self.bytes.len() - self.at
                )
            })? as usize;
        Ok(self
            .take(n, what)?
            .chunks_exact(4)
            .map(|w| u32::from_le_bytes(w.try_into().expect("4 bytes")))
            .collect())
    }

    fn floats(&mut self, count: u64, what: &str) -> Result<Vec<f32>, String> {
        let words = self.words(count, what)?;
        let floats: Vec<f32> = words.into_iter().map(f32::from_bits).collect();
        if let Some(i) = floats.iter().position(|f| !f.is_finite()) {
            return Err(format!("damaged: {what} value {i} is not finite"));
        }
        Ok(floats)
    }
}

/// Parses a layout file's bytes ([`encode`]'s form); returns it with its checksum.
pub fn decode(bytes: &[u8]) -> Result<(StoredLayout, u32), String> {
    if bytes.len() < MAGIC.len() + 8 || bytes[..MAGIC.len()] != MAGIC {
        return Err("not a valgi light-map layout file (no VALGILYT header)".into());
    }
    let (body, tail) = bytes.split_at(bytes.len() - 4);
    let stored_crc = u32::from_le_bytes(tail.try_into().expect("4 bytes"));
    let mut r = Reader {
        bytes: body,
        at: MAGIC.len(),
    };
    let version = r.u32("format version")?;
    if version != FORMAT_VERSION {
        return Err(format!(
            "layout file format {version}; this build reads format {FORMAT_VERSION} (bake the \
             atlas again)"
        ));
    }
    let actual_crc = crc32fast::hash(body);
    if actual_crc != stored_crc {
        return Err(format!(
            "damaged or truncated: checksum {actual_crc:08x}, the file says {stored_crc:08x}"
        ));
    }
    let key = LayoutKey {
        layout_version: r.u32("layout version")?,
        resolution: r.u32("resolution")?,
        instances: r.u32("instance count")?,
        geometry_crc: r.u32("geometry checksum")?,
        triangles: r.u64("triangle count")?,
        vertices: r.u64("vertex count")?,
    };
    let res = key.resolution;
    if !(16..=MAX_RESOLUTION).contains(&res) {
        return Err(format!(
            "damaged: atlas resolution {res} is out of range (16..{MAX_RESOLUTION})"
        ));
    }
    let name_len = r.u32("scene name length")? as usize;
    if name_len > MAX_NAME_BYTES {
        return Err(format!(
            "damaged: scene name of {name_len} bytes (at most {MAX_NAME_BYTES})"
        ));
    }
    let scene_name = String::from_utf8_lossy(r.take(name_len, "scene name")?).into_owned();
    let max_edge = Some(f32::from_bits(r.u32("max edge")?)).filter(|e| e.is_finite());
    let source = match r.u32("UV source")? {
        0 => "generated",
        1 => "texcoord1",
        other => return Err(format!("damaged: UV source {other} (0 or 1)")),
    };
    let mesh_count = r.u32("mesh count")?;
    // Each mesh takes at least its 16-byte header: a count beyond the rest is damage.
    if mesh_count as usize > (body.len() - r.at) / 16 {
        return Err(format!(
            "truncated or damaged: {mesh_count} meshes in {} bytes",
            body.len() - r.at
        ));
    }
    let mut meshes = Vec::with_capacity(mesh_count as usize);
    for mi in 0..mesh_count {
        let instance = r.u32("mesh instance")?;
        if instance >= key.instances {
            return Err(format!(
                "damaged: mesh {mi} places instance {instance} of {}",
                key.instances
            ));
        }
        let sheet_face = match r.u32("sheet flag")? {
            0 => false,
            1 => true,
            other => return Err(format!("damaged: mesh {mi} sheet flag {other}")),
        };
        let vertex_count = r.u32("vertex count")? as u64;
        let index_count = r.u32("index count")? as u64;
        if !index_count.is_multiple_of(3) {
            return Err(format!(
                "damaged: mesh {mi} has {index_count} indices (not whole triangles)"
            ));
        }
        let what = format!("mesh {mi}'s positions");
        let model_positions: Vec<Vec3> = r
            .floats(vertex_count * 3, &what)?
            .chunks_exact(3)
            .map(Vec3::from_slice)
            .collect();
        let what = format!("mesh {mi}'s light-map UVs");
        let uvs: Vec<Vec2> = r
            .floats(vertex_count * 2, &what)?
            .chunks_exact(2)
            .map(Vec2::from_slice)
            .collect();
        let indices = r.words(index_count, &format!("mesh {mi}'s indices"))?;
        if let Some(bad) = indices.iter().find(|&&i| i as u64 >= vertex_count) {
            return Err(format!(
                "damaged: mesh {mi} indexes vertex {bad} of {vertex_count}"
            ));
        }
        meshes.push(LookupMesh {
            instance,
            sheet_face,
            model_positions,
            uvs,
            indices,
        });
    }
    let texel_count = res as u64 * res as u64;
    let cut_count = r.u32("cut count")? as u64;
    let cut_words = r.words(cut_count * (1 + CUTS_PER_TEXEL as u64), "contact cuts")?;
    let mut cuts = Vec::with_capacity(cut_count as usize);
    for w in cut_words.chunks_exact(1 + CUTS_PER_TEXEL) {
        let texel = w[0];
        if texel as u64 >= texel_count || cuts.last().is_some_and(|&(t, _)| t >= texel) {
            return Err(format!(
                "damaged: cut texel {texel} out of order or outside {res}²"
            ));
        }
        let mut pieces = [0; CUTS_PER_TEXEL];
        pieces.copy_from_slice(&w[1..]);
        cuts.push((texel, pieces));
    }
    let mask = r.words(mask_words(res) as u64, "surface texel mask")?;
    let texels: Vec<u32> = (0..texel_count as u32)
        .filter(|&t| mask[(t / 32) as usize] & (1 << (t % 32)) != 0)
        .collect();
    if r.at != body.len() {
        return Err(format!(
            "damaged: {} bytes after the layout's end",
            body.len() - r.at
        ));
    }
    let stored = StoredLayout {
        key,
        scene_name,
        max_edge,
        lookup: LookupLayout {
            resolution: res,
            source,
            meshes,
            texels,
            cuts,
        },
    };
    Ok((stored, stored_crc))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two meshes (one a sheet face), a few cut texels and surface texels at 16².
    fn small_layout() -> StoredLayout {
        let quad = |instance, sheet_face, z| LookupMesh {
            instance,
            sheet_face,
            model_positions: vec![
                Vec3::new(0.0, 0.0, z),
                Vec3::new(1.0, 0.0, z),
                Vec3::new(1.0, 1.0, z),
                Vec3::new(0.0, 1.0, z),
            ],
            uvs: vec![
                Vec2::new(0.1, 0.1),
                Vec2::new(0.4, 0.1),
                Vec2::new(0.4, 0.4),
                Vec2::new(0.1, 0.4),
            ],
            indices: vec![0, 1, 2, 0, 2, 3],
        };
        StoredLayout {
            key: LayoutKey {
                layout_version: LAYOUT_VERSION,
                resolution: 16,
                instances: 2,
                triangles: 4,
                vertices: 8,
                geometry_crc: 0x1234_5678,
            },
            scene_name: "test-room".into(),
            max_edge: Some(0.25),
            lookup: LookupLayout {
                resolution: 16,
                source: "generated",
                meshes: vec![quad(0, false, 0.0), quad(1, true, 2.0)],
                texels: vec![17, 18, 33, 34, 255],
                cuts: vec![(18, [0x0102_0304, 0]), (34, [7, 9])],
            },
        }
    }

    /// The bytes with the trailing checksum made right again after an edit.
    fn reseal(bytes: &mut [u8]) {
        let n = bytes.len() - 4;
        let crc = crc32fast::hash(&bytes[..n]);
        bytes[n..].copy_from_slice(&crc.to_le_bytes());
    }

    /// Offset of the mesh count: magic, format, four key words, two u64, the name, max edge
    /// and source.
    fn mesh_count_offset(stored: &StoredLayout) -> usize {
        8 + 4 + 16 + 16 + 4 + stored.scene_name.len() + 4 + 4
    }

    #[test]
    fn a_layout_reads_back_as_written() {
        let stored = small_layout();
        let (bytes, checksum) = encode(&stored);
        let (read, read_checksum) = decode(&bytes).unwrap();
        assert_eq!(read, stored);
        assert_eq!(read_checksum, checksum);
        assert_eq!(read.lookup.dense_cuts()[34], [7, 9]);
    }

    #[test]
    fn every_truncation_and_every_flipped_byte_is_an_error() {
        let (bytes, _) = encode(&small_layout());
        for len in 0..bytes.len() {
            let err = decode(&bytes[..len]).unwrap_err();
            assert!(
                err.contains("truncated") || err.contains("not a valgi"),
                "{len}: {err}"
            );
        }
        for i in 0..bytes.len() {
            let mut damaged = bytes.clone();
            damaged[i] ^= 0x10;
            assert!(decode(&damaged).is_err(), "byte {i} flipped");
        }
    }

    #[test]
    fn absurd_counts_are_refused_before_allocating() {
        let stored = small_layout();
        let (bytes, _) = encode(&stored);
        let at = mesh_count_offset(&stored);
        assert_eq!(bytes[at..at + 4], 2u32.to_le_bytes());
        let mut many_meshes = bytes.clone();
        many_meshes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        reseal(&mut many_meshes);
        let err = decode(&many_meshes).unwrap_err();
        assert!(err.contains("4294967295 meshes"), "{err}");
        // The first mesh's vertex count: 2³² − 1 vertices of 20 bytes each.
        let mut many_vertices = bytes.clone();
        many_vertices[at + 12..at + 16].copy_from_slice(&u32::MAX.to_le_bytes());
        reseal(&mut many_vertices);
        let err = decode(&many_vertices).unwrap_err();
        assert!(err.contains("mesh 0's positions"), "{err}");
        // An index past the mesh's vertices (the first mesh's first index).
        let mut bad_index = bytes.clone();
        let first_index = at + 4 + 16 + 4 * 12 + 4 * 8;
        assert_eq!(bad_index[first_index..first_index + 4], 0u32.to_le_bytes());
        bad_index[first_index..first_index + 4].copy_from_slice(&4u32.to_le_bytes());
        reseal(&mut bad_index);
        let err = decode(&bad_index).unwrap_err();
        assert!(err.contains("indexes vertex 4 of 4"), "{err}");
    }

    #[test]
    fn another_format_version_is_named() {
        let (mut bytes, _) = encode(&small_layout());
        bytes[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
        reseal(&mut bytes);
        let err = decode(&bytes).unwrap_err();
        assert!(err.contains("format 2"), "{err}");
    }

    #[test]
    fn key_differences_name_what_changed() {
        let key = small_layout().key;
        assert!(key.differences(&key).is_empty());
        let finer = LayoutKey {
            triangles: 16,
            vertices: 18,
            ..key
        };
        let words = key.differences(&finer).join("; ");
        assert!(
            words.contains("4 triangles") && words.contains("16"),
            "{words}"
        );
        assert!(!key.same_geometry(&finer));
        let newer = LayoutKey {
            layout_version: key.layout_version + 1,
            ..key
        };
        assert!(key.same_geometry(&newer));
        assert!(key.differences(&newer)[0].contains("layout version"));
    }
}
