//! Where each light's shadow views live: square tiles in the layers of one depth-texture
//! array, sized by the light's importance and fitted to a memory budget.
//!
//! A layer of side R is a quadtree: a tile of level k has side `R >> k` (level 0 is the whole
//! layer), down to [`MIN_TILE_SIDE`]. Every light starts at the level its power asks for — the
//! tile's area proportional to the light's share of the brightest light's power, so a light a
//! quarter as bright gets half the side — and while the tiles exceed the budget the light
//! with the most texels per watt is coarsened by one level. Only when every light is at the
//! smallest tile and the budget still does not hold are the least powerful lights left
//! unshadowed (they still light the scene; the caller warns with their count).
//!
//! Packing is exact: tiles sorted from large to small are laid out along the layer's Morton
//! order in units of the smallest tile, so each tile starts on a multiple of its own size and
//! no layer holds a hole before the last tile.

use std::collections::BinaryHeap;

/// Smallest tile side in texels: below it a PCF kernel spans the whole view.
pub const MIN_TILE_SIDE: u32 = 16;

/// One light's request: how many views it needs (six for a cube) and what it is worth.
#[derive(Clone, Copy, Debug)]
pub struct TileRequest {
    pub views: u32,
    /// Power in watts (luminance-weighted); `f32::INFINITY` keeps the light at full
    /// resolution whatever the others (a sun).
    pub importance: f32,
}

/// A view's square in the array: layer, top-left texel and side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tile {
    pub layer: u32,
    pub x: u32,
    pub y: u32,
    pub side: u32,
}

impl Tile {
    /// `(u0, v0, size)` of the tile in the layer's [0, 1]² texture coordinates.
    pub fn uv_rect(&self, layer_side: u32) -> [f32; 3] {
        let s = layer_side as f32;
        [self.x as f32 / s, self.y as f32 / s, self.side as f32 / s]
    }
}

/// The outcome: per light its tiles (one per view, in view order) or `None` when the light
/// is unshadowed.
#[derive(Clone, Debug)]
pub struct ShadowAtlas {
    pub layer_side: u32,
    pub layers: u32,
    pub tiles: Vec<Option<Vec<Tile>>>,
}

impl ShadowAtlas {
    pub fn unshadowed(&self) -> usize {
        self.tiles.iter().filter(|t| t.is_none()).count()
    }

    /// Lights whose tiles are smaller than the full layer.
    pub fn reduced(&self) -> usize {
        self.tiles
            .iter()
            .flatten()
            .filter(|tiles| tiles.first().is_some_and(|t| t.side < self.layer_side))
            .count()
    }

    /// Smallest tile side in use (the layer side when no light is shadowed).
    pub fn smallest_side(&self) -> u32 {
        self.tiles
            .iter()
            .flatten()
            .flatten()
            .map(|t| t.side)
            .min()
            .unwrap_or(self.layer_side)
    }
}

/// Why no atlas fits.
#[derive(Debug, PartialEq, Eq)]
pub enum AtlasError {
    /// Not even one layer of `layer_side`² fits the budget.
    LayerOverBudget { layer_bytes: u64, budget_bytes: u64 },
}

/// Lays out the tiles of `requests` in layers of side `layer_side` holding `bytes_per_texel`
/// each, within `budget_bytes` and `max_layers`.
pub fn allocate(
    requests: &[TileRequest],
    layer_side: u32,
    bytes_per_texel: u64,
    budget_bytes: u64,
    max_layers: u32,
) -> Result<ShadowAtlas, AtlasError> {
    let layer_bytes = layer_side as u64 * layer_side as u64 * bytes_per_texel;
    let layers_in_budget = (budget_bytes / layer_bytes.max(1)).min(max_layers as u64);
    if layers_in_budget == 0 {
        return Err(AtlasError::LayerOverBudget {
            layer_bytes,
            budget_bytes,
        });
    }
    // Deepest level: the smallest tile still has MIN_TILE_SIDE texels a side (a layer smaller
    // than that is one tile).
    let max_level = (0..)
        .take_while(|&k: &u32| k < 31 && (layer_side >> k) >= MIN_TILE_SIDE)
        .last()
        .unwrap_or(0);
    // Costs in cells of the deepest level: a level-k tile takes 4^(max_level−k) cells.
    let cells_per_layer = 1u64 << (2 * max_level);
    let cell_budget = layers_in_budget * cells_per_layer;
    let cost = |views: u32, level: u32| views as u64 * (1u64 << (2 * (max_level - level)));

    let mut levels: Vec<Option<u32>> = requests
        .iter()
        .map(|r| (r.views > 0).then_some(0))
        .collect();
    let mut used: u64 = requests.iter().map(|r| cost(r.views, 0)).sum();
    // Coarsen the light that spends the most texels per watt, one level at a time: finite
    // importances first (a max-heap on cells / watt), a sun only when nothing else can.
    let mut heap: BinaryHeap<Candidate> = requests
        .iter()
        .enumerate()
        .filter(|(_, r)| r.views > 0 && max_level > 0)
        .map(|(i, r)| Candidate::new(i, r, cost(r.views, 0)))
        .collect();
    while used > cell_budget {
        if let Some(Candidate { light: i, .. }) = heap.pop() {
            let r = &requests[i];
            let l = levels[i].as_mut().expect("a candidate is shadowed");
            used -= cost(r.views, *l) - cost(r.views, *l + 1);
            *l += 1;
            if *l < max_level {
                heap.push(Candidate::new(i, r, cost(r.views, *l)));
            }
            continue;
        }
        // Every light at the smallest tile: drop the least powerful one's shadows.
        let weakest = (0..requests.len())
            .filter(|&i| levels[i].is_some())
            .min_by(|&a, &b| {
                importance_weight(&requests[a])
                    .total_cmp(&importance_weight(&requests[b]))
                    .then(b.cmp(&a))
            })
            .expect("over budget with no shadowed light");
        used -= cost(requests[weakest].views, levels[weakest].expect("shadowed"));
        levels[weakest] = None;
    }

    // Pack: large tiles first (stable by light index), each at the next cell multiple of its
    // own cost — which with sizes descending is the cursor itself.
    let mut order: Vec<usize> = (0..requests.len())
        .filter(|&i| levels[i].is_some())
        .collect();
    order.sort_by_key(|&i| levels[i]);
    let mut tiles: Vec<Option<Vec<Tile>>> = vec![None; requests.len()];
    let mut cursor = 0u64;
    for i in order {
        let level = levels[i].expect("filtered to shadowed");
        let step = cost(1, level);
        let side = layer_side >> level;
        let light_tiles = (0..requests[i].views)
            .map(|_| {
                debug_assert_eq!(cursor % step, 0);
                let layer = (cursor / cells_per_layer) as u32;
                let (x, y) = cell_position(cursor % cells_per_layer, max_level, layer_side);
                cursor += step;
                Tile { layer, x, y, side }
            })
            .collect();
        tiles[i] = Some(light_tiles);
    }
    Ok(ShadowAtlas {
        layer_side,
        layers: cursor.div_ceil(cells_per_layer) as u32,
        tiles,
    })
}

/// A light that can still be coarsened, ordered by how many cells per watt it spends (ties:
/// the later light first, so the order is deterministic).
#[derive(PartialEq)]
struct Candidate {
    finite: bool,
    cells_per_watt: f64,
    light: usize,
}

impl Candidate {
    fn new(light: usize, r: &TileRequest, cells: u64) -> Self {
        Self {
            finite: r.importance.is_finite(),
            cells_per_watt: cells as f64 / importance_weight(r),
            light,
        }
    }
}

impl Eq for Candidate {}

impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.finite
            .cmp(&other.finite)
            .then(self.cells_per_watt.total_cmp(&other.cells_per_watt))
            .then(self.light.cmp(&other.light))
    }
}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// Importance as a weight for "texels per watt": infinite importance never coarsens, zero
/// power coarsens first.
fn importance_weight(r: &TileRequest) -> f64 {
    if r.importance.is_nan() {
        f64::MIN_POSITIVE
    } else {
        (r.importance as f64).max(f64::MIN_POSITIVE)
    }
}

/// Top-left texel of Morton cell `cell` of a layer of side `layer_side` cut `depth` times:
/// at depth d the quadrant bit pair selects an offset of `layer_side >> d` (floor sides, so
/// four children always fit in their parent even when the side is not a power of two).
fn cell_position(cell: u64, depth: u32, layer_side: u32) -> (u32, u32) {
    let (mut x, mut y) = (0, 0);
    for d in 1..=depth {
        let pair = (cell >> (2 * (depth - d))) & 3;
        let half = layer_side >> d;
        x += (pair & 1) as u32 * half;
        y += (pair >> 1) as u32 * half;
    }
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn overlap(a: &Tile, b: &Tile) -> bool {
        a.layer == b.layer
            && a.x < b.x + b.side
            && b.x < a.x + a.side
            && a.y < b.y + b.side
            && b.y < a.y + a.side
    }

    #[test]
    fn lights_within_budget_keep_full_resolution() {
        let requests = [
            TileRequest {
                views: 6,
                importance: 10.0,
            },
            TileRequest {
                views: 1,
                importance: 10.0,
            },
        ];
        let atlas = allocate(&requests, 1024, 4, 64 << 20, 2048).unwrap();
        assert_eq!(atlas.layers, 7);
        assert_eq!(atlas.unshadowed(), 0);
        assert_eq!(atlas.reduced(), 0);
    }

    #[test]
    fn a_thousand_point_lights_fit_by_shrinking_not_by_dropping() {
        // 6000 views at 1024² would take 24 GB; 256 MiB holds 64 layers.
        let requests: Vec<TileRequest> = (0..1000)
            .map(|i| TileRequest {
                views: 6,
                importance: 1.0 + (i % 7) as f32,
            })
            .collect();
        let atlas = allocate(&requests, 1024, 4, 256 << 20, 2048).unwrap();
        assert_eq!(atlas.unshadowed(), 0);
        assert!(atlas.layers <= 64, "{} layers", atlas.layers);
        // Brighter lights never get smaller tiles than dimmer ones.
        let side = |i: usize| atlas.tiles[i].as_ref().unwrap()[0].side;
        for i in 0..1000 {
            for j in 0..7 {
                if requests[i].importance > requests[j].importance {
                    assert!(side(i) >= side(j), "light {i} vs {j}");
                }
            }
        }
        // The budget is used, not wasted: the tiles fill more than half of it.
        let texels: u64 = atlas
            .tiles
            .iter()
            .flatten()
            .flatten()
            .map(|t| (t.side as u64).pow(2))
            .sum();
        assert!(texels * 4 > (128 << 20), "{texels} texels");
    }

    #[test]
    fn beyond_the_smallest_tile_the_weakest_lights_lose_their_shadows() {
        // One 64² layer holds 16 tiles of 16²: two cubes fit, the two weakest do not.
        let requests: Vec<TileRequest> = [4.0, 1.0, 3.0, 2.0]
            .iter()
            .map(|&importance| TileRequest {
                views: 6,
                importance,
            })
            .collect();
        let atlas = allocate(&requests, 64, 4, 64 * 64 * 4, 8).unwrap();
        assert!(atlas.tiles[1].is_none() && atlas.tiles[3].is_none());
        assert!(atlas.tiles[0].is_some() && atlas.tiles[2].is_some());
        assert_eq!(atlas.unshadowed(), 2);
        assert_eq!(atlas.smallest_side(), 16);
    }

    #[test]
    fn a_layer_over_budget_is_an_error() {
        let requests = [TileRequest {
            views: 1,
            importance: 1.0,
        }];
        assert_eq!(
            allocate(&requests, 4096, 4, 1 << 20, 2048).unwrap_err(),
            AtlasError::LayerOverBudget {
                layer_bytes: 64 << 20,
                budget_bytes: 1 << 20
            }
        );
    }

    #[test]
    fn a_sun_keeps_full_resolution_among_many_lights() {
        let mut requests = vec![
            TileRequest {
                views: 6,
                importance: 1e6
            };
            100
        ];
        requests.push(TileRequest {
            views: 1,
            importance: f32::INFINITY,
        });
        let atlas = allocate(&requests, 512, 4, 16 << 20, 2048).unwrap();
        assert_eq!(atlas.tiles[100].as_ref().unwrap()[0].side, 512);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn tiles_never_overlap_and_stay_inside_their_layer(
            lights in prop::collection::vec((prop::sample::select(vec![1u32, 6]), 0.0f32..100.0), 0..60),
            side in prop::sample::select(vec![16u32, 100, 256, 1000, 1024]),
            budget_layers in 1u64..12,
        ) {
            let requests: Vec<TileRequest> = lights
                .iter()
                .map(|&(views, importance)| TileRequest { views, importance })
                .collect();
            let layer_bytes = side as u64 * side as u64 * 4;
            let atlas = allocate(&requests, side, 4, budget_layers * layer_bytes, 2048).unwrap();
            prop_assert!(atlas.layers as u64 <= budget_layers);
            let all: Vec<Tile> = atlas.tiles.iter().flatten().flatten().copied().collect();
            for (a_index, a) in all.iter().enumerate() {
                prop_assert!(a.layer < atlas.layers.max(1));
                prop_assert!(a.x + a.side <= side && a.y + a.side <= side, "{a:?}");
                prop_assert!(a.side >= MIN_TILE_SIDE.min(side));
                for b in &all[a_index + 1..] {
                    prop_assert!(!overlap(a, b), "{a:?} overlaps {b:?}");
                }
            }
            for (r, t) in requests.iter().zip(&atlas.tiles) {
                if let Some(t) = t {
                    prop_assert_eq!(t.len() as u32, r.views);
                    // A light's views share one size.
                    prop_assert!(t.iter().all(|x| x.side == t[0].side));
                }
            }
        }
    }
}
