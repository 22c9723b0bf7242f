//! The scene as a two-level BVH on the GPU, for shadow rays of indirect light
//! (`shaders/base/bvh.wgsl`): one binary BVH per mesh in model space, built once (the mesh's
//! flat regions merged, so a tessellated wall is two triangles again), and per frame the
//! instances' `model_from_world` matrices and world bounds under a top-level BVH over those
//! bounds. Rigid motion therefore rebuilds only the top level (milliseconds for 10⁴
//! instances), never a mesh, and a ray visits the instances near it rather than all of them.
//! [`SceneBvh::occluded`] is the CPU twin of the WGSL query.
//!
//! Both levels are laid out for a walk without a stack ([`threaded`]): depth-first preorder,
//! a node's left child right after it, and each inner node holding the index just past its
//! subtree, where the walk goes when the segment misses the node. A shader's private array is
//! zero-filled on every call, and on the software Vulkan driver the two 64-entry stacks of
//! the walk this replaced were half the visibility pass's time.

use std::sync::Arc;
use std::time::Duration;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::resources::GpuBytes;
use crate::gpu::{GpuContext, GpuError};
use crate::scene::merge::flat_region_indices;
use crate::scene::{Aabb, Material, Scene};

/// `bvh.wgsl`'s group: the mesh nodes, the triangles, the instances and the top-level nodes,
/// all as texels ([`BVH_ROW_TEXELS`]).
const BVH_BINDINGS: &[Slot] = &[Slot::UintTexture; 4];

/// Texels per row of the node and triangle textures (`BVH_ROW_SHIFT` in `bvh.wgsl` is its
/// log2): texel t is at (t mod 4096, t div 4096). A node is 2 texels, a triangle 3, an
/// instance 6.
///
/// Why textures: a shadow ray's walk reads nodes and triangles at addresses that differ from
/// lane to lane. On a CPU device (Mesa 22.3's llvmpipe) such a read from a storage buffer is a
/// loop over the lanes, with a bounds test and a scalar load per lane and component; a texel
/// fetch is one gathered load per component. A kernel reading 4096 random vec4s per
/// invocation (65536 invocations) took 3.58 s from a storage buffer, 3.30 s from workgroup
/// memory and 0.82 s from an rgba32 texture (each less the 0.10 s of its index arithmetic).
pub const BVH_ROW_TEXELS: u32 = 4096;
const _: () = assert!(
    BVH_ROW_TEXELS.is_power_of_two(),
    "bvh.wgsl shifts and masks"
);

/// One BVH node in [`threaded`] order: a leaf when `prim_count > 0` (triangles
/// `first..first + prim_count` of its mesh), otherwise an inner node whose left child is the
/// next node and whose subtree ends before node `first` (indices relative to the tree's root).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub prim_count: u32,
    pub max: [f32; 3],
    pub first: u32,
}

/// One model-space triangle as a vertex and two edges (the Möller–Trumbore form).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct BvhTriangle {
    pub v0: [f32; 4],
    pub e1: [f32; 4],
    pub e2: [f32; 4],
}

/// One instance for the top level: where its mesh's nodes and triangles start, its world
/// bounds (the ray skips the instance when it misses them) and the matrix into model space.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct BvhInstance {
    pub model_from_world: [[f32; 4]; 4],
    /// xyz: world-space minimum; w: the first node of the mesh (bits).
    pub world_min: [f32; 4],
    /// xyz: world-space maximum; w: the first triangle of the mesh (bits).
    pub world_max: [f32; 4],
}

/// Where a mesh's part of the flat arrays starts.
#[derive(Clone, Copy, Debug, Default)]
struct MeshRange {
    first_node: u32,
    first_triangle: u32,
    /// Model-space bounds of the mesh's triangles (empty when it has none).
    min: Vec3,
    max: Vec3,
    empty: bool,
}

/// Every mesh's BVH in its model space (the bottom level), flattened, and their texels: built
/// once per scene and shared by every [`SceneBvh`] over it (budget mode's pilots build the
/// sparse method once per candidate; on Sponza this build was 0.4 s of each).
pub struct MeshBvhs {
    pub nodes: Vec<BvhNode>,
    pub triangles: Vec<BvhTriangle>,
    /// Where each mesh's nodes and triangles start.
    ranges: Vec<MeshRange>,
    node_texels: wgpu::Texture,
    triangle_texels: wgpu::Texture,
    pub bytes: GpuBytes,
}

/// A scene's shadow-ray BVH: its meshes' BVHs and the top level over the instances placed
/// this frame, with their GPU texels.
pub struct SceneBvh {
    /// The bottom level, which other BVHs over the scene may share.
    pub bottom: Arc<MeshBvhs>,
    /// The instances with triangles, in the top level's leaf order (a leaf's instances are
    /// contiguous); written each frame by [`SceneBvh::update`].
    pub instances: Vec<BvhInstance>,
    /// The top level over the instances' world boxes, [`threaded`] like the mesh nodes: leaves
    /// hold `prim_count` instances from `first`.
    pub top_nodes: Vec<BvhNode>,
    /// The instances [`SceneBvh::update`] built the top level from (scene order), so a
    /// frame that places them the same way skips the rebuild and the upload.
    placed: Option<Vec<BvhInstance>>,
    /// The instances and top-level nodes as rgba32uint texels ([`BVH_ROW_TEXELS`] a row),
    /// rewritten by [`SceneBvh::update`].
    pub instance_texels: wgpu::Texture,
    pub top_texels: wgpu::Texture,
    /// The GPU bytes of the whole BVH, the shared mesh level's included.
    pub bytes: GpuBytes,
    /// Bind group 1 of the shaders that include `bvh.wgsl`.
    pub layout: GroupLayout,
    pub group: wgpu::BindGroup,
}

/// An rgba32uint texture of [`BVH_ROW_TEXELS`]-wide rows that holds `texels` texels, and its
/// bytes; an error naming `what` when its rows exceed the device's texture height. The BVH's
/// records and the visibility pass's copy of the VALs use this layout (texel t at
/// (t mod width, t div width)).
pub fn texel_row_texture(
    ctx: &GpuContext,
    what: &str,
    texels: u64,
    remedy: &str,
) -> Result<(wgpu::Texture, u64), GpuError> {
    let texels = texels.max(1);
    let rows = texels.div_ceil(u64::from(BVH_ROW_TEXELS));
    let size = rows * u64::from(BVH_ROW_TEXELS) * 16;
    let most = u64::from(ctx.device.limits().max_texture_dimension_2d);
    if rows > most {
        return Err(GpuError::Allocation {
            what: what.to_string(),
            size: crate::gpu::format_bytes(size),
            message: format!(
                "{texels} texels need {rows} rows of {BVH_ROW_TEXELS}; the device's 2D textures \
                 have at most {most}"
            ),
            remedy: remedy.to_string(),
        });
    }
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(what),
        size: wgpu::Extent3d {
            width: BVH_ROW_TEXELS,
            height: rows as u32,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Uint,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    Ok((texture, size))
}

/// `words` (4 per texel) in a [`texel_row_texture`], the rest of its last row zero.
fn texel_rows(
    ctx: &GpuContext,
    what: &str,
    words: &[u32],
    remedy: &str,
) -> Result<(wgpu::Texture, u64), GpuError> {
    let (texture, size) = texel_row_texture(ctx, what, (words.len() / 4) as u64, remedy)?;
    write_texel_rows(ctx, &texture, words);
    Ok((texture, size))
}

/// Rewrites the first texels of a [`texel_rows`] texture with `words` (whole rows, the rest of
/// the last one zero).
fn write_texel_rows(ctx: &GpuContext, texture: &wgpu::Texture, words: &[u32]) {
    let row_words = BVH_ROW_TEXELS as usize * 4;
    let rows = words.len().div_ceil(row_words).max(1) as u32;
    let mut data = vec![0u32; rows as usize * row_words];
    data[..words.len()].copy_from_slice(words);
    ctx.queue.write_texture(
        texture.as_image_copy(),
        bytemuck::cast_slice(&data),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(BVH_ROW_TEXELS * 16),
            rows_per_image: Some(rows),
        },
        wgpu::Extent3d {
            width: BVH_ROW_TEXELS,
            height: rows,
            depth_or_array_layers: 1,
        },
    );
}

/// Builds one mesh's BVH over its merged triangles; returns its nodes and triangles in leaf
/// order (so a leaf's triangles are contiguous).
fn build_mesh(positions: &[Vec3], indices: &[u32]) -> (Vec<BvhNode>, Vec<BvhTriangle>) {
    let triangles: Vec<Triangle> = indices
        .chunks_exact(3)
        .filter_map(|t| {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| positions.get(i as usize).copied());
            let (a, b, c) = (a?, b?, c?);
            (a.is_finite() && b.is_finite() && c.is_finite()).then_some(Triangle {
                v0: a.into(),
                v1: b.into(),
                v2: c.into(),
            })
        })
        .collect();
    if triangles.is_empty() {
        return (vec![], vec![]);
    }
    let bvh = build_bvh2_from_tris(
        &triangles,
        BvhBuildParams::medium_build(),
        &mut Duration::default(),
    );
    let nodes = threaded(&flat_nodes(&bvh));
    let ordered = bvh
        .primitive_indices
        .iter()
        .map(|&i| {
            let t = &triangles[i as usize];
            let v0 = Vec3::from(t.v0);
            BvhTriangle {
                v0: v0.extend(0.0).into(),
                e1: (Vec3::from(t.v1) - v0).extend(0.0).into(),
                e2: (Vec3::from(t.v2) - v0).extend(0.0).into(),
            }
        })
        .collect();
    (nodes, ordered)
}

/// An obvhs tree's nodes as [`BvhNode`]s, same indices: an inner node's children at `first`
/// and `first + 1` (the input of [`threaded`]).
fn flat_nodes(bvh: &obvhs::bvh2::Bvh2) -> Vec<BvhNode> {
    bvh.nodes
        .iter()
        .map(|n| BvhNode {
            min: Vec3::from(n.aabb.min).into(),
            prim_count: n.prim_count,
            max: Vec3::from(n.aabb.max).into(),
            first: n.first_index,
        })
        .collect()
}

/// The binary tree `nodes` (root 0, an inner node's children at `first` and `first + 1`) in
/// depth-first preorder for a walk without a stack: a leaf keeps its primitive range; an inner
/// node's left child is the node after it, and its `first` becomes the index just past its
/// subtree. The walk starts at 0 and, at node i, goes to i + 1 when the segment enters the box
/// of an inner node or after a leaf, and to `first` when it misses an inner node's box; it
/// ends at the root's `first` (1 for a lone leaf). Each node is visited when its parent's box
/// was entered, as with a stack, but no stack is kept.
pub fn threaded(nodes: &[BvhNode]) -> Vec<BvhNode> {
    enum Step {
        Enter(u32),
        // The inner node written at this index: its subtree ends here.
        Close(usize),
    }
    let mut out = Vec::with_capacity(nodes.len());
    if nodes.is_empty() {
        return out;
    }
    let mut steps = vec![Step::Enter(0)];
    while let Some(step) = steps.pop() {
        match step {
            Step::Enter(i) => {
                let node = nodes[i as usize];
                out.push(node);
                if node.prim_count == 0 {
                    steps.push(Step::Close(out.len() - 1));
                    steps.push(Step::Enter(node.first + 1));
                    steps.push(Step::Enter(node.first));
                }
            }
            Step::Close(at) => out[at].first = out.len() as u32,
        }
    }
    out
}

/// Where the walk over a [`threaded`] tree whose root is `root` ends.
fn walk_end(root: &BvhNode) -> u32 {
    if root.prim_count > 0 {
        1
    } else {
        root.first
    }
}

/// The stackless walk over the [`threaded`] tree whose root is `nodes[0]` (the CPU twin of the
/// loops in `bvh.wgsl`): true as soon as `leaf_hit` is true for a leaf whose box the segment
/// (`origin` + t·dir, t in [0, 1], `inv` = 1/dir) enters.
fn walk(
    nodes: &[BvhNode],
    origin: Vec3,
    inv: Vec3,
    mut leaf_hit: impl FnMut(&BvhNode) -> bool,
) -> bool {
    let end = walk_end(&nodes[0]);
    let mut i = 0u32;
    while i < end {
        let node = &nodes[i as usize];
        let leaf = node.prim_count > 0;
        let entered = ray_box(origin, inv, 1.0, node.min.into(), node.max.into());
        if entered && leaf && leaf_hit(node) {
            return true;
        }
        // `bvh_next`: the next node after a leaf or into an entered inner node, else past the
        // inner node's subtree.
        i = if entered || leaf { i + 1 } else { node.first };
    }
    false
}

/// Möller–Trumbore: the ray parameter of the hit, if the segment's line hits the triangle
/// (both faces) at t in (0, t_max) ([`crate::scene::pick::ray_triangle`]).
pub fn ray_triangle(origin: Vec3, dir: Vec3, t_max: f32, tri: &BvhTriangle) -> Option<f32> {
    let corner = |v: &[f32; 4]| Vec3::from_slice(&v[..3]);
    crate::scene::pick::ray_triangle(
        origin,
        dir,
        corner(&tri.v0),
        corner(&tri.e1),
        corner(&tri.e2),
    )
    .map(|(t, _, _)| t)
    .filter(|&t| t < t_max)
}

pub use crate::scene::pick::{ray_box, safe_inverse};

/// The texels of `words` for the BVH of `scene` (`what` names the part in a size error),
/// their bytes added to `bytes`.
fn bvh_texels(
    ctx: &GpuContext,
    scene: &Scene,
    what: &str,
    words: &[u32],
    bytes: &mut GpuBytes,
) -> Result<wgpu::Texture, GpuError> {
    let remedy = "Use a coarser --max-edge, or a scene with fewer triangles or instances";
    let name = format!("the shadow-ray BVH {what} of scene '{}'", scene.name);
    texel_rows(ctx, &name, words, remedy).map(|(texture, size)| {
        bytes.0 += size;
        texture
    })
}

impl MeshBvhs {
    /// `scene`'s mesh BVHs, the ones a live user of the same content (`content_key`,
    /// [`Scene::content_key`]) holds on this device or else new ones
    /// ([`GpuContext::live_by_key`]).
    pub fn shared(
        ctx: &GpuContext,
        scene: &Scene,
        content_key: u64,
    ) -> Result<Arc<Self>, GpuError> {
        ctx.live_by_key(content_key, || Self::new(ctx, scene))
    }

    pub fn new(ctx: &GpuContext, scene: &Scene) -> Result<Self, GpuError> {
        let mut nodes = Vec::new();
        let mut triangles = Vec::new();
        let mut ranges = Vec::with_capacity(scene.meshes.len());
        for mesh in &scene.meshes {
            let textured = scene
                .materials
                .get(mesh.material)
                .is_some_and(Material::has_textures);
            let indices = flat_region_indices(mesh, textured);
            let (mesh_nodes, mesh_triangles) = build_mesh(&mesh.positions, &indices);
            let range = match mesh_nodes.first() {
                Some(root) => MeshRange {
                    first_node: nodes.len() as u32,
                    first_triangle: triangles.len() as u32,
                    min: Vec3::from(root.min),
                    max: Vec3::from(root.max),
                    empty: false,
                },
                None => MeshRange {
                    empty: true,
                    ..MeshRange::default()
                },
            };
            ranges.push(range);
            nodes.extend(mesh_nodes);
            triangles.extend(mesh_triangles);
        }
        // wgpu rejects zero-sized storage bindings: keep one inert record of each.
        if nodes.is_empty() {
            nodes.push(BvhNode::default());
        }
        if triangles.is_empty() {
            triangles.push(BvhTriangle::default());
        }
        let mut bytes = GpuBytes::default();
        let node_texels = bvh_texels(
            ctx,
            scene,
            "nodes",
            bytemuck::cast_slice(&nodes),
            &mut bytes,
        )?;
        let triangle_texels = bvh_texels(
            ctx,
            scene,
            "triangles",
            bytemuck::cast_slice(&triangles),
            &mut bytes,
        )?;
        Ok(Self {
            nodes,
            triangles,
            ranges,
            node_texels,
            triangle_texels,
            bytes,
        })
    }
}

impl SceneBvh {
    /// The BVH of `scene`, its mesh level shared with the live BVHs of the same content
    /// ([`MeshBvhs::shared`]).
    pub fn new(ctx: &GpuContext, scene: &Scene) -> Result<Self, GpuError> {
        Self::over(
            ctx,
            scene,
            MeshBvhs::shared(ctx, scene, scene.content_key())?,
        )
    }

    /// The BVH of `scene` over `bottom`, its meshes' BVHs (which other BVHs may share).
    pub fn over(ctx: &GpuContext, scene: &Scene, bottom: Arc<MeshBvhs>) -> Result<Self, GpuError> {
        let instances = vec![BvhInstance::default(); scene.instances.len().max(1)];
        // A binary tree over n leaves has at most 2n − 1 nodes.
        let top_nodes = vec![UNREACHABLE_LEAF; 2 * scene.instances.len().max(1)];
        let mut bytes = bottom.bytes;
        let instance_texels = bvh_texels(
            ctx,
            scene,
            "instances",
            bytemuck::cast_slice(&instances),
            &mut bytes,
        )?;
        let top_texels = bvh_texels(
            ctx,
            scene,
            "top-level nodes",
            bytemuck::cast_slice(&top_nodes),
            &mut bytes,
        )?;
        let layout = Self::layout(ctx);
        let view = |texture: &wgpu::Texture| texture.create_view(&Default::default());
        let group = layout.bind(
            &ctx.device,
            &[
                &view(&bottom.node_texels),
                &view(&bottom.triangle_texels),
                &view(&instance_texels),
                &view(&top_texels),
            ],
        );
        Ok(Self {
            bottom,
            instances,
            top_nodes,
            placed: None,
            instance_texels,
            top_texels,
            bytes,
            layout,
            group,
        })
    }

    /// The BVH's bind-group layout, one per device, so that pipelines made for one scene's
    /// BVH (and shared by every user of the device) take another's group.
    pub fn layout(ctx: &GpuContext) -> GroupLayout {
        struct Shared(GroupLayout);
        let shared = ctx.shared(|| {
            let cs = wgpu::ShaderStages::COMPUTE;
            Ok::<_, std::convert::Infallible>(Shared(GroupLayout::new(
                &ctx.device,
                "scene bvh",
                cs,
                BVH_BINDINGS,
            )))
        });
        match shared {
            Ok(shared) => shared.0.clone(),
            Err(never) => match never {},
        }
    }

    /// Places the instances for this frame and builds the top level over them (CPU records
    /// and their upload). Instances without triangles or with a singular matrix are left out:
    /// no ray can hit them.
    pub fn update(&mut self, ctx: &GpuContext, scene: &Scene, world_from_node: &[Mat4]) {
        let placed: Vec<BvhInstance> = scene
            .instances
            .iter()
            .filter_map(|inst| {
                let range = self.bottom.ranges[inst.mesh];
                let world_from_model = world_from_node[inst.node];
                let invertible = world_from_model.determinant().abs() > 1e-30;
                if range.empty || !invertible || !world_from_model.is_finite() {
                    return None;
                }
                let world = Aabb {
                    min: range.min,
                    max: range.max,
                }
                .transformed(world_from_model);
                Some(BvhInstance {
                    model_from_world: world_from_model.inverse().to_cols_array_2d(),
                    world_min: world.min.extend(f32::from_bits(range.first_node)).into(),
                    world_max: world
                        .max
                        .extend(f32::from_bits(range.first_triangle))
                        .into(),
                })
            })
            .collect();
        // A scene at rest places its instances the same way every frame: keep the last build.
        if self.placed.as_ref() == Some(&placed) {
            return;
        }
        let (top_nodes, instances) = build_top_level(&placed);
        self.placed = Some(placed);
        self.top_nodes = top_nodes;
        self.instances = instances;
        write_texel_rows(
            ctx,
            &self.instance_texels,
            bytemuck::cast_slice(&self.instances),
        );
        write_texel_rows(ctx, &self.top_texels, bytemuck::cast_slice(&self.top_nodes));
    }

    /// True when something lies on the segment from `from` to `to` (ends excluded by the
    /// caller's offsets): the CPU twin of `segment_occluded` in `shaders/base/bvh.wgsl`. The
    /// top level is walked like a mesh BVH; at its leaves each instance's box is tested, then
    /// its mesh in model space.
    pub fn occluded(&self, from: Vec3, to: Vec3) -> bool {
        let d = to - from;
        let inv = safe_inverse(d);
        walk(&self.top_nodes, from, inv, |leaf| {
            let instances = &self.instances[leaf.first as usize..][..leaf.prim_count as usize];
            instances.iter().any(|inst| {
                let world_min = Vec3::from_slice(&inst.world_min[..3]);
                let world_max = Vec3::from_slice(&inst.world_max[..3]);
                if !ray_box(from, inv, 1.0, world_min, world_max) {
                    return false;
                }
                let m = Mat4::from_cols_array_2d(&inst.model_from_world);
                // Model-space direction of the whole segment: t stays in [0, 1] in both spaces.
                let (origin, dir) = (m.transform_point3(from), m.transform_vector3(d));
                let first_node = inst.world_min[3].to_bits() as usize;
                let first_triangle = inst.world_max[3].to_bits() as usize;
                walk(
                    &self.bottom.nodes[first_node..],
                    origin,
                    safe_inverse(dir),
                    |leaf| {
                        let triangles =
                            &self.bottom.triangles[first_triangle + leaf.first as usize..];
                        triangles[..leaf.prim_count as usize]
                            .iter()
                            .any(|tri| ray_triangle(origin, dir, 1.0, tri).is_some())
                    },
                )
            })
        })
    }
}

/// The top level's root when no instance can be hit: a leaf whose box no segment inside the
/// scene reaches, so its one (inert) instance is never read. A slab test is symmetric in min
/// and max, so an inverted box would not do.
const UNREACHABLE_LEAF: BvhNode = BvhNode {
    min: [f32::MAX; 3],
    prim_count: 1,
    max: [f32::MAX; 3],
    first: 0,
};

/// Builds the top level over `instances`' world boxes; returns its nodes (root first) and the
/// instances in leaf order.
fn build_top_level(instances: &[BvhInstance]) -> (Vec<BvhNode>, Vec<BvhInstance>) {
    if instances.is_empty() {
        return (vec![UNREACHABLE_LEAF], vec![BvhInstance::default()]);
    }
    let boxes: Vec<obvhs::aabb::Aabb> = instances
        .iter()
        .map(|inst| {
            obvhs::aabb::Aabb::new(
                glam::Vec3A::from_slice(&inst.world_min[..3]),
                glam::Vec3A::from_slice(&inst.world_max[..3]),
            )
        })
        .collect();
    let bvh = obvhs::bvh2::builder::build_bvh2(
        &boxes,
        BvhBuildParams::fast_build(),
        &mut Duration::default(),
    );
    let nodes = threaded(&flat_nodes(&bvh));
    let ordered = bvh
        .primitive_indices
        .iter()
        .map(|&i| instances[i as usize])
        .collect();
    (nodes, ordered)
}

/// Struct layouts shared with WGSL.
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::shared_layout;
    vec![
        shared_layout!(
            "BvhNode",
            "bvh.wgsl",
            BvhNode,
            [min, prim_count, max, first]
        ),
        shared_layout!("BvhTriangle", "bvh.wgsl", BvhTriangle, [v0, e1, e2]),
        shared_layout!(
            "BvhInstance",
            "bvh.wgsl",
            BvhInstance,
            [model_from_world, world_min, world_max]
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 300 small random triangles in a 10 m cube (a deterministic xorshift stream).
    fn random_mesh() -> (Vec<Vec3>, Vec<u32>) {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut positions = Vec::new();
        for _ in 0..300 {
            let centre = Vec3::new(next(), next(), next()) * 10.0;
            for _ in 0..3 {
                positions.push(centre + (Vec3::new(next(), next(), next()) - 0.5) * 1.5);
            }
        }
        let indices = (0..positions.len() as u32).collect();
        (positions, indices)
    }

    /// Nodes in the subtree of node `i` of a threaded tree, read from its layout: 1 for a leaf;
    /// an inner node, its left subtree (from i + 1) and its right subtree (after the left).
    fn subtree_size(nodes: &[BvhNode], i: usize) -> usize {
        if nodes[i].prim_count > 0 {
            return 1;
        }
        let left = subtree_size(nodes, i + 1);
        1 + left + subtree_size(nodes, i + 1 + left)
    }

    #[test]
    fn a_threaded_tree_skips_exactly_a_subtree_and_its_walk_reaches_every_leaf_once() {
        let (positions, indices) = random_mesh();
        let (nodes, triangles) = build_mesh(&positions, &indices);
        assert!(nodes.len() > 100, "{} nodes", nodes.len());
        assert_eq!(subtree_size(&nodes, 0), nodes.len());
        for (i, node) in nodes.iter().enumerate() {
            if node.prim_count == 0 {
                assert_eq!(node.first as usize, i + subtree_size(&nodes, i), "node {i}");
            }
        }
        // With every box entered (boxes widened to cover any segment) the walk reaches each
        // leaf once, so every triangle once.
        let mut open = nodes.clone();
        for node in &mut open {
            node.min = [-1e9; 3];
            node.max = [1e9; 3];
        }
        let mut seen = vec![0u32; triangles.len()];
        let hit = walk(&open, Vec3::ZERO, safe_inverse(Vec3::ONE), |leaf| {
            for k in leaf.first..leaf.first + leaf.prim_count {
                seen[k as usize] += 1;
            }
            false
        });
        assert!(!hit);
        assert!(seen.iter().all(|&n| n == 1), "{seen:?}");
    }

    #[test]
    fn the_stackless_walk_finds_what_testing_every_triangle_finds() {
        let (positions, indices) = random_mesh();
        let (nodes, triangles) = build_mesh(&positions, &indices);
        let mut state = 12345u32;
        let mut next = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..2000 {
            let from = Vec3::new(next(), next(), next()) * 12.0 - 1.0;
            let to = Vec3::new(next(), next(), next()) * 12.0 - 1.0;
            let dir = to - from;
            let every = triangles
                .iter()
                .any(|tri| ray_triangle(from, dir, 1.0, tri).is_some());
            let walked = walk(&nodes, from, safe_inverse(dir), |leaf| {
                triangles[leaf.first as usize..][..leaf.prim_count as usize]
                    .iter()
                    .any(|tri| ray_triangle(from, dir, 1.0, tri).is_some())
            });
            assert_eq!(walked, every, "segment {from} → {to}");
            if every {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(hits > 200 && misses > 200, "{hits} hits, {misses} misses");
    }
}
