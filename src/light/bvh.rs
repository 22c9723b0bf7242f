//! The scene as a two-level BVH on the GPU, for shadow rays of indirect light
//! (`shaders/base/bvh.wgsl`): one binary BVH per mesh in model space, built once (the mesh's
//! flat regions merged, so a tessellated wall is two triangles again), and per frame the
//! instances' `model_from_world` matrices and world bounds under a top-level BVH over those
//! bounds. Rigid motion therefore rebuilds only the top level (milliseconds for 10⁴
//! instances), never a mesh, and a ray visits the instances near it rather than all of them.
//! [`SceneBvh::occluded`] is the CPU twin of the WGSL query.

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
/// all read-only.
const BVH_BINDINGS: &[Slot] = &[Slot::Storage, Slot::Storage, Slot::Storage, Slot::Storage];

/// One BVH node: a leaf when `prim_count > 0` (triangles `first..first + prim_count` of its
/// mesh), otherwise an inner node whose children are nodes `first` and `first + 1` of its mesh.
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

/// The per-mesh BVHs of a scene, flattened, and their GPU buffers.
pub struct SceneBvh {
    pub nodes: Vec<BvhNode>,
    pub triangles: Vec<BvhTriangle>,
    meshes: Vec<MeshRange>,
    /// The instances with triangles, in the top level's leaf order (a leaf's instances are
    /// contiguous); written each frame by [`SceneBvh::update`].
    pub instances: Vec<BvhInstance>,
    /// The top level over the instances' world boxes: leaves hold `prim_count` instances from
    /// `first`, inner nodes their children at `first`, `first + 1` (as the mesh nodes).
    pub top_nodes: Vec<BvhNode>,
    /// The instances [`SceneBvh::update`] built the top level from (scene order), so a
    /// frame that places them the same way skips the rebuild and the upload.
    placed: Option<Vec<BvhInstance>>,
    pub node_buffer: wgpu::Buffer,
    pub triangle_buffer: wgpu::Buffer,
    pub instance_buffer: wgpu::Buffer,
    pub top_buffer: wgpu::Buffer,
    pub bytes: GpuBytes,
    /// Bind group 1 of the shaders that include `bvh.wgsl`.
    pub layout: GroupLayout,
    pub group: wgpu::BindGroup,
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
    let nodes = flat_nodes(&bvh);
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

/// An obvhs tree's nodes in the layout the shader reads (same indices).
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

/// The deepest BVH the shader's traversal stack holds.
pub const STACK_DEPTH: usize = 64;

impl SceneBvh {
    pub fn new(ctx: &GpuContext, scene: &Scene) -> Result<Self, GpuError> {
        let mut nodes = Vec::new();
        let mut triangles = Vec::new();
        let mut meshes = Vec::with_capacity(scene.meshes.len());
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
            meshes.push(range);
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
        let instances = vec![BvhInstance::default(); scene.instances.len().max(1)];
        // A binary tree over n leaves has at most 2n − 1 nodes.
        let top_nodes = vec![UNREACHABLE_LEAF; 2 * scene.instances.len().max(1)];
        for (what, size) in [
            ("nodes", std::mem::size_of_val(nodes.as_slice())),
            ("triangles", std::mem::size_of_val(triangles.as_slice())),
            ("instances", std::mem::size_of_val(instances.as_slice())),
        ] {
            ctx.check_storage_buffer(
                &format!("the shadow-ray BVH {what} of scene '{}'", scene.name),
                size as u64,
                "Use a coarser --max-edge, or a scene with fewer triangles or instances",
            )?;
        }
        let mut bytes = GpuBytes::default();
        let init = |bytes: &mut GpuBytes, label: &str, data: &[u8]| {
            use wgpu::util::DeviceExt;
            bytes.0 += data.len() as u64;
            ctx.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: data,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                })
        };
        let node_buffer = init(&mut bytes, "bvh nodes", bytemuck::cast_slice(&nodes));
        let triangle_buffer = init(
            &mut bytes,
            "bvh triangles",
            bytemuck::cast_slice(&triangles),
        );
        let instance_buffer = init(
            &mut bytes,
            "bvh instances",
            bytemuck::cast_slice(&instances),
        );
        let top_buffer = init(&mut bytes, "bvh top", bytemuck::cast_slice(&top_nodes));
        let layout = Self::layout(ctx);
        let group = layout.bind(
            &ctx.device,
            &[
                &node_buffer,
                &triangle_buffer,
                &instance_buffer,
                &top_buffer,
            ],
        );
        Ok(Self {
            nodes,
            triangles,
            meshes,
            instances,
            top_nodes,
            placed: None,
            node_buffer,
            triangle_buffer,
            instance_buffer,
            top_buffer,
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
                let range = self.meshes[inst.mesh];
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
        ctx.queue.write_buffer(
            &self.instance_buffer,
            0,
            bytemuck::cast_slice(&self.instances),
        );
        ctx.queue
            .write_buffer(&self.top_buffer, 0, bytemuck::cast_slice(&self.top_nodes));
    }

    /// True when something lies on the segment from `from` to `to` (ends excluded by the
    /// caller's offsets): the CPU twin of `segment_occluded` in `shaders/base/bvh.wgsl`. The
    /// top level is walked like a mesh BVH; at its leaves each instance's box is tested, then
    /// its mesh in model space.
    pub fn occluded(&self, from: Vec3, to: Vec3) -> bool {
        let d = to - from;
        let inv = safe_inverse(d);
        let mut stack = [0u32; STACK_DEPTH];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let node = self.top_nodes[stack[top] as usize];
            if !ray_box(from, inv, 1.0, node.min.into(), node.max.into()) {
                continue;
            }
            if node.prim_count == 0 {
                if top + 2 <= STACK_DEPTH {
                    stack[top] = node.first;
                    stack[top + 1] = node.first + 1;
                    top += 2;
                }
                continue;
            }
            for inst in
                &self.instances[node.first as usize..(node.first + node.prim_count) as usize]
            {
                let world_min = Vec3::from_slice(&inst.world_min[..3]);
                let world_max = Vec3::from_slice(&inst.world_max[..3]);
                if !ray_box(from, inv, 1.0, world_min, world_max) {
                    continue;
                }
                let m = Mat4::from_cols_array_2d(&inst.model_from_world);
                let origin = m.transform_point3(from);
                // Model-space direction of the whole segment: t stays in [0, 1] in both spaces.
                let dir = m.transform_vector3(d);
                let first_node = inst.world_min[3].to_bits() as usize;
                let first_triangle = inst.world_max[3].to_bits() as usize;
                if self.mesh_hit(origin, dir, first_node, first_triangle) {
                    return true;
                }
            }
        }
        false
    }

    fn mesh_hit(&self, origin: Vec3, dir: Vec3, first_node: usize, first_triangle: usize) -> bool {
        let inv = safe_inverse(dir);
        let mut stack = [0u32; STACK_DEPTH];
        let mut top = 1usize;
        stack[0] = 0;
        while top > 0 {
            top -= 1;
            let node = self.nodes[first_node + stack[top] as usize];
            if !ray_box(origin, inv, 1.0, node.min.into(), node.max.into()) {
                continue;
            }
            if node.prim_count > 0 {
                for i in 0..node.prim_count {
                    let tri = &self.triangles[first_triangle + (node.first + i) as usize];
                    if ray_triangle(origin, dir, 1.0, tri).is_some() {
                        return true;
                    }
                }
            } else if top + 2 <= STACK_DEPTH {
                stack[top] = node.first;
                stack[top + 1] = node.first + 1;
                top += 2;
            }
        }
        false
    }

    /// The deepest path from a mesh root or the top level's root to a leaf (the shader's
    /// stack must hold it).
    pub fn max_depth(&self) -> usize {
        self.meshes
            .iter()
            .filter(|m| !m.empty)
            .map(|m| tree_depth(&self.nodes[m.first_node as usize..], 0))
            .fold(tree_depth(&self.top_nodes, 0), usize::max)
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
    let nodes = flat_nodes(&bvh);
    if tree_depth(&nodes, 0) > STACK_DEPTH {
        // Deeper than the shader's stack: one leaf of every instance is slower but exact.
        let all = boxes
            .iter()
            .fold(obvhs::aabb::Aabb::empty(), |a, b| a.union(b));
        let root = BvhNode {
            min: Vec3::from(all.min).into(),
            prim_count: instances.len() as u32,
            max: Vec3::from(all.max).into(),
            first: 0,
        };
        return (vec![root], instances.to_vec());
    }
    let ordered = bvh
        .primitive_indices
        .iter()
        .map(|&i| instances[i as usize])
        .collect();
    (nodes, ordered)
}

/// Longest root-to-leaf path of the binary tree `nodes` rooted at `root`.
fn tree_depth(nodes: &[BvhNode], root: u32) -> usize {
    let mut deepest = 0;
    let mut stack = vec![(root, 1usize)];
    while let Some((i, depth)) = stack.pop() {
        deepest = deepest.max(depth);
        let node = nodes[i as usize];
        if node.prim_count == 0 {
            stack.push((node.first, depth + 1));
            stack.push((node.first + 1, depth + 1));
        }
    }
    deepest
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
