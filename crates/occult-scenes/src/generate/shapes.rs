//! Mesh-building primitives shared by the generators: quads, boxes, tubes swept along paths,
//! lathed solids and UV spheres, each appended to a [`MeshBuilder`] with a per-triangle color;
//! plus the nested-grid helper that replicates a node in O(side) stored instances.
//!
//! Winding: every primitive is counter-clockwise seen from outside (the geometric normal
//! `(p1 − p0) × (p2 − p0)` points out of the solid), so that back-face culling, when a renderer
//! enables it, removes exactly the faces turned away. Unit tests check this for every closed
//! primitive.

use occult_core::{Affine3A, CoreError, Instance, Mat3, Mesh, MeshColors, NodeId, Rgba8, SceneBuilder, Vec3};
use std::f32::consts::TAU;

/// Bytes that one triangle of a [`MeshBuilder`] mesh costs at most: indices (12), color (4) and
/// up to two vertices (24). Quads and boxes use 2 vertices per triangle; tubes and spheres fewer.
pub(crate) const BYTES_PER_BUILT_TRIANGLE: u64 = 40;
/// Bytes that one stored instance costs (the transform, the child id and its item offset).
pub(crate) const BYTES_PER_INSTANCE: u64 = std::mem::size_of::<Instance>() as u64 + 8;

/// An indexed mesh under construction, with one color per triangle.
#[derive(Debug, Default)]
pub(crate) struct MeshBuilder {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub colors: Vec<Rgba8>,
}

impl MeshBuilder {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Index the next pushed vertex will get.
    #[inline]
    fn base(&self) -> u32 {
        // Generators bound their unique geometry far below 2^32 vertices (MAX_UNIQUE_BYTES),
        // and Mesh::new re-checks the count; the cast cannot wrap for any accepted parameter.
        self.positions.len() as u32
    }

    /// A planar quad `p0 p1 p2 p3`, counter-clockwise seen from its front, as triangles
    /// `(p0 p1 p2)` and `(p0 p2 p3)`.
    pub fn quad(&mut self, p0: Vec3, p1: Vec3, p2: Vec3, p3: Vec3, color: Rgba8) {
        let i = self.base();
        self.positions.extend([p0, p1, p2, p3]);
        self.triangles.push([i, i + 1, i + 2]);
        self.triangles.push([i, i + 2, i + 3]);
        self.colors.extend([color, color]);
    }

    /// A rectangle in a plane facing `normal`: `origin` is its bottom-left corner seen from the
    /// front, `right` and `up` its edge vectors (`right × up` must point along `normal`).
    pub fn rect(&mut self, origin: Vec3, right: Vec3, up: Vec3, color: Rgba8) {
        self.quad(origin, origin + right, origin + right + up, origin + up, color);
    }

    /// An axis-aligned box, all six faces outward (12 triangles). Empty boxes are skipped.
    pub fn cuboid(&mut self, min: Vec3, max: Vec3, color: Rgba8) {
        self.cuboid_faces(min, max, color, [true; 6]);
    }

    /// An axis-aligned box with only the faces selected by `faces` (order −x, +x, −y, +y, −z, +z).
    pub fn cuboid_faces(&mut self, min: Vec3, max: Vec3, color: Rgba8, faces: [bool; 6]) {
        if !(min.x < max.x && min.y < max.y && min.z < max.z) {
            return;
        }
        let s = max - min;
        let (x, y, z) = (Vec3::X * s.x, Vec3::Y * s.y, Vec3::Z * s.z);
        // Each face: a corner, then `right` and `up` edges with right × up pointing outward.
        let all = [
            (min, z, y),          // −x: z × y = −x
            (min + x + z, -z, y), // +x: −z × y = +x
            (min, x, z),          // −y: x × z = −y
            (min + y + z, x, -z), // +y: x × −z = +y
            (min + x, -x, y),     // −z: −x × y = −z
            (min + z, x, y),      // +z: x × y = +z
        ];
        for (&(o, r, u), &on) in all.iter().zip(faces.iter()) {
            if on {
                self.rect(o, r, u, color);
            }
        }
    }

    /// A tube swept along `centers` with per-point `radii`, `sides` vertices per ring, capped at
    /// both ends when `caps`. Triangles: `2·sides·(rings − 1)`, plus `2·sides` with caps.
    /// Frames are propagated by projection (rotation-minimizing for turns under 90°).
    pub fn tube(&mut self, centers: &[Vec3], radii: &[f32], sides: u32, caps: bool, color: Rgba8) {
        debug_assert_eq!(centers.len(), radii.len());
        let rings = centers.len();
        if rings < 2 || sides < 3 {
            return;
        }
        let tangent = |k: usize| -> Vec3 {
            let a = centers[k.saturating_sub(1)];
            let b = centers[(k + 1).min(rings - 1)];
            (b - a).normalize_or(Vec3::Y)
        };
        let t0 = tangent(0);
        let mut normal = t0.any_orthonormal_vector();
        let first = self.base();
        for k in 0..rings {
            let t = tangent(k);
            // Project the previous normal onto the plane normal to t (rotation-minimizing).
            let n = (normal - t * normal.dot(t)).normalize_or(t.any_orthonormal_vector());
            normal = n;
            let b = t.cross(n);
            for s in 0..sides {
                let phi = TAU * s as f32 / sides as f32;
                let (sin, cos) = phi.sin_cos();
                self.positions.push(centers[k] + radii[k] * (cos * n + sin * b));
            }
        }
        for k in 0..rings as u32 - 1 {
            for s in 0..sides {
                let a = first + k * sides + s;
                let b = first + k * sides + (s + 1) % sides;
                let c = a + sides;
                let d = b + sides;
                self.triangles.push([a, b, c]);
                self.triangles.push([b, d, c]);
                self.colors.extend([color, color]);
            }
        }
        if caps {
            let start = self.base();
            self.positions.push(centers[0]);
            for s in 0..sides {
                self.triangles.push([start, first + (s + 1) % sides, first + s]);
                self.colors.push(color);
            }
            let end = self.base();
            self.positions.push(centers[rings - 1]);
            let last = first + (rings as u32 - 1) * sides;
            for s in 0..sides {
                self.triangles.push([end, last + s, last + (s + 1) % sides]);
                self.colors.push(color);
            }
        }
    }

    /// A solid of revolution about the vertical axis through `base`: `profile` is a list of
    /// `(radius, height)` from bottom to top; a radius of 0 closes the solid with a pole (fan).
    /// Triangles: `2·sides` per band between two rings, `sides` per band touching a pole.
    pub fn lathe(&mut self, base: Vec3, profile: &[(f32, f32)], sides: u32, color: Rgba8) {
        if profile.len() < 2 || sides < 3 {
            return;
        }
        // Ring k starts at `starts[k]`; a pole ring is a single vertex.
        let mut starts = Vec::with_capacity(profile.len());
        for &(r, h) in profile {
            starts.push(self.base());
            if r <= 0.0 {
                self.positions.push(base + Vec3::Y * h);
            } else {
                for s in 0..sides {
                    // Counter-clockwise seen from above is towards −z from +x (right-handed, +y up):
                    // angle measured from +x towards −z.
                    let phi = TAU * s as f32 / sides as f32;
                    let (sin, cos) = phi.sin_cos();
                    self.positions.push(base + Vec3::new(r * cos, h, -r * sin));
                }
            }
        }
        for k in 0..profile.len() - 1 {
            let (lo_pole, hi_pole) = (profile[k].0 <= 0.0, profile[k + 1].0 <= 0.0);
            let (lo, hi) = (starts[k], starts[k + 1]);
            for s in 0..sides {
                let s1 = (s + 1) % sides;
                match (lo_pole, hi_pole) {
                    (true, true) => {}
                    (true, false) => {
                        self.triangles.push([lo, hi + s1, hi + s]);
                        self.colors.push(color);
                    }
                    (false, true) => {
                        self.triangles.push([lo + s, lo + s1, hi]);
                        self.colors.push(color);
                    }
                    (false, false) => {
                        self.triangles.push([lo + s, lo + s1, hi + s]);
                        self.triangles.push([lo + s1, hi + s1, hi + s]);
                        self.colors.extend([color, color]);
                    }
                }
            }
        }
    }

    /// A UV sphere of `stacks` latitude bands and `slices` meridians:
    /// `2·slices·(stacks − 1)` triangles.
    pub fn uv_sphere(&mut self, center: Vec3, radius: f32, stacks: u32, slices: u32, color: Rgba8) {
        let stacks = stacks.max(2);
        let profile: Vec<(f32, f32)> = (0..=stacks)
            .map(|k| {
                // From the south pole (k = 0) to the north pole (k = stacks).
                let theta = std::f32::consts::PI * k as f32 / stacks as f32;
                let r = if k == 0 || k == stacks {
                    0.0
                } else {
                    radius * theta.sin()
                };
                (r, -radius * theta.cos())
            })
            .collect();
        self.lathe(center, &profile, slices, color);
    }

    /// Triangles so far.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The finished mesh with per-triangle colors.
    ///
    /// # Errors
    /// [`CoreError`] from [`Mesh::new`] (non-finite vertices, which the generators never produce
    /// for accepted parameters, or too many vertices).
    pub fn finish(self) -> Result<Mesh, CoreError> {
        Mesh::new(self.positions, self.triangles)?.with_colors(MeshColors::PerTriangle(self.colors))
    }
}

/// Triangles and per-triangle colors of a `w × h` grid of quads whose `(w + 1) × (h + 1)` vertices
/// are stored row by row (vertex `(i, j)` at index `j·(w + 1) + i`, rows along +z, columns along
/// +x). Quads come row by row, each as `[v00, v01, v10]`, `[v10, v01, v11]` (counter-clockwise
/// seen from +y), both triangles colored `color(i, j)`. The vertex count must fit `u32`.
pub(crate) fn grid_quads(w: u32, h: u32, mut color: impl FnMut(u32, u32) -> Rgba8) -> (Vec<[u32; 3]>, Vec<Rgba8>) {
    let n = w + 1;
    let mut triangles = Vec::with_capacity(2 * (w * h) as usize);
    let mut colors = Vec::with_capacity(2 * (w * h) as usize);
    for j in 0..h {
        for i in 0..w {
            let v00 = j * n + i;
            let (v10, v01, v11) = (v00 + 1, v00 + n, v00 + n + 1);
            triangles.push([v00, v01, v10]);
            triangles.push([v10, v01, v11]);
            let c = color(i, j);
            colors.extend([c, c]);
        }
    }
    (triangles, colors)
}

/// Rotation about +y by `quarter_turns · 90°`, built exactly (no rounding of cos/sin), so that
/// rotated footprints stay axis-aligned to the bit.
pub(crate) fn quarter_turn_y(quarter_turns: u32) -> Mat3 {
    let (c, s) = match quarter_turns % 4 {
        0 => (1.0, 0.0),
        1 => (0.0, 1.0),
        2 => (-1.0, 0.0),
        _ => (0.0, -1.0),
    };
    // Column-major rotation about y by angle θ with cos θ = c, sin θ = s.
    Mat3::from_cols(Vec3::new(c, 0.0, -s), Vec3::Y, Vec3::new(s, 0.0, c))
}

/// Places `count_x × count_z` copies of cells on a grid, in O(count_x + count_z) stored
/// instances per distinct row: a row group holds `count_x` instances spaced `pitch_x` along +x,
/// the returned group holds `count_z` row instances spaced `pitch_z` along +z, the first cell at
/// `origin`. `cell(i, j)` names the node of cell `(i, j)`; rows whose cells are the same
/// node sequence are stored once (`row_key(j)` names row `j`'s variant, rows with equal keys must
/// hold the same cells).
#[allow(clippy::too_many_arguments)]
pub(crate) fn grid(
    builder: &mut SceneBuilder,
    name: &str,
    count_x: u32,
    count_z: u32,
    pitch_x: f32,
    pitch_z: f32,
    origin: Vec3,
    row_key: impl Fn(u32) -> u32,
    cell: impl Fn(u32, u32) -> NodeId,
) -> Result<NodeId, CoreError> {
    let mut rows: Vec<(u32, NodeId)> = Vec::new();
    let mut instances = Vec::with_capacity(count_z as usize);
    for j in 0..count_z {
        let key = row_key(j);
        let row = match rows.iter().find(|(k, _)| *k == key) {
            Some(&(_, id)) => id,
            None => {
                let cells = (0..count_x)
                    .map(|i| Instance {
                        parent_from_child: Affine3A::from_translation(Vec3::X * (i as f32 * pitch_x)),
                        child: cell(i, j),
                    })
                    .collect();
                let id = builder.add_group(format!("{name} row {key}"), cells)?;
                rows.push((key, id));
                id
            }
        };
        instances.push(Instance {
            parent_from_child: Affine3A::from_translation(origin + Vec3::Z * (j as f32 * pitch_z)),
            child: row,
        });
    }
    builder.add_group(name, instances)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every triangle of a closed convex solid faces away from `inside`.
    fn assert_outward(m: &MeshBuilder, inside: Vec3) {
        assert!(!m.triangles.is_empty());
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let n = (b - a).cross(c - a);
            if n.length_squared() < 1e-12 {
                continue;
            }
            let centroid = (a + b + c) / 3.0;
            assert!(n.dot(centroid - inside) > 0.0, "inward triangle {t:?}");
        }
    }

    #[test]
    fn cuboid_faces_outward() {
        let mut m = MeshBuilder::new();
        m.cuboid(Vec3::new(-1.0, -2.0, -3.0), Vec3::new(2.0, 1.0, 0.5), [1; 4]);
        assert_eq!(m.triangle_count(), 12);
        assert_outward(&m, Vec3::new(0.5, -0.5, -1.25));
    }

    #[test]
    fn empty_cuboid_adds_nothing() {
        let mut m = MeshBuilder::new();
        m.cuboid(Vec3::ONE, Vec3::ONE, [1; 4]);
        assert_eq!(m.triangle_count(), 0);
    }

    #[test]
    fn capped_tube_faces_outward_and_counts() {
        let mut m = MeshBuilder::new();
        let centers = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        m.tube(&centers, &[0.2; 3], 8, true, [1; 4]);
        assert_eq!(m.triangle_count(), 2 * 8 * 2 + 2 * 8);
        assert_outward(&m, Vec3::X);
    }

    #[test]
    fn sphere_faces_outward_and_counts() {
        let mut m = MeshBuilder::new();
        m.uv_sphere(Vec3::new(1.0, 2.0, 3.0), 1.5, 8, 16, [1; 4]);
        assert_eq!(m.triangle_count(), 2 * 16 * (8 - 1));
        assert_outward(&m, Vec3::new(1.0, 2.0, 3.0));
    }

    #[test]
    fn degenerate_tubes_and_lathes_add_nothing() {
        let mut m = MeshBuilder::new();
        m.tube(&[Vec3::ZERO], &[1.0], 8, true, [1; 4]);
        m.tube(&[Vec3::ZERO, Vec3::X], &[1.0, 1.0], 2, true, [1; 4]);
        m.lathe(Vec3::ZERO, &[(1.0, 0.0)], 8, [1; 4]);
        assert_eq!(m.triangle_count(), 0);
    }

    #[test]
    fn quarter_turns_are_exact_rotations() {
        assert_eq!(quarter_turn_y(0), Mat3::IDENTITY);
        assert_eq!(quarter_turn_y(1) * Vec3::X, Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(quarter_turn_y(2) * Vec3::X, -Vec3::X);
        assert_eq!(quarter_turn_y(4), Mat3::IDENTITY);
        assert!((quarter_turn_y(1) - Mat3::from_rotation_y(std::f32::consts::FRAC_PI_2)).abs_diff_eq(Mat3::ZERO, 1e-6));
    }
}
