//! §II.B's partition plane by a cost model (`plane=cost`; an addition, see the module doc of
//! [`super`]): the plane whose frame is expected to cost least.

use super::NEAR_MARGIN;

/// `plane=cost`: the partition plane's view distance whose frame is expected to cost least.
/// `leaves`: every leaf in the frustum as (its least view distance, its triangle references);
/// `hits`: the coarse rays' first-hit distances (`None`: no hit), each standing for `pixels /
/// hits.len()` pixels; `ns_per_triangle` and `ns_per_ray`: wall time of a rasterized triangle
/// and of a ray; `near_share`: the triangles the near pass draws per reference of the near
/// leaves (1 without `near_cull`); `pvl_share`: the triangles the rays' PVL holds per reference
/// of the far leaves;
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
    let mut hit_distances: Vec<f32> = hits.iter().flatten().copied().filter(|d| d.is_finite()).collect();
    hit_distances.sort_unstable_by(f32::total_cmp);
    let per_ray = pixels / hits.len().max(1) as f64;
    // The candidates in the order they are weighed (of equal costs the first wins), and their
    // near limits: a leaf is near for a candidate whose limit lies beyond its distance.
    let candidates: Vec<f32> = std::iter::once(near)
        .chain(hit_distances.iter().copied())
        .chain(std::iter::once(far))
        .map(|z| z.clamp(near, far))
        .collect();
    let mut limits: Vec<f32> = candidates.iter().map(|&z| z * (1.0 + NEAR_MARGIN)).collect();
    limits.sort_unstable_by(f32::total_cmp);
    // Each leaf counted once, at the first (sorted) limit it lies below: the limits at most
    // its distance counted through buckets of their range rather than the leaves sorted
    // (hundreds of thousands on a city) or a binary search per leaf.
    let below = LimitBuckets::new(&limits);
    let mut triangles_at = vec![0u64; limits.len() + 1];
    let mut leaves_at = vec![0u64; limits.len() + 1];
    for &(d, t) in leaves {
        let k = if d.is_nan() {
            limits.len()
        } else {
            below.at_most(&limits, d)
        };
        triangles_at[k] += u64::from(t);
        leaves_at[k] += 1;
    }
    let all_triangles: u64 = triangles_at.iter().sum();
    let (mut triangles, mut count) = (0u64, 0u64);
    // Per sorted limit, the triangles and leaves nearer than it.
    let near_of: Vec<(u64, u64)> = (0..limits.len())
        .map(|k| {
            triangles += triangles_at[k];
            count += leaves_at[k];
            (triangles, count)
        })
        .collect();
    let cost = |z: f32| {
        let limit = z * (1.0 + NEAR_MARGIN);
        // The last sorted limit equal to this one: every leaf below it is near.
        let k = limits.partition_point(|&l| l <= limit) - 1;
        let (near_triangles, near_leaves) = near_of[k];
        let far_triangles = (all_triangles - near_triangles) as f64;
        let far_leaves = (leaves.len() as u64 - near_leaves) as f64;
        let rays = (hit_distances.len() - hit_distances.partition_point(|&d| d < z)) as f64 * per_ray;
        (near_triangles as f64 * near_share + far_triangles * pvl_share) * ns_per_triangle
            + rays * ns_per_ray
            + far_leaves * ns_per_far_leaf
    };
    candidates
        .into_iter()
        .map(|z| (cost(z), z))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map_or(near, |(_, z)| z)
}

/// Buckets of equal width over the range of sorted limits, each with the count of the limits
/// in the buckets before it: the limits at most a distance are those of the earlier buckets
/// and those of its own bucket at most it (the bucket of a value never decreases with it), a
/// lookup and a binary search within one bucket (a few limits, usually) instead of one over
/// all of them.
struct LimitBuckets {
    low: f32,
    /// Buckets per unit of distance; 0 when the limits span no finite range (none, one, all
    /// equal, or a range beyond `f32`: then a binary search over all of them).
    scale: f32,
    /// Per bucket, the limits in the buckets before it; then the count of all.
    before: Vec<usize>,
}

/// Buckets per limit.
const BUCKETS_PER_LIMIT: usize = 4;

impl LimitBuckets {
    /// The buckets of `limits` (sorted, finite).
    fn new(limits: &[f32]) -> Self {
        let (low, high) = match (limits.first(), limits.last()) {
            (Some(&l), Some(&h)) if h > l && (h - l).is_finite() => (l, h),
            _ => {
                return Self {
                    low: 0.0,
                    scale: 0.0,
                    before: Vec::new(),
                }
            }
        };
        let n = limits.len() * BUCKETS_PER_LIMIT;
        let mut b = Self {
            low,
            scale: n as f32 / (high - low),
            before: vec![0; n + 1],
        };
        let mut counts = vec![0usize; n];
        for &l in limits {
            counts[b.bucket(l)] += 1;
        }
        let mut sum = 0;
        for (before, count) in b.before.iter_mut().zip(counts) {
            *before = sum;
            sum += count;
        }
        b.before[n] = sum;
        b
    }

    /// The bucket of `x` (not NaN): the first for what lies below the range, the last for
    /// what lies beyond it.
    fn bucket(&self, x: f32) -> usize {
        // Saturating: below the range (negative) is 0, beyond it is clamped.
        (((x - self.low) * self.scale) as usize).min(self.before.len() - 2)
    }

    /// How many of `limits` (those the buckets were made of) are at most `d` (not NaN).
    fn at_most(&self, limits: &[f32], d: f32) -> usize {
        if self.scale == 0.0 {
            return limits.partition_point(|&l| l <= d);
        }
        let b = self.bucket(d);
        let (first, end) = (self.before[b], self.before[b + 1]);
        first + limits[first..end].partition_point(|&l| l <= d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The buckets count what a binary search over all the limits counts, for distances below,
    /// within, on and beyond the limits (negative, zero, infinite), with repeated limits, one
    /// limit, equal limits and a range wider than `f32` holds.
    #[test]
    fn buckets_count_the_limits_a_binary_search_counts() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let mut sets: Vec<Vec<f32>> = vec![
            vec![],
            vec![3.0],
            vec![2.0; 9],
            vec![-f32::MAX, f32::MAX],
            vec![0.1, 0.1, 0.1, 5.0, 5.0, 1e6],
            vec![1.0, 1.0 + f32::EPSILON, 1.0 + 2.0 * f32::EPSILON],
        ];
        for _ in 0..200 {
            let mut l: Vec<f32> = (0..rng.random_range(1..300))
                .map(|_| {
                    if rng.random_bool(0.3) {
                        rng.random_range(1..8) as f32
                    } else {
                        rng.random_range(0.01..1000.0f32)
                    }
                })
                .collect();
            l.sort_unstable_by(f32::total_cmp);
            sets.push(l);
        }
        for limits in &sets {
            let b = LimitBuckets::new(limits);
            let mut ds: Vec<f32> = vec![f32::NEG_INFINITY, -1.0, -0.0, 0.0, f32::INFINITY, f32::MAX, -f32::MAX];
            for &l in limits {
                ds.extend([l, l.next_up(), l.next_down()]);
            }
            ds.extend((0..100).map(|_| rng.random_range(-10.0..1100.0f32)));
            for d in ds {
                assert_eq!(
                    b.at_most(limits, d),
                    limits.partition_point(|&l| l <= d),
                    "{d} among {} limits",
                    limits.len()
                );
            }
        }
    }
}
