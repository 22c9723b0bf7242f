//! What builds of the sparse method over one scene share.

use std::cell::{OnceCell, RefCell};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use crate::gpu::GpuContext;
use crate::light::bvh::MeshBvhs;
use crate::raster::scene_gpu::SceneGpu;
use crate::raster::RenderError;
use crate::scene::Scene;
use crate::trace::Tracer;

use super::points::{self, LinkCut, MeshPoints};
use super::recent::Recent;

/// A point count's preprocessing: the placed points with their links cut, what the cut did,
/// and how many meshes' points were computed rather than taken from the process-wide cache.
#[derive(Clone)]
pub struct PreparedPoints {
    pub points: Vec<Arc<MeshPoints>>,
    pub link_cut: LinkCut,
    pub meshes_computed: usize,
}

/// The parts of a sparse build that depend on the scene alone (its upload, its meshes' BVHs,
/// the link test's tracer) and, per point count, the preprocessing, each made on first use.
/// Budget mode builds the method once per pilot and once more for its choice, all over one
/// scene: on Sponza (657k triangles, 8192 points, lavapipe) the upload was 0.8 s of a 3.7 s
/// build, the tracer 0.6 s, the meshes' BVHs 0.4 s and the link test's rays 0.9 s.
///
/// Beyond one cache, builds over the same scene content share too (the viewer's rebuilds,
/// `valgi eval`'s warm-up instance): the upload and the BVHs with any live build on the device
/// ([`SceneGpu::shared`], [`MeshBvhs::shared`]), the link-tested points with the last few
/// builds in the process ([`KEPT_LINK_CUTS`]).
pub struct SceneCache<'s> {
    pub scene: &'s Scene,
    content_key: OnceCell<u64>,
    scene_gpu: OnceCell<Arc<SceneGpu>>,
    mesh_bvhs: OnceCell<Arc<MeshBvhs>>,
    tracer: OnceCell<Tracer<'s>>,
    /// By (point count, seed, link test).
    points: RefCell<HashMap<(usize, u64, bool), PreparedPoints>>,
}

/// What `cell` keeps, made by `make` on first use (a failure keeps nothing).
fn kept<T>(
    cell: &OnceCell<Arc<T>>,
    make: impl FnOnce() -> Result<Arc<T>, RenderError>,
) -> Result<Arc<T>, RenderError> {
    if let Some(value) = cell.get() {
        return Ok(value.clone());
    }
    let value = make()?;
    Ok(cell.get_or_init(|| value).clone())
}

impl<'s> SceneCache<'s> {
    pub fn new(scene: &'s Scene) -> Self {
        Self {
            scene,
            content_key: OnceCell::new(),
            scene_gpu: OnceCell::new(),
            mesh_bvhs: OnceCell::new(),
            tracer: OnceCell::new(),
            points: RefCell::new(HashMap::new()),
        }
    }

    /// [`Scene::content_key`], computed once (53 ms on Sponza).
    fn content_key(&self) -> u64 {
        *self.content_key.get_or_init(|| self.scene.content_key())
    }

    /// The scene's upload (vertices, indices, instances, materials and their textures).
    pub fn scene_gpu(&self, ctx: &GpuContext) -> Result<Arc<SceneGpu>, RenderError> {
        kept(&self.scene_gpu, || {
            Ok(SceneGpu::shared(ctx, self.scene, self.content_key())?)
        })
    }

    /// The shadow rays' bottom level: every mesh's BVH in model space.
    pub fn mesh_bvhs(&self, ctx: &GpuContext) -> Result<Arc<MeshBvhs>, RenderError> {
        kept(&self.mesh_bvhs, || {
            Ok(MeshBvhs::shared(ctx, self.scene, self.content_key())?)
        })
    }

    /// `total` sparse points placed by area and turn with `seed`, their links cut through
    /// walls when `link_test` is on (`points::cut_links_with`); an error when a mesh would
    /// get more points than its links address.
    pub fn points(
        &self,
        total: usize,
        seed: u64,
        link_test: bool,
    ) -> Result<PreparedPoints, RenderError> {
        let key = (total, seed, link_test);
        if let Some(prepared) = self.points.borrow().get(&key) {
            return Ok(PreparedPoints {
                meshes_computed: 0,
                ..prepared.clone()
            });
        }
        let scene = self.scene;
        // Measures each mesh's turn (`points::curvature_boost`): computed once, for the size
        // check and the placement both.
        let counts = points::points_per_mesh(scene, total);
        if let Some((mesh, count)) = points::oversized_mesh(scene, &counts) {
            return Err(RenderError::Settings(format!(
                "--sparse-points {total}: mesh '{mesh}' of scene '{}' would get {count} sparse \
                 points; links address at most {} per mesh: lower --sparse-points",
                scene.name,
                points::MAX_POINTS_PER_MESH
            )));
        }
        let kept_key = (self.content_key(), total, seed);
        let prepared = match link_test.then(|| kept_link_cut(kept_key)).flatten() {
            Some(kept) => kept,
            None => {
                let (placed, meshes_computed) = points::scene_points_for(scene, &counts, seed);
                let (points, link_cut) = if link_test {
                    points::cut_links_with(scene, &placed, &self.tracer)
                } else {
                    (placed, LinkCut::default())
                };
                let prepared = PreparedPoints {
                    points,
                    link_cut,
                    meshes_computed,
                };
                if link_test {
                    keep_link_cut(kept_key, &prepared);
                }
                prepared
            }
        };
        self.points.borrow_mut().insert(key, prepared.clone());
        Ok(prepared)
    }
}

/// How many link-tested point sets the process keeps, the most recently used. The placement
/// itself is cached per mesh (`points::scene_points_for`); the link test needs the whole
/// scene's tracer and its rays (1.5 s on Sponza at 8192 points), which a rebuild with another
/// RSM side or occlusion would otherwise pay again.
pub const KEPT_LINK_CUTS: usize = 4;

/// (scene content, point count, seed).
type LinkCutKey = (u64, usize, u64);

/// Link-tested point sets by [`LinkCutKey`], at most [`KEPT_LINK_CUTS`] (each costs 1).
type KeptLinkCuts = Recent<LinkCutKey, PreparedPoints>;

static LINK_CUTS: Mutex<KeptLinkCuts> = Mutex::new(Recent::new(KEPT_LINK_CUTS));

/// The set `kept` holds for `key`, now the most recently used; counted as computed nowhere.
fn take(kept: &mut KeptLinkCuts, key: LinkCutKey) -> Option<PreparedPoints> {
    kept.get(&key).map(|prepared| PreparedPoints {
        meshes_computed: 0,
        ..prepared.clone()
    })
}

fn kept_link_cut(key: LinkCutKey) -> Option<PreparedPoints> {
    take(&mut *LINK_CUTS.lock().ok()?, key)
}

fn keep_link_cut(key: LinkCutKey, prepared: &PreparedPoints) {
    if let Ok(mut kept) = LINK_CUTS.lock() {
        kept.insert(key, prepared.clone(), 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prepared(links: usize) -> PreparedPoints {
        PreparedPoints {
            points: vec![],
            link_cut: LinkCut {
                meshes: 1,
                links,
                kept_rows: 0,
            },
            meshes_computed: 2,
        }
    }

    /// The store keeps the most recently used sets, at most `KEPT_LINK_CUTS`, and hands a
    /// kept one back as computed nowhere.
    #[test]
    fn the_kept_link_cuts_are_the_most_recently_used_few() {
        let mut kept = KeptLinkCuts::new(KEPT_LINK_CUTS);
        let key = |i: usize| (7, 1024 * i, 3);
        for i in 0..KEPT_LINK_CUTS {
            kept.insert(key(i), prepared(i), 1);
        }
        let first = take(&mut kept, key(0)).expect("kept");
        assert_eq!((first.link_cut.links, first.meshes_computed), (0, 0));
        // Set 0 was just used: one more set drops set 1, the least recently used.
        kept.insert(key(KEPT_LINK_CUTS), prepared(KEPT_LINK_CUTS), 1);
        assert!(take(&mut kept, key(1)).is_none());
        for i in (0..KEPT_LINK_CUTS + 1).filter(|&i| i != 1) {
            assert_eq!(take(&mut kept, key(i)).map(|p| p.link_cut.links), Some(i));
        }
        assert!(
            take(&mut kept, (8, 0, 3)).is_none(),
            "another scene's content"
        );
        assert_eq!(kept.len(), KEPT_LINK_CUTS);
    }
}
