//! Light-map UVs and the atlas layout: which world point (and normal) every atlas texel stands
//! for. UVs come from TEXCOORD_1 when every placed mesh has it and is placed once; otherwise
//! charts are generated with `uvunwrap` (segmentation, flattening, packing with padding), one
//! input per placed instance in world space so every instance owns its texels.
//!
//! Texels are found by rasterizing every triangle in UV space at texel centres, then adding
//! the texels a triangle touches without covering a centre (edges, vertices, slivers: the
//! CPU form of the points-lines-triangles passes of seed 001 §4). A touched texel stands for
//! the triangle point closest to its centre.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use glam::{Mat3, Mat4, Vec2, Vec3};

use crate::scene::Scene;

/// UV-space mesh of one placed instance: world positions and normals at bake time, model
/// positions for rendering, and atlas UVs in [0, 1] (v down, texel (0, 0) at the top left).
#[derive(Clone, Debug)]
pub struct ChartMesh {
    pub instance: usize,
    pub material: usize,
    pub model_positions: Vec<Vec3>,
    pub world_positions: Vec<Vec3>,
    pub world_normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    /// The mesh's material texture coordinates (TEXCOORD_0) per vertex, empty when it has
    /// none: the bake reads the textured albedo at its sample points.
    pub material_uvs: Vec<Vec2>,
    pub indices: Vec<u32>,
    /// One face of a two-sided sheet ([`sheet_meshes`]): its triangles are wound
    /// counter-clockwise about its normals, and the lookup draws it with back faces culled so
    /// each side of the sheet reads its own texels.
    pub sheet_face: bool,
}

/// One atlas texel that stands for a surface point.
#[derive(Clone, Copy, Debug)]
pub struct Texel {
    /// Row-major texel index `y·R + x`.
    pub index: u32,
    pub position: Vec3,
    pub normal: Vec3,
    pub material: u32,
    /// True when a triangle covers the texel centre; false for texels only touched.
    pub centre: bool,
}

#[derive(Clone, Debug)]
pub struct AtlasLayout {
    pub resolution: u32,
    /// `"texcoord1"` or `"generated"`.
    pub source: &'static str,
    pub meshes: Vec<ChartMesh>,
    pub texels: Vec<Texel>,
    /// Lines where other geometry touches a surface; the lookup does not filter across them.
    pub cuts: super::cuts::ContactCuts,
}

/// World transform's normal matrix (inverse transpose).
fn normal_matrix(m: Mat4) -> Mat3 {
    let m3 = Mat3::from_mat4(m);
    if m3.determinant().abs() > 1e-20 {
        m3.inverse().transpose()
    } else {
        Mat3::IDENTITY
    }
}

type LayoutCache = Mutex<HashMap<u64, Arc<AtlasLayout>>>;

fn cache() -> &'static LayoutCache {
    static CACHE: OnceLock<LayoutCache> = OnceLock::new();
    CACHE.get_or_init(Default::default)
}

fn layout_key(scene: &Scene, world_from_node: &[Mat4], resolution: u32) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    resolution.hash(&mut h);
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh];
        inst.mesh.hash(&mut h);
        for v in world_from_node[inst.node].to_cols_array() {
            v.to_bits().hash(&mut h);
        }
        mesh.indices.hash(&mut h);
        for p in &mesh.positions {
            p.x.to_bits().hash(&mut h);
            p.y.to_bits().hash(&mut h);
            p.z.to_bits().hash(&mut h);
        }
        if let Some(uv1) = &mesh.uv1 {
            for t in uv1 {
                t.x.to_bits().hash(&mut h);
                t.y.to_bits().hash(&mut h);
            }
        }
    }
    h.finish()
}

/// The atlas layout of a scene placed at `world_from_node`, cached per scene content and
/// resolution in this process (bake and render of one scene share it).
pub fn layout(
    scene: &Scene,
    world_from_node: &[Mat4],
    resolution: u32,
) -> Result<Arc<AtlasLayout>, String> {
    let key = layout_key(scene, world_from_node, resolution);
    if let Some(found) = cache().lock().unwrap().get(&key) {
        return Ok(found.clone());
    }
    let built = Arc::new(build_layout(scene, world_from_node, resolution)?);
    cache().lock().unwrap().insert(key, built.clone());
    Ok(built)
}

/// The atlas layout built afresh (no cache): what [`layout`] builds the first time.
pub fn build_layout(
    scene: &Scene,
    world_from_node: &[Mat4],
    resolution: u32,
) -> Result<AtlasLayout, String> {
    if !(16..=MAX_RESOLUTION).contains(&resolution) {
        return Err(format!(
            "atlas resolution {resolution} is out of range (16..{MAX_RESOLUTION})"
        ));
    }
    let mut meshes = Vec::new();
    for (i, inst) in scene.instances.iter().enumerate() {
        let mesh = &scene.meshes[inst.mesh];
        if mesh.indices.is_empty() {
            continue;
        }
        let m = world_from_node[inst.node];
        let nm = normal_matrix(m);
        meshes.push(ChartMesh {
            instance: i,
            material: mesh.material,
            model_positions: mesh.positions.clone(),
            world_positions: mesh
                .positions
                .iter()
                .map(|&p| m.transform_point3(p))
                .collect(),
            world_normals: mesh
                .normals
                .iter()
                .map(|&n| (nm * n).try_normalize().unwrap_or(Vec3::Y))
                .collect(),
            uvs: Vec::new(),
            material_uvs: if mesh.uv0.len() == mesh.positions.len() {
                mesh.uv0.clone()
            } else {
                Vec::new()
            },
            indices: mesh.indices.clone(),
            sheet_face: false,
        });
    }
    if meshes.is_empty() {
        return Err(format!("scene '{}' has no triangles to bake", scene.name));
    }
    let mut uses = HashMap::new();
    for inst in &scene.instances {
        *uses.entry(inst.mesh).or_insert(0usize) += 1;
    }
    let all_uv1 = scene
        .instances
        .iter()
        .all(|inst| scene.meshes[inst.mesh].uv1.is_some() && uses[&inst.mesh] == 1);
    let started = std::time::Instant::now();
    let lap = |stage: &str| {
        log::info!(
            "atlas layout {resolution}²: {stage} done at {:.0} ms",
            started.elapsed().as_secs_f64() * 1000.0
        );
    };
    let source = if all_uv1 {
        for cm in &mut meshes {
            let inst = &scene.instances[cm.instance];
            cm.uvs = scene.meshes[inst.mesh].uv1.clone().unwrap_or_default();
        }
        "texcoord1"
    } else {
        // Refuse a resolution the charts cannot fit before the sheet test and the unwrap
        // (minutes on Sponza): every connected piece of a mesh is at least one chart.
        let pieces: usize = meshes.iter().map(connected_pieces).sum();
        let needed = min_resolution_for_charts(pieces);
        if needed > resolution {
            return Err(format!(
                "the meshes have at least {pieces} separate pieces, each a light-map chart of at \
                 least {side}×{side} texels with its padding: they need --atlas-res {needed} or \
                 more (got {resolution})",
                side = 1 + 2 * CHART_PADDING,
            ));
        }
        // Both faces of a zero-thickness sheet (a partition, a door) are seen, and one texel
        // cannot hold both sides' light: the back face gets charts of its own.
        for i in sheet_meshes(&meshes) {
            let mut back = meshes[i].clone();
            for n in &mut back.world_normals {
                *n = -*n;
            }
            for tri in back.indices.chunks_exact_mut(3) {
                tri.swap(1, 2);
            }
            back.sheet_face = true;
            meshes[i].sheet_face = true;
            meshes.push(back);
        }
        lap("sheet test");
        unwrap(scene, &mut meshes, resolution, pieces)?;
        lap("unwrap");
        for m in meshes.iter_mut().filter(|m| m.sheet_face) {
            orient_to_normals(m);
        }
        "generated"
    };
    let texels = find_texels(&meshes, resolution);
    lap("texels");
    let cuts = super::cuts::contact_cuts(&meshes, resolution);
    lap("contact cuts");
    Ok(AtlasLayout {
        resolution,
        source,
        meshes,
        texels,
        cuts,
    })
}

/// Largest atlas side.
pub const MAX_RESOLUTION: u32 = 4096;

/// Version of the layout this code builds, stored with every baked atlas's layout
/// (`stored_layout`): raise it whenever a change moves any chart, UV, sheet face, contact cut
/// or texel, so a layout file written before is recognised as another version's.
pub const LAYOUT_VERSION: u32 = 1;

/// Empty texels around every chart (charts are twice this apart).
const CHART_PADDING: u32 = 2;

/// Smallest square atlas side that can hold `charts` charts: each takes at least one texel
/// plus its padding on every side, (1 + 2p)² texels that no other chart's padded box
/// overlaps, so the side is at least (1 + 2p)·√charts.
pub fn min_resolution_for_charts(charts: usize) -> u32 {
    ((1 + 2 * CHART_PADDING) as f64 * (charts as f64).sqrt()).ceil() as u32
}

/// Connected pieces of a mesh with area: triangles joined through shared edges (index
/// pairs; the unwrapper cuts charts at split vertices, so pieces are a lower bound on its
/// charts).
fn connected_pieces(m: &ChartMesh) -> usize {
    let tris: Vec<[u32; 3]> = m
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let mut parent: Vec<usize> = (0..tris.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut by_edge: HashMap<(u32, u32), usize> = HashMap::with_capacity(tris.len() * 3 / 2);
    for (ti, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            if let Some(&other) = by_edge.get(&key) {
                let (ra, rb) = (root(&mut parent, ti), root(&mut parent, other));
                if ra != rb {
                    parent[ra] = rb;
                }
            } else {
                by_edge.insert(key, ti);
            }
        }
    }
    let has_area = |t: &[u32; 3]| {
        let p = t.map(|i| {
            m.world_positions
                .get(i as usize)
                .copied()
                .unwrap_or(Vec3::ZERO)
        });
        (p[1] - p[0]).cross(p[2] - p[0]).length_squared() > 0.0
    };
    let mut roots = std::collections::HashSet::new();
    for (ti, t) in tris.iter().enumerate() {
        if has_area(t) {
            roots.insert(root(&mut parent, ti));
        }
    }
    roots.len()
}

/// Rays per mesh of the sheet test.
const SHEET_RAYS: usize = 64;
/// A mesh is a sheet when at least this fraction of the rays leaving its back side hit the
/// front of a surface. Closed rooms (back sides face outwards: rays escape) and solid or
/// open-bottomed boxes (back sides face the box's own back faces) stay far below it; a wall
/// between two rooms is near 1.
const SHEET_FRACTION: f32 = 0.8;

/// Meshes whose back side faces the inside of the scene: zero-thickness sheets seen from both
/// sides. Brute-force ray casting from area-uniform points (fixed seed), directions
/// cosine-distributed about the back normal; a hit counts when it meets the front of a
/// triangle (vertex normals facing the ray).
pub fn sheet_meshes(meshes: &[ChartMesh]) -> Vec<usize> {
    use rayon::prelude::*;
    struct Tri {
        p: [Vec3; 3],
        n: Vec3,
        area: f32,
    }
    let tris: Vec<Vec<Tri>> = meshes
        .iter()
        .map(|m| {
            m.indices
                .chunks_exact(3)
                .map(|t| {
                    let p = [0, 1, 2].map(|k| m.world_positions[t[k] as usize]);
                    let n = [0, 1, 2]
                        .map(|k| m.world_normals[t[k] as usize])
                        .iter()
                        .sum::<Vec3>()
                        .normalize_or_zero();
                    let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
                    Tri { p, n, area }
                })
                .collect()
        })
        .collect();
    let (lo, hi) = tris.iter().flatten().flat_map(|t| t.p).fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(p), hi.max(p)),
    );
    let eps = 1e-4 * (hi - lo).length().max(1e-3);
    // A BVH over every triangle: the brute-force loop cost 64 rays × meshes × triangles, two
    // minutes on Sponza's 262k triangles in 25 meshes.
    let flat: Vec<&Tri> = tris.iter().flatten().collect();
    let bvh_tris: Vec<obvhs::triangle::Triangle> = flat
        .iter()
        .map(|t| obvhs::triangle::Triangle {
            v0: t.p[0].into(),
            v1: t.p[1].into(),
            v2: t.p[2].into(),
        })
        .collect();
    let bvh = (!bvh_tris.is_empty()).then(|| {
        obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &bvh_tris,
            obvhs::BvhBuildParams::medium_build(),
            &mut std::time::Duration::default(),
        )
    });
    let closest = |o: Vec3, d: Vec3| -> Option<(f32, Vec3)> {
        let bvh = bvh.as_ref()?;
        let ray = crate::trace::obvhs_ray(o, d, eps, f32::INFINITY);
        let mut hit = obvhs::ray::RayHit::none();
        let found = bvh.ray_traverse(ray, &mut hit, |ray, id| {
            bvh_tris[bvh.primitive_indices[id] as usize].intersect(ray)
        });
        if !found || !hit.t.is_finite() {
            return None;
        }
        let tri = bvh.primitive_indices[hit.primitive_id as usize] as usize;
        Some((hit.t, flat[tri].n))
    };
    (0..meshes.len())
        .into_par_iter()
        .filter(|&i| {
            let own = &tris[i];
            let total: f32 = own.iter().map(|t| t.area).sum();
            if own.is_empty() || total <= 0.0 {
                return false;
            }
            let mut state =
                0x9E37_79B9_7F4A_7C15u64 ^ (i as u64).wrapping_mul(0xA24B_AED4_963E_E407);
            let mut next = || {
                state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
                let mut z = state;
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
            };
            let mut front = 0;
            for _ in 0..SHEET_RAYS {
                let mut pick = next() * total;
                let t = own
                    .iter()
                    .find(|t| {
                        pick -= t.area;
                        pick <= 0.0
                    })
                    .unwrap_or(&own[own.len() - 1]);
                let (mut a, mut b) = (next(), next());
                if a + b > 1.0 {
                    (a, b) = (1.0 - a, 1.0 - b);
                }
                let p = t.p[0] + (t.p[1] - t.p[0]) * a + (t.p[2] - t.p[0]) * b;
                let back = -t.n;
                let (u1, u2) = (next(), next());
                let (r, phi) = (u1.sqrt(), std::f32::consts::TAU * u2);
                let (x, y) = back.any_orthonormal_pair();
                let d =
                    (x * (r * phi.cos()) + y * (r * phi.sin()) + back * (1.0 - u1).max(0.0).sqrt())
                        .normalize();
                if let Some((_, n)) = closest(p + back * eps, d) {
                    if n.dot(d) < 0.0 {
                        front += 1;
                    }
                }
            }
            front as f32 >= SHEET_FRACTION * SHEET_RAYS as f32
        })
        .collect()
}

/// Winds every triangle counter-clockwise about its vertex normals (front faces for the
/// lookup's culling).
fn orient_to_normals(m: &mut ChartMesh) {
    for tri in m.indices.chunks_exact_mut(3) {
        let p = [0, 1, 2].map(|k| m.world_positions[tri[k] as usize]);
        let n: Vec3 = [0, 1, 2]
            .map(|k| m.world_normals[tri[k] as usize])
            .iter()
            .sum();
        if (p[1] - p[0]).cross(p[2] - p[0]).dot(n) < 0.0 {
            tri.swap(1, 2);
        }
    }
}

/// Generated charts for every placed instance, packed into one page with 2 texels padding.
/// A mesh that has TEXCOORD_1 keeps its islands (repacked); the others are unwrapped.
/// Above this many mesh pieces the charts are packed row by row ([`uvunwrap::Packing::Fast`])
/// instead of by shape: shape packing's density search took 58 of the 71 s of Sponza's
/// layout (14k charts), and the layout is built again by every render that looks the atlas
/// up. The built-in scenes have far fewer pieces and keep their shape-packed layouts.
pub const FAST_PACKING_PIECES: usize = 1000;

fn unwrap(
    scene: &Scene,
    meshes: &mut [ChartMesh],
    resolution: u32,
    pieces: usize,
) -> Result<(), String> {
    let positions: Vec<Vec<[f32; 3]>> = meshes
        .iter()
        .map(|m| m.world_positions.iter().map(|p| p.to_array()).collect())
        .collect();
    let uv1: Vec<Option<Vec<[f32; 2]>>> = meshes
        .iter()
        .map(|m| {
            scene.meshes[scene.instances[m.instance].mesh]
                .uv1
                .as_ref()
                .map(|uv| uv.iter().map(|t| t.to_array()).collect())
        })
        .collect();
    let inputs: Vec<uvunwrap::MeshInput> = meshes
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let mut input = uvunwrap::MeshInput::new(&positions[i], &m.indices);
            input.existing_uvs = uv1[i].as_deref();
            input
        })
        .collect();
    let options = uvunwrap::Options {
        density: uvunwrap::Density::Auto {
            page_size: resolution,
        },
        padding: CHART_PADDING,
        packing: if pieces > FAST_PACKING_PIECES {
            uvunwrap::Packing::Fast
        } else {
            uvunwrap::Packing::Shape
        },
        ..Default::default()
    };
    let started = std::time::Instant::now();
    let last_stage = Mutex::new(None);
    let atlas = uvunwrap::generate_with_progress(&inputs, &options, |p| {
        let mut last = last_stage.lock().unwrap_or_else(|e| e.into_inner());
        if *last != Some(p.stage) {
            log::info!(
                "unwrap: {:?} from {:.0} ms",
                p.stage,
                started.elapsed().as_secs_f64() * 1000.0
            );
            *last = Some(p.stage);
        }
        true
    })
    .map_err(|e| format!("unwrap: {e:?}"))?;
    log::info!(
        "unwrap: {} charts, {} page(s) at {:.3} texels/m",
        atlas.chart_count,
        atlas.page_count,
        atlas.texels_per_unit
    );
    if atlas.page_count > 1 {
        // P pages of R² hold the charts at the fallback density, so one page of R·√P does;
        // no page under (1 + 2p)·√charts can. Rounded up to a multiple of 64.
        let pages = (resolution as f64 * (atlas.page_count as f64).sqrt()).ceil() as u32;
        let needed = pages.max(min_resolution_for_charts(atlas.chart_count as usize));
        let needed = needed.div_ceil(64) * 64;
        return Err(if needed <= MAX_RESOLUTION {
            format!(
                "the {} charts need {} atlas pages at {resolution}²; use --atlas-res {needed} \
                 (one page of {resolution}·√{} texels holds them)",
                atlas.chart_count, atlas.page_count, atlas.page_count
            )
        } else {
            format!(
                "the {} charts need {} atlas pages at {resolution}², about {needed}² on one page, \
                 beyond the largest atlas ({MAX_RESOLUTION}²)",
                atlas.chart_count, atlas.page_count
            )
        });
    }
    // uvunwrap's UVs are relative to the (possibly cropped) page; rescale to the square atlas.
    let sx = atlas.width as f32 / resolution as f32;
    let sy = atlas.height as f32 / resolution as f32;
    for (cm, out) in meshes.iter_mut().zip(&atlas.meshes) {
        let xref: Vec<usize> = out.vertices.iter().map(|v| v.xref as usize).collect();
        cm.model_positions = xref.iter().map(|&i| cm.model_positions[i]).collect();
        cm.world_positions = xref.iter().map(|&i| cm.world_positions[i]).collect();
        cm.world_normals = xref.iter().map(|&i| cm.world_normals[i]).collect();
        if !cm.material_uvs.is_empty() {
            cm.material_uvs = xref.iter().map(|&i| cm.material_uvs[i]).collect();
        }
        cm.uvs = out
            .vertices
            .iter()
            .map(|v| Vec2::new(v.uv[0] * sx, v.uv[1] * sy))
            .collect();
        cm.indices = out.indices.clone();
    }
    Ok(())
}

/// Whether triangle (a, b, c) overlaps the axis-aligned square [lo, hi] (separating axes).
pub fn triangle_overlaps_square(a: Vec2, b: Vec2, c: Vec2, lo: Vec2, hi: Vec2) -> bool {
    let tmin = a.min(b).min(c);
    let tmax = a.max(b).max(c);
    if tmax.x < lo.x || tmin.x > hi.x || tmax.y < lo.y || tmin.y > hi.y {
        return false;
    }
    let corners = [lo, Vec2::new(hi.x, lo.y), hi, Vec2::new(lo.x, hi.y)];
    for (p, q, r) in [(a, b, c), (b, c, a), (c, a, b)] {
        let e = q - p;
        let axis = Vec2::new(-e.y, e.x);
        let side = axis.dot(r - p);
        // The square is separated when all corners lie strictly on the other side.
        if corners.iter().all(|&k| axis.dot(k - p) * side < 0.0) {
            return false;
        }
    }
    true
}

/// Barycentric coordinates of the point of triangle (a, b, c) closest to p (2D).
pub fn closest_barycentric(p: Vec2, a: Vec2, b: Vec2, c: Vec2) -> Vec3 {
    if let Some(w) = barycentric(p, a, b, c) {
        if w.min_element() >= 0.0 {
            return w;
        }
    }
    let seg = |p: Vec2, a: Vec2, b: Vec2| {
        let ab = b - a;
        let len2 = ab.length_squared();
        let t = if len2 > 0.0 {
            ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (t, (a + ab * t).distance_squared(p))
    };
    let (t0, d0) = seg(p, a, b);
    let (t1, d1) = seg(p, b, c);
    let (t2, d2) = seg(p, c, a);
    if d0 <= d1 && d0 <= d2 {
        Vec3::new(1.0 - t0, t0, 0.0)
    } else if d1 <= d2 {
        Vec3::new(0.0, 1.0 - t1, t1)
    } else {
        Vec3::new(t2, 0.0, 1.0 - t2)
    }
}

fn barycentric(p: Vec2, a: Vec2, b: Vec2, c: Vec2) -> Option<Vec3> {
    let v0 = b - a;
    let v1 = c - a;
    let det = v0.perp_dot(v1);
    if det.abs() < 1e-20 {
        return None;
    }
    let v2 = p - a;
    let w1 = v2.perp_dot(v1) / det;
    let w2 = v0.perp_dot(v2) / det;
    Some(Vec3::new(1.0 - w1 - w2, w1, w2))
}

/// Calls `visit(texel index, barycentrics)` for every texel whose centre the triangle (in
/// texel units) covers, in row order, until `visit` returns false. The barycentrics are
/// clamped to the triangle and normalized.
fn for_each_covered_centre(
    t: &[Vec2; 3],
    resolution: u32,
    mut visit: impl FnMut(usize, Vec3) -> bool,
) {
    let r = resolution as i64;
    let lo = t[0].min(t[1]).min(t[2]);
    let hi = t[0].max(t[1]).max(t[2]);
    let clamp = |v: f32| (v.floor() as i64).clamp(0, r - 1);
    for y in clamp(lo.y)..=clamp(hi.y) {
        for x in clamp(lo.x)..=clamp(hi.x) {
            let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            if let Some(w) = barycentric(p, t[0], t[1], t[2]) {
                if w.min_element() >= -1e-6 {
                    let w = w.max(Vec3::ZERO);
                    if !visit((y * r + x) as usize, w / w.element_sum()) {
                        return;
                    }
                }
            }
        }
    }
}

/// The figures of seed 001's light-map pre-pass (§4 and its table) for a layout. The paper
/// rasterizes the uv triangles and keeps T_uv, the triangles that produce at least one texel
/// (at texel centres); texels that only its point and line passes reach become the point list
/// P_uv. Here the same texels come from the conservative coverage of
/// [`rasterize_uv_triangles`]: P_uv are the used texels no triangle covers at the centre
/// (filled from the nearest triangle point, [`Texel::centre`] false).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrepassFigures {
    /// Triangles of the layout's meshes (a two-sided sheet's back face counted again).
    pub triangles: usize,
    pub t_uv: usize,
    pub p_uv: usize,
    pub used_texels: usize,
}

impl PrepassFigures {
    pub fn of(layout: &AtlasLayout) -> Self {
        let scale = layout.resolution as f32;
        let mut triangles = 0;
        let mut t_uv = 0;
        for m in &layout.meshes {
            for tri in m.indices.chunks_exact(3) {
                let uv = [0, 1, 2].map(|k| m.uvs[tri[k] as usize] * scale);
                let mut produces = false;
                for_each_covered_centre(&uv, layout.resolution, |_, _| {
                    produces = true;
                    false
                });
                triangles += 1;
                t_uv += produces as usize;
            }
        }
        Self {
            triangles,
            t_uv,
            p_uv: layout.texels.iter().filter(|t| !t.centre).count(),
            used_texels: layout.texels.len(),
        }
    }

    pub fn to_json(self) -> serde_json::Value {
        serde_json::json!({
            "triangles": self.triangles,
            "t_uv": self.t_uv,
            "p_uv": self.p_uv,
            "used_texels": self.used_texels,
        })
    }
}

/// Texels of triangles given in texel units: first the texels whose centre a triangle covers,
/// then the touched ones no triangle covers, each standing for the closest triangle point.
/// Returns (texel index, triangle index, barycentrics, covers centre).
pub fn rasterize_uv_triangles(
    triangles: &[[Vec2; 3]],
    resolution: u32,
) -> Vec<(u32, usize, Vec3, bool)> {
    let r = resolution as i64;
    let mut owner: Vec<Option<(usize, Vec3, bool)>> = vec![None; (r * r) as usize];
    let bbox = |t: &[Vec2; 3]| {
        let lo = t[0].min(t[1]).min(t[2]);
        let hi = t[0].max(t[1]).max(t[2]);
        (
            (lo.x.floor() as i64).clamp(0, r - 1),
            (lo.y.floor() as i64).clamp(0, r - 1),
            (hi.x.floor() as i64).clamp(0, r - 1),
            (hi.y.floor() as i64).clamp(0, r - 1),
        )
    };
    // Pass 1: centres covered.
    for (ti, t) in triangles.iter().enumerate() {
        for_each_covered_centre(t, resolution, |i, w| {
            let slot = &mut owner[i];
            if slot.is_none() {
                *slot = Some((ti, w, true));
            }
            true
        });
    }
    // Pass 2: touched but not covered (edges, vertices, slivers).
    for (ti, t) in triangles.iter().enumerate() {
        let (x0, y0, x1, y1) = bbox(t);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let i = (y * r + x) as usize;
                if owner[i].is_some() {
                    continue;
                }
                let lo = Vec2::new(x as f32, y as f32);
                if triangle_overlaps_square(t[0], t[1], t[2], lo, lo + Vec2::ONE) {
                    let w = closest_barycentric(lo + Vec2::splat(0.5), t[0], t[1], t[2]);
                    owner[i] = Some((ti, w, false));
                }
            }
        }
    }
    owner
        .into_iter()
        .enumerate()
        .filter_map(|(i, o)| o.map(|(t, w, c)| (i as u32, t, w, c)))
        .collect()
}

fn find_texels(meshes: &[ChartMesh], resolution: u32) -> Vec<Texel> {
    let scale = resolution as f32;
    let mut triangles = Vec::new();
    let mut refs = Vec::new();
    for (mi, m) in meshes.iter().enumerate() {
        for (ti, tri) in m.indices.chunks_exact(3).enumerate() {
            triangles.push([
                m.uvs[tri[0] as usize] * scale,
                m.uvs[tri[1] as usize] * scale,
                m.uvs[tri[2] as usize] * scale,
            ]);
            refs.push((mi, ti));
        }
    }
    rasterize_uv_triangles(&triangles, resolution)
        .into_iter()
        .map(|(index, t, w, centre)| {
            let (mi, ti) = refs[t];
            let m = &meshes[mi];
            let idx = &m.indices[ti * 3..ti * 3 + 3];
            let p = |a: &[Vec3]| {
                a[idx[0] as usize] * w.x + a[idx[1] as usize] * w.y + a[idx[2] as usize] * w.z
            };
            let face = (m.world_positions[idx[1] as usize] - m.world_positions[idx[0] as usize])
                .cross(m.world_positions[idx[2] as usize] - m.world_positions[idx[0] as usize]);
            let mut normal = p(&m.world_normals).try_normalize().unwrap_or(Vec3::Y);
            if let Some(f) = face.try_normalize() {
                if f.dot(normal) < 0.0 {
                    normal = -normal;
                }
            }
            Texel {
                index,
                position: p(&m.world_positions),
                normal,
                material: m.material as u32,
                centre,
            }
        })
        .collect()
}

/// Fills empty texels next to filled ones with the mean of their filled neighbours, `passes`
/// times, so bilinear lookups at chart borders never blend in black. `filled` marks texels
/// that hold values; it is updated.
pub fn dilate(values: &mut [[f32; 3]], filled: &mut [bool], resolution: u32, passes: u32) {
    let r = resolution as i64;
    for _ in 0..passes {
        let mut updates = Vec::new();
        for y in 0..r {
            for x in 0..r {
                let i = (y * r + x) as usize;
                if filled[i] {
                    continue;
                }
                let mut sum = [0.0f32; 3];
                let mut n = 0;
                for (dx, dy) in [
                    (-1, 0),
                    (1, 0),
                    (0, -1),
                    (0, 1),
                    (-1, -1),
                    (1, 1),
                    (-1, 1),
                    (1, -1),
                ] {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= r || ny >= r {
                        continue;
                    }
                    let j = (ny * r + nx) as usize;
                    if filled[j] {
                        for c in 0..3 {
                            sum[c] += values[j][c];
                        }
                        n += 1;
                    }
                }
                if n > 0 {
                    updates.push((i, sum.map(|s| s / n as f32)));
                }
            }
        }
        if updates.is_empty() {
            break;
        }
        for (i, v) in updates {
            values[i] = v;
            filled[i] = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sliver_that_covers_no_centre_still_gets_texels() {
        // A needle from (0.6, 2.1) to (9.4, 2.3), far thinner than a texel and below the row
        // of centres at y = 2.5: plain rasterization finds nothing.
        let sliver = [
            Vec2::new(0.6, 2.1),
            Vec2::new(9.4, 2.3),
            Vec2::new(9.4, 2.31),
        ];
        let found = rasterize_uv_triangles(&[sliver], 16);
        assert!(found.iter().all(|f| !f.3), "no centre is covered");
        let xs: Vec<u32> = found.iter().map(|f| f.0 % 16).collect();
        for x in 0..=9 {
            assert!(
                xs.contains(&x),
                "texel column {x} touched by the sliver: {xs:?}"
            );
        }
        for f in &found {
            assert_eq!(f.0 / 16, 2, "only row 2 is touched");
            assert!((f.2.element_sum() - 1.0).abs() < 1e-5 && f.2.min_element() >= 0.0);
        }
    }

    #[test]
    fn prepass_figures_count_the_triangles_that_make_texels_and_the_texels_they_miss() {
        // In a 16² atlas: a quad of two triangles over [2.1, 5.9]² (texel units), inside
        // texels 2..=5 and over their centres, and a micro triangle inside texel (10, 10)
        // that covers no centre.
        let uv = |x: f32, y: f32| Vec2::new(x, y) / 16.0;
        let positions = vec![Vec3::ZERO; 7];
        let mesh = ChartMesh {
            instance: 0,
            material: 0,
            model_positions: positions.clone(),
            world_positions: positions,
            world_normals: vec![Vec3::Y; 7],
            uvs: vec![
                uv(2.1, 2.1),
                uv(5.9, 2.1),
                uv(5.9, 5.9),
                uv(2.1, 5.9),
                uv(10.1, 10.1),
                uv(10.3, 10.1),
                uv(10.1, 10.3),
            ],
            material_uvs: vec![],
            indices: vec![0, 1, 2, 0, 2, 3, 4, 5, 6],
            sheet_face: false,
        };
        let meshes = vec![mesh];
        let layout = AtlasLayout {
            resolution: 16,
            source: "texcoord1",
            texels: find_texels(&meshes, 16),
            meshes,
            cuts: Default::default(),
        };
        let figures = PrepassFigures::of(&layout);
        // The quad covers the 16 centres of its texels and reaches no other texel; the micro
        // triangle produces no centre, only its one touched texel.
        assert_eq!(
            figures,
            PrepassFigures {
                triangles: 3,
                t_uv: 2,
                p_uv: 1,
                used_texels: 17,
            }
        );
    }

    #[test]
    fn every_touched_texel_is_found_once() {
        // A triangle with edges through texel interiors: the found set is exactly the texels
        // whose square overlaps it, centres first.
        let t = [
            Vec2::new(1.3, 1.2),
            Vec2::new(7.7, 2.9),
            Vec2::new(3.1, 6.6),
        ];
        let found = rasterize_uv_triangles(&[t], 10);
        let mut expected = 0;
        for y in 0..10 {
            for x in 0..10 {
                let lo = Vec2::new(x as f32, y as f32);
                if triangle_overlaps_square(t[0], t[1], t[2], lo, lo + Vec2::ONE) {
                    expected += 1;
                    assert!(found.iter().any(|f| f.0 == y * 10 + x), "texel ({x}, {y})");
                }
            }
        }
        assert_eq!(found.len(), expected);
        assert!(found.iter().any(|f| f.3) && found.iter().any(|f| !f.3));
    }

    #[test]
    fn square_overlap_and_closest_point() {
        let (a, b, c) = (Vec2::ZERO, Vec2::new(4.0, 0.0), Vec2::new(0.0, 4.0));
        assert!(triangle_overlaps_square(
            a,
            b,
            c,
            Vec2::new(1.0, 1.0),
            Vec2::new(2.0, 2.0)
        ));
        // Beyond the hypotenuse x + y = 4.
        assert!(!triangle_overlaps_square(
            a,
            b,
            c,
            Vec2::new(2.6, 2.6),
            Vec2::new(3.5, 3.5)
        ));
        let w = closest_barycentric(Vec2::new(3.0, 3.0), a, b, c);
        let p = a * w.x + b * w.y + c * w.z;
        assert!((p - Vec2::new(2.0, 2.0)).length() < 1e-5, "{p}");
    }

    #[test]
    fn dilation_fills_the_padding_from_the_chart() {
        let res = 6;
        let mut values = vec![[0.0f32; 3]; 36];
        let mut filled = vec![false; 36];
        values[2 * 6 + 2] = [1.0, 2.0, 3.0];
        filled[2 * 6 + 2] = true;
        dilate(&mut values, &mut filled, res, 2);
        assert_eq!(values[6 + 1], [1.0, 2.0, 3.0]);
        assert_eq!(values[4 * 6 + 4], [1.0, 2.0, 3.0]);
        assert!(!filled[5 * 6 + 5], "two passes reach two texels");
    }
}
