//! §II.B's partition plane by a cost model (`plane=cost`; an addition, see the module doc of
//! [`super`]): the plane whose frame is expected to cost least.

use super::NEAR_MARGIN;

/// `plane=cost`: the partition plane's view distance whose frame is expected to cost least.
/// `leaves`: every leaf in the frustum as (its least view distance, its triangles); `hits`:
/// the coarse rays' first-hit distances (`None`: no hit), each standing for `pixels /
/// hits.len()` pixels; `ns_per_triangle` and `ns_per_ray`: wall time of a rasterized triangle
/// and of a ray; `near_share`: the share of the near leaves' triangles the near pass draws
/// (1 without `near_cull`); `pvl_share`: the share of the far leaves' triangles the rays' PVL
/// holds;
/// `ns_per_far_leaf`: the rest of a far leaf's cost (its polygon, the PVL's assembly). A
/// plane at `z` draws the leaves nearer than `z · (1 + NEAR_MARGIN)`, casts the pixels whose
/// first hit lies at `z` or beyond (those nearer are finished by the near pass; those that hit
/// nothing are left out, object-oriented casting skipping most of them) and draws their PVL.
/// Candidates: `near`, every coarse hit distance, and beyond every leaf (`far`: all drawn
/// near, no ray).
#[allow(clippy::too_many_arguments)]
pub fn cost_plane(
    leaves: &[(f32, u32)],
    hits: &[Option<f32>],
    pixels: f64,
    ns_per_triangle: f64,
    ns_per_ray: f64,
    near_share: f64,
    pvl_share: f64,
    ns_per_far_leaf: f64,
    near: f32,
    far: f32,
) -> f32 {
    let mut by_distance: Vec<(f32, u32)> = leaves.to_vec();
    by_distance.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut prefix = Vec::with_capacity(by_distance.len() + 1);
    prefix.push(0u64);
    for &(_, t) in &by_distance {
        prefix.push(prefix.last().copied().unwrap_or(0) + u64::from(t));
    }
    let mut hit_distances: Vec<f32> = hits.iter().flatten().copied().filter(|d| d.is_finite()).collect();
    hit_distances.sort_unstable_by(f32::total_cmp);
    let per_ray = pixels / hits.len().max(1) as f64;
    let cost = |z: f32| {
        let limit = z * (1.0 + NEAR_MARGIN);
        let near_leaves = by_distance.partition_point(|&(d, _)| d < limit);
        let near_triangles = prefix[near_leaves] as f64;
        let far_triangles = prefix[by_distance.len()] as f64 - near_triangles;
        let far_leaves = (by_distance.len() - near_leaves) as f64;
        let rays = (hit_distances.len() - hit_distances.partition_point(|&d| d < z)) as f64 * per_ray;
        (near_triangles * near_share + far_triangles * pvl_share) * ns_per_triangle
            + rays * ns_per_ray
            + far_leaves * ns_per_far_leaf
    };
    std::iter::once(near)
        .chain(hit_distances.iter().copied())
        .chain(std::iter::once(far))
        .map(|z| z.clamp(near, far))
        .map(|z| (cost(z), z))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map_or(near, |(_, z)| z)
}
