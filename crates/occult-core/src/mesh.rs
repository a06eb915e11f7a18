//! Indexed triangle meshes.

use crate::error::{CoreError, Result};
use crate::geom::Aabb;
use glam::Vec3;

/// An sRGB color with alpha.
pub type Rgba8 = [u8; 4];

/// Optional colors of a mesh.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshColors {
    /// One color for the whole mesh.
    PerMesh(Rgba8),
    /// One color per triangle (same length as the triangle list).
    PerTriangle(Vec<Rgba8>),
}

/// A triangle mesh: positions (object space) and counter-clockwise index triples.
///
/// Invariants, checked by [`Mesh::new`]: every coordinate is finite, every index names a vertex,
/// per-triangle colors match the triangle count. Degenerate (zero-area) triangles are allowed:
/// the rasterizer draws nothing for them. The rasterizer's unsafe code relies on the index
/// invariant (it reads projected vertices without bounds checks): keep the fields private and
/// every change to the indices checked.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    colors: Option<MeshColors>,
    bounds: Aabb,
}

impl Mesh {
    /// A mesh from positions and index triples.
    ///
    /// # Errors
    /// [`CoreError::NonFiniteVertex`], [`CoreError::IndexOutOfRange`],
    /// [`CoreError::TooManyVertices`].
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Self> {
        if positions.len() > u32::MAX as usize {
            return Err(CoreError::TooManyVertices(positions.len()));
        }
        // One pass over the positions: finiteness and the box of them all.
        let mut all = Aabb::EMPTY;
        let mut finite = true;
        for &p in &positions {
            finite &= p.is_finite();
            all = all.including(p);
        }
        if !finite {
            let vertex_index = positions.iter().position(|p| !p.is_finite()).unwrap_or(0);
            return Err(CoreError::NonFiniteVertex {
                vertex_index,
                value: positions[vertex_index].to_array(),
            });
        }
        // One pass over the indices: the range check and which vertices are used, a byte each
        // (plain stores: a bit set's read-modify-write of one word for neighbouring indices
        // chains through memory and costs several times as much); the first bad triangle is
        // looked for only on failure.
        let vertex_count = positions.len();
        let mut used = vec![0u8; vertex_count];
        let mut in_range = true;
        for &i in triangles.iter().flatten() {
            match used.get_mut(i as usize) {
                Some(flag) => *flag = 1,
                None => in_range = false,
            }
        }
        if !in_range {
            for (triangle_index, t) in triangles.iter().enumerate() {
                if let Some(&vertex_index) = t.iter().find(|&&i| i as usize >= vertex_count) {
                    return Err(CoreError::IndexOutOfRange {
                        triangle_index,
                        vertex_index,
                        vertex_count,
                    });
                }
            }
        }
        // The bounds are those of the vertices the triangles use: the box of all positions
        // when every vertex is used (loaders' meshes), else the used ones picked out.
        let used_count: usize = used.iter().map(|&u| usize::from(u)).sum();
        let bounds = if used_count == vertex_count {
            all
        } else {
            Aabb::from_points(positions.iter().zip(&used).filter(|(_, &u)| u != 0).map(|(&p, _)| p))
        };
        Ok(Self {
            positions,
            triangles,
            colors: None,
            bounds,
        })
    }

    /// This mesh with colors attached.
    ///
    /// # Errors
    /// [`CoreError::ColorCountMismatch`] when per-triangle colors do not match.
    pub fn with_colors(mut self, colors: MeshColors) -> Result<Self> {
        if let MeshColors::PerTriangle(c) = &colors {
            if c.len() != self.triangles.len() {
                return Err(CoreError::ColorCountMismatch {
                    triangle_count: self.triangles.len(),
                    color_count: c.len(),
                });
            }
        }
        self.colors = Some(colors);
        Ok(self)
    }

    /// Vertex positions, object space.
    #[inline]
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }
    /// Index triples.
    #[inline]
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    /// Number of triangles.
    #[inline]
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }
    /// Colors, if any.
    pub fn colors(&self) -> Option<&MeshColors> {
        self.colors.as_ref()
    }
    /// Color of triangle `triangle_index`, if the mesh has colors.
    pub fn triangle_color(&self, triangle_index: usize) -> Option<Rgba8> {
        match &self.colors {
            None => None,
            Some(MeshColors::PerMesh(c)) => Some(*c),
            Some(MeshColors::PerTriangle(c)) => c.get(triangle_index).copied(),
        }
    }
    /// Bounds of the referenced vertices (empty for a mesh without triangles).
    #[inline]
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }
    /// The three corners of a triangle.
    #[inline]
    pub fn triangle_positions(&self, triangle_index: usize) -> [Vec3; 3] {
        let t = self.triangles[triangle_index];
        [
            self.positions[t[0] as usize],
            self.positions[t[1] as usize],
            self.positions[t[2] as usize],
        ]
    }
    /// Bytes held by this mesh's arrays.
    pub fn memory_bytes(&self) -> usize {
        let colors = match &self.colors {
            Some(MeshColors::PerTriangle(c)) => c.len() * 4,
            _ => 0,
        };
        self.positions.len() * 12 + self.triangles.len() * 12 + colors
    }

    /// Reorders the triangles by `order` (a permutation of `0..triangle_count`), carrying colors.
    ///
    /// # Panics
    /// If `order` is not a permutation of the triangle indices (a programmer error).
    pub fn permute_triangles(&mut self, order: &[u32]) {
        assert_eq!(order.len(), self.triangles.len(), "permutation length");
        self.triangles = order.iter().map(|&i| self.triangles[i as usize]).collect();
        if let Some(MeshColors::PerTriangle(c)) = &mut self.colors {
            *c = order.iter().map(|&i| c[i as usize]).collect();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_nan_and_out_of_range() {
        assert!(matches!(
            Mesh::new(vec![Vec3::new(f32::NAN, 0.0, 0.0)], vec![]),
            Err(CoreError::NonFiniteVertex { vertex_index: 0, .. })
        ));
        assert!(matches!(
            Mesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 3]]),
            Err(CoreError::IndexOutOfRange {
                triangle_index: 0,
                vertex_index: 3,
                vertex_count: 3
            })
        ));
        assert!(Mesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 2]])
            .expect("three vertices and one in-range triangle make a mesh")
            .with_colors(MeshColors::PerTriangle(vec![]))
            .is_err());
    }

    #[test]
    fn empty_mesh_has_empty_bounds() {
        let m = Mesh::new(vec![], vec![]).expect("an empty mesh is valid");
        assert!(m.bounds().is_empty());
        assert_eq!(m.triangle_count(), 0);
    }

    #[test]
    fn bounds_hold_the_used_vertices_only() {
        let positions = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(100.0, -50.0, 7.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 3.0),
        ];
        let m = Mesh::new(positions.clone(), vec![[0, 2, 3]]).expect("indices in range");
        assert_eq!((m.bounds().min, m.bounds().max), (Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0)));
        let m = Mesh::new(positions, vec![[0, 2, 3], [3, 1, 0]]).expect("indices in range");
        assert_eq!(
            (m.bounds().min, m.bounds().max),
            (Vec3::new(0.0, -50.0, 0.0), Vec3::new(100.0, 2.0, 7.0))
        );
        // Vertices but no triangles: an empty box; a non-finite vertex is refused even unused.
        assert!(Mesh::new(vec![Vec3::ONE; 70], vec![])
            .expect("no triangles is a valid mesh")
            .bounds()
            .is_empty());
        assert!(matches!(
            Mesh::new(vec![Vec3::ONE, Vec3::new(0.0, f32::INFINITY, 0.0)], vec![[0, 0, 0]]),
            Err(CoreError::NonFiniteVertex { vertex_index: 1, .. })
        ));
        // The first bad triangle is named.
        let m = Mesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 2], [2, 63, 0], [70, 0, 0]]);
        assert!(matches!(
            m,
            Err(CoreError::IndexOutOfRange {
                triangle_index: 1,
                vertex_index: 63,
                vertex_count: 3
            })
        ));
    }
}
