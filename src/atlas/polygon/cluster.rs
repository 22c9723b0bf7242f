//! kd-tree clustering with gap-aware splits (seed 001 §5.2, methods §B.5): at each node the
//! axis of greatest extent is split between the sorted coordinates p_j and p_{j+1} at
//!
//! `j* = argmax_j |p_j − p_{j+1}|·(1 − 2|I_m − j|/n)^ρ`,  I_m = (n + 1)/2 (1-based j),
//!
//! so a split may move off the median into a gap in the VPLs (a shadow) instead of putting a
//! cluster across it. ρ = 0.5 is the paper's; ρ = ∞ is the pure median split. Nodes stop
//! splitting once they hold at most the target count. Works in 2-D (in-plane coordinates of
//! a planar segment) and 3-D.

/// One leaf: its points (indices into the input) and its kd cell.
#[derive(Clone, Debug)]
pub struct Cluster<const D: usize> {
    pub members: Vec<usize>,
    pub cell_min: [f32; D],
    pub cell_max: [f32; D],
}

/// Clusters `points` into leaves of at most `target` points. `rho = f32::INFINITY` splits
/// at the median. The root cell is the points' bounding box.
pub fn kd_clusters<const D: usize>(
    points: &[[f32; D]],
    target: usize,
    rho: f32,
) -> Vec<Cluster<D>> {
    if points.is_empty() {
        return Vec::new();
    }
    let mut lo = [f32::INFINITY; D];
    let mut hi = [f32::NEG_INFINITY; D];
    for p in points {
        for a in 0..D {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let mut out = Vec::new();
    let mut stack = vec![((0..points.len()).collect::<Vec<_>>(), lo, hi)];
    let target = target.max(1);
    while let Some((mut members, cell_min, cell_max)) = stack.pop() {
        if members.len() <= target {
            out.push(Cluster {
                members,
                cell_min,
                cell_max,
            });
            continue;
        }
        // The axis of greatest extent of the node's points (not of its cell).
        let (mut blo, mut bhi) = ([f32::INFINITY; D], [f32::NEG_INFINITY; D]);
        for &i in &members {
            for a in 0..D {
                blo[a] = blo[a].min(points[i][a]);
                bhi[a] = bhi[a].max(points[i][a]);
            }
        }
        let axis = (0..D)
            .max_by(|&a, &b| (bhi[a] - blo[a]).total_cmp(&(bhi[b] - blo[b])))
            .unwrap_or(0);
        if bhi[axis] <= blo[axis] {
            // All coincident: nothing to split by position; halve the list.
            let half = members.split_off(members.len() / 2);
            stack.push((half, cell_min, cell_max));
            stack.push((members, cell_min, cell_max));
            continue;
        }
        members.sort_by(|&a, &b| points[a][axis].total_cmp(&points[b][axis]));
        let j = gap_aware_split(
            &members.iter().map(|&i| points[i][axis]).collect::<Vec<_>>(),
            rho,
        );
        let at = 0.5 * (points[members[j - 1]][axis] + points[members[j]][axis]);
        let right = members.split_off(j);
        let (mut left_max, mut right_min) = (cell_max, cell_min);
        left_max[axis] = at;
        right_min[axis] = at;
        stack.push((right, right_min, cell_max));
        stack.push((members, cell_min, left_max));
    }
    out
}

/// The split index of Eq. 1 on sorted coordinates: the left part is `sorted[..j]`, j in
/// 1..n. Ties and all-zero gaps fall back to the median.
pub fn gap_aware_split(sorted: &[f32], rho: f32) -> usize {
    let n = sorted.len();
    let median = n / 2;
    if n < 2 {
        return n;
    }
    if !rho.is_finite() {
        return median.max(1);
    }
    let m = (n as f64 + 1.0) / 2.0;
    let mut best = (0.0f64, median.max(1));
    for j in 1..n {
        // j is 1-based p_j, p_{j+1}: sorted[j - 1], sorted[j].
        let gap = (sorted[j] - sorted[j - 1]) as f64;
        let w = (1.0 - 2.0 * (m - j as f64).abs() / n as f64).max(0.0);
        let score = gap * w.powf(rho as f64);
        let better = score > best.0
            || (score == best.0 && score > 0.0 && j.abs_diff(median) < best.1.abs_diff(median));
        if better {
            best = (score, j);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_points_split_near_the_median_and_keep_the_target_size() {
        let points: Vec<[f32; 1]> = (0..1000).map(|i| [i as f32]).collect();
        let leaves = kd_clusters(&points, 50, 0.5);
        let sizes: Vec<usize> = leaves.iter().map(|c| c.members.len()).collect();
        assert_eq!(sizes.iter().sum::<usize>(), 1000);
        assert!(sizes.iter().all(|&s| (25..=50).contains(&s)), "{sizes:?}");
        // Equal gaps: the weight decides, so the split is the median.
        assert_eq!(gap_aware_split(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], 0.5), 3);
        // Coincident points: the median.
        assert_eq!(gap_aware_split(&[1.0; 8], 0.5), 4);
    }
}
