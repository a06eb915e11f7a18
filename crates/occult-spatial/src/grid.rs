//! Uniform and nested grids over scene elements (triangles of a mesh, instances of a group).
//!
//! # References
//! - Hillesland, Salomon, Lastra, Manocha, "Fast and Simple Occlusion Culling using
//!   Hardware-Based Depth Queries", 2002 (`papers/occlusion-queries-hillesland-2002.txt`):
//!   §3.1 the uniform grid, each triangle assigned to *every* cell it intersects; §3.2 the
//!   nested grid, cells holding more than a split threshold of triangles subdivided by a
//!   branching factor per axis, recursively to a maximum depth; §4.1 the resolution counted in
//!   cells along the longest axis (35–50 was best for the paper's 13M-triangle model).
//! - Akenine-Möller, "Fast 3D Triangle-Box Overlap Testing", 2001, through
//!   [`occult_core::tri_box_overlap`]: the exact assignment test.
//!
//! A [`NestedGrid`] is built over any [`GridElements`]: a set of elements with bounds, an exact
//! overlap test against a cell box and a weight (triangles it stands for). It stores only the
//! non-empty cells of each level, in flat arrays with `u32` indices: a cell names the range of
//! its elements in one shared index array and, when subdivided, the level of its subgrid.
//! A subdivided cell hands all its elements to its subgrid (§3.2).
//!
//! Each cell carries a *tight box*: the cell's box intersected with the union of its elements'
//! bounds, which holds every point of every element inside the cell. Renderers query the tight
//! box instead of the whole cube: it is never larger and still conservative.
//!
//! # Instanced scenes
//! A grid is built per *unique* node of the scene DAG, in that node's own space (see
//! `occult-render`'s `oqgrid`): a mesh node's grid holds triangle indices, a group node's grid
//! holds instance indices. An instance is placed by its transform at traversal time, so memory
//! is linear in unique geometry (triangles and instances as stored in the DAG), whatever the
//! number of triangle instances.
//!
//! # Memory bound
//! Before any allocation of a level, the number of (cell, element) candidates is counted from
//! the elements' bounds (exactly, in 128-bit arithmetic) and the level's bytes are checked
//! against [`GridConfig::max_bytes`]; an absurd resolution is a [`GridError`], never an
//! allocation attempt.
//!
//! ```
//! use occult_core::{Mesh, Vec3};
//! use occult_spatial::grid::{GridConfig, MeshTriangles, NestedGrid, Resolution};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 4.0, 0.0)], vec![[0, 1, 2]])?;
//! let config = GridConfig { resolution: Resolution::Cells(4), cells_per_element: 16.0, ..GridConfig::default() };
//! let grid = NestedGrid::build(&MeshTriangles(&mesh), mesh.bounds(), &config)?;
//! // A 4 x 4 x 1 grid; the triangle is in the 10 cells below its hypotenuse and in those that
//! // touch it there.
//! assert_eq!(grid.levels()[0].dims, [4, 4, 1]);
//! assert!(grid.levels()[0].cells.len() >= 10 && grid.levels()[0].cells.len() < 16);
//! # Ok(())
//! # }
//! ```

use occult_core::{tri_box_overlap, Aabb, Mesh, Vec3};
use rayon::prelude::*;
use std::fmt;

/// Index meaning "no subgrid".
pub const NO_CHILD: u32 = u32::MAX;

/// Elements per cell aimed at by [`Resolution::Auto`].
pub const AUTO_ELEMENTS_PER_CELL: f64 = 100.0;

/// Most cells along one axis of any level (keeps cell coordinates in `u32` and products sane).
pub const MAX_AXIS_CELLS: u64 = 1 << 16;

/// How many cells along the longest axis of a grid's top level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Resolution {
    /// About [`AUTO_ELEMENTS_PER_CELL`] elements per cell with cubic cells, capped at 64 along
    /// the longest axis. On the paper's 13M-triangle plant this gives ~50 cells along the longest
    /// axis, the upper end of the 35–50 the paper found best (§4.1).
    Auto,
    /// Exactly this many cells along the longest axis (≥ 1); the other axes get as many as keep
    /// the cells closest to cubes.
    Cells(u32),
}

/// Tunables of a [`NestedGrid`].
#[derive(Clone, Debug, PartialEq)]
pub struct GridConfig {
    /// Top-level resolution.
    pub resolution: Resolution,
    /// Subcells per axis of a split cell (≥ 2; §4.1 uses 4, i.e. 64 subcells).
    pub branching: u32,
    /// A cell with more elements than this is split (≥ 1; §4.1 uses 10,000).
    pub split_threshold: usize,
    /// Most levels below the top (0 gives the uniform grid of §3.1).
    pub max_depth: u32,
    /// Cap on the grid's bytes, checked before each level is allocated.
    pub max_bytes: usize,
    /// Never more cells in a level than `max(1, elements × cells_per_element)`: a group of four
    /// instances does not get a 50³ grid. Only lowers the resolution, never raises it.
    pub cells_per_element: f64,
}

impl Default for GridConfig {
    fn default() -> Self {
        Self {
            resolution: Resolution::Auto,
            branching: 4,
            split_threshold: 10_000,
            max_depth: 0,
            max_bytes: 4 << 30,
            cells_per_element: 1.0,
        }
    }
}

/// Errors of grid construction.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GridError {
    /// A configuration value out of range; the message names it.
    BadConfig(String),
    /// The grid would exceed [`GridConfig::max_bytes`]; refused before allocating.
    TooLarge {
        /// Bytes the level needs (at least).
        bytes: u128,
        /// The cap.
        max_bytes: usize,
        /// The level's cells per axis.
        dims: [u64; 3],
    },
}

impl fmt::Display for GridError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadConfig(m) => write!(f, "{m}"),
            Self::TooLarge { bytes, max_bytes, dims } => write!(
                f,
                "a {}x{}x{} grid needs at least {bytes} bytes, more than the bound of {max_bytes} bytes",
                dims[0], dims[1], dims[2]
            ),
        }
    }
}

impl std::error::Error for GridError {}

/// The elements a grid is built over.
pub trait GridElements: Sync {
    /// How many.
    fn len(&self) -> usize;
    /// True when there are none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Bounds of element `i` (an empty box puts it in no cell).
    fn bounds(&self, i: usize) -> Aabb;
    /// Exact (or conservative) overlap of element `i` with a closed box.
    fn overlaps(&self, i: usize, cell: &Aabb) -> bool;
    /// Triangles element `i` stands for (1 for a triangle).
    fn weight(&self, i: usize) -> u64;
}

/// The triangles of a mesh, assigned by the exact triangle–box test (§3.1).
pub struct MeshTriangles<'a>(pub &'a Mesh);

impl GridElements for MeshTriangles<'_> {
    fn len(&self) -> usize {
        self.0.triangle_count()
    }
    fn bounds(&self, i: usize) -> Aabb {
        Aabb::from_points(self.0.triangle_positions(i))
    }
    fn overlaps(&self, i: usize, cell: &Aabb) -> bool {
        tri_box_overlap(cell, self.0.triangle_positions(i))
    }
    fn weight(&self, _: usize) -> u64 {
        1
    }
}

/// Boxes with weights (instances of a group, by their placed bounds): assigned to every cell
/// their box overlaps, which holds every point of what they bound.
pub struct WeightedBoxes {
    /// One box per element.
    pub boxes: Vec<Aabb>,
    /// One weight per element.
    pub weights: Vec<u64>,
}

impl GridElements for WeightedBoxes {
    fn len(&self) -> usize {
        self.boxes.len()
    }
    fn bounds(&self, i: usize) -> Aabb {
        self.boxes[i]
    }
    fn overlaps(&self, i: usize, cell: &Aabb) -> bool {
        self.boxes[i].overlaps(cell)
    }
    fn weight(&self, i: usize) -> u64 {
        self.weights[i]
    }
}

/// A non-empty cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridCell {
    /// The cell's box intersected with its elements' bounds (see the module doc).
    pub tight: Aabb,
    /// Its elements: `elements[first..first + count]` of the grid.
    pub first: u32,
    /// Number of elements.
    pub count: u32,
    /// Level index of its subgrid, or [`NO_CHILD`].
    pub child: u32,
    /// Sum of its elements' weights (saturating).
    pub weight: u64,
}

impl GridCell {
    /// The range of its elements in [`NestedGrid::elements`].
    pub fn range(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }
}

/// One uniform grid: the top level, or the subgrid of a split cell.
#[derive(Clone, Debug, PartialEq)]
pub struct GridLevel {
    /// The box it divides.
    pub bounds: Aabb,
    /// Cells per axis.
    pub dims: [u32; 3],
    /// Size of one cell.
    pub cell_size: Vec3,
    /// Nesting depth (0 at the top).
    pub depth: u32,
    /// Its non-empty cells.
    pub cells: Vec<GridCell>,
}

/// A uniform grid (`max_depth` 0) or nested grid over elements.
#[derive(Clone, Debug, PartialEq)]
pub struct NestedGrid {
    levels: Vec<GridLevel>,
    elements: Vec<u32>,
}

/// Bytes of one stored cell.
const CELL_BYTES: u128 = std::mem::size_of::<GridCell>() as u128;
/// Bytes per candidate during a level's build: a (cell, element) pair, and its stored index.
const CANDIDATE_BYTES: u128 = 12;

impl NestedGrid {
    /// Builds the grid over `elements` inside `bounds` (which should hold them all).
    ///
    /// # Errors
    /// [`GridError::BadConfig`] for resolution 0, branching < 2, split threshold 0 or a non
    /// finite `cells_per_element`; [`GridError::TooLarge`] when a level would exceed the memory
    /// bound (checked before allocating it).
    pub fn build(elements: &dyn GridElements, bounds: Aabb, config: &GridConfig) -> Result<Self, GridError> {
        if config.resolution == Resolution::Cells(0) {
            return Err(GridError::BadConfig("grid resolution must be at least 1".into()));
        }
        if config.branching < 2 {
            return Err(GridError::BadConfig(format!(
                "grid branching {} must be at least 2",
                config.branching
            )));
        }
        if config.split_threshold == 0 {
            return Err(GridError::BadConfig("grid split threshold must be at least 1".into()));
        }
        if !(config.cells_per_element.is_finite() && config.cells_per_element > 0.0) {
            return Err(GridError::BadConfig("cells per element must be positive".into()));
        }
        let mut grid = Self {
            levels: Vec::new(),
            elements: Vec::new(),
        };
        let all: Vec<u32> = (0..elements.len() as u32)
            .filter(|&i| !elements.bounds(i as usize).is_empty())
            .collect();
        if bounds.is_empty() || all.is_empty() {
            grid.levels.push(GridLevel {
                bounds,
                dims: [1, 1, 1],
                cell_size: Vec3::ZERO,
                depth: 0,
                cells: Vec::new(),
            });
            return Ok(grid);
        }
        let dims = top_dims(bounds, all.len(), config);
        let mut used: u128 = 0;
        // Work list of (level index to fill, its elements).
        grid.add_level(elements, bounds, dims, 0, &all, config, &mut used)?;
        Ok(grid)
    }

    /// Builds the level over `members` and, recursively, the subgrids of its split cells.
    #[allow(clippy::too_many_arguments)]
    fn add_level(
        &mut self,
        elements: &dyn GridElements,
        bounds: Aabb,
        dims: [u64; 3],
        depth: u32,
        members: &[u32],
        config: &GridConfig,
        used: &mut u128,
    ) -> Result<u32, GridError> {
        let size = bounds.size();
        let cell_size = Vec3::new(
            size.x / dims[0] as f32,
            size.y / dims[1] as f32,
            size.z / dims[2] as f32,
        );
        // Widen each cell so that float rounding in the overlap test can never drop an element
        // touching a cell face: every point of an element is then inside the widened box of the
        // cell its coordinates floor to.
        let slack = cell_size * 1e-4 + Vec3::splat(bounds.min.abs().max(bounds.max.abs()).max_element() * 1e-6);
        let range_of = |b: &Aabb| -> [std::ops::RangeInclusive<u64>; 3] {
            let lo = ((b.min - bounds.min) / cell_size.max(Vec3::splat(f32::MIN_POSITIVE))).floor();
            let hi = ((b.max - bounds.min) / cell_size.max(Vec3::splat(f32::MIN_POSITIVE))).floor();
            let clamp = |v: f32, d: u64| -> u64 { (v.max(0.0) as u64).min(d - 1) };
            [
                clamp(lo.x, dims[0])..=clamp(hi.x, dims[0]),
                clamp(lo.y, dims[1])..=clamp(hi.y, dims[1]),
                clamp(lo.z, dims[2])..=clamp(hi.z, dims[2]),
            ]
        };
        // Count candidates before allocating anything that depends on the resolution.
        let candidates: u128 = members
            .iter()
            .map(|&e| {
                let r = range_of(&elements.bounds(e as usize));
                r.iter().map(|a| (a.end() - a.start() + 1) as u128).product::<u128>()
            })
            .sum();
        let cell_count = dims.iter().map(|&d| d as u128).product::<u128>();
        let bytes = candidates * CANDIDATE_BYTES + candidates.min(cell_count) * CELL_BYTES;
        if *used + bytes > config.max_bytes as u128 || cell_count > u32::MAX as u128 {
            return Err(GridError::TooLarge {
                bytes: *used + bytes,
                max_bytes: config.max_bytes,
                dims,
            });
        }
        *used += bytes;
        let cell_box = |c: [u64; 3]| -> Aabb {
            let min = bounds.min + cell_size * Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
            Aabb::new(min - slack, min + cell_size + slack)
        };
        let linear = |c: [u64; 3]| -> u32 { ((c[2] * dims[1] + c[1]) * dims[0] + c[0]) as u32 };
        // (cell, element) pairs that pass the exact test.
        let mut pairs: Vec<(u32, u32)> = members
            .par_iter()
            .flat_map_iter(|&e| {
                let r = range_of(&elements.bounds(e as usize));
                let mut out = Vec::new();
                for z in r[2].clone() {
                    for y in r[1].clone() {
                        for x in r[0].clone() {
                            let c = [x, y, z];
                            if elements.overlaps(e as usize, &cell_box(c)) {
                                out.push((linear(c), e));
                            }
                        }
                    }
                }
                out
            })
            .collect();
        pairs.par_sort_unstable();
        let level_index = self.levels.len() as u32;
        let mut cells = Vec::new();
        let mut split = Vec::new();
        let mut i = 0;
        while i < pairs.len() {
            let cell = pairs[i].0;
            let mut j = i;
            let mut union = Aabb::EMPTY;
            let mut weight = 0u64;
            while j < pairs.len() && pairs[j].0 == cell {
                let e = pairs[j].1 as usize;
                union = union.union(elements.bounds(e));
                weight = weight.saturating_add(elements.weight(e));
                j += 1;
            }
            let c = cell as u64;
            let coords = [c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])];
            let cb = cell_box(coords);
            let first = self.elements.len() as u32;
            self.elements.extend(pairs[i..j].iter().map(|p| p.1));
            if j - i > config.split_threshold && depth < config.max_depth {
                split.push((cells.len(), cb, first, (j - i) as u32));
            }
            cells.push(GridCell {
                tight: cb.intersection(union),
                first,
                count: (j - i) as u32,
                child: NO_CHILD,
                weight,
            });
            i = j;
        }
        drop(pairs);
        self.levels.push(GridLevel {
            bounds,
            dims: dims.map(|d| d as u32),
            cell_size,
            depth,
            cells,
        });
        // §3.2: split cells with more than the threshold, `branching` per axis.
        let b = config.branching as u64;
        for (cell_index, cb, first, count) in split {
            let members: Vec<u32> = self.elements[first as usize..(first + count) as usize].to_vec();
            let child = self.add_level(elements, cb, [b, b, b], depth + 1, &members, config, used)?;
            self.levels[level_index as usize].cells[cell_index].child = child;
        }
        Ok(level_index)
    }

    /// The levels; `levels()[0]` is the top one, subgrids are named by [`GridCell::child`].
    pub fn levels(&self) -> &[GridLevel] {
        &self.levels
    }

    /// Element indices of all cells, in cell order (a cell's are [`GridCell::range`]).
    pub fn elements(&self) -> &[u32] {
        &self.elements
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.elements.len() * 4
            + self
                .levels
                .iter()
                .map(|l| std::mem::size_of::<GridLevel>() + l.cells.len() * std::mem::size_of::<GridCell>())
                .sum::<usize>()
    }
}

/// Cells per axis of the top level: the resolution along the longest axis, the others in
/// proportion (at least 1), then lowered until the cell count is at most
/// `max(1, elements × cells_per_element)`.
fn top_dims(bounds: Aabb, element_count: usize, config: &GridConfig) -> [u64; 3] {
    let size = bounds.size().max(Vec3::ZERO);
    let longest = size.max_element();
    if longest.is_nan() || longest <= 0.0 || !longest.is_finite() {
        return [1, 1, 1];
    }
    let rel = size / longest;
    let dims_for = |n: f64| -> [u64; 3] {
        [rel.x, rel.y, rel.z].map(|r| ((n * r as f64).round() as u64).clamp(1, MAX_AXIS_CELLS))
    };
    let cap = (element_count as f64 * config.cells_per_element).max(1.0);
    let mut n = match config.resolution {
        Resolution::Cells(n) => n as f64,
        Resolution::Auto => {
            // Cubic cells holding ~AUTO_ELEMENTS_PER_CELL elements: n³·(rel volume) = e / k.
            let vol = (rel.x.max(1e-3) * rel.y.max(1e-3) * rel.z.max(1e-3)) as f64;
            (element_count as f64 / AUTO_ELEMENTS_PER_CELL / vol)
                .cbrt()
                .clamp(1.0, 64.0)
        }
    };
    loop {
        let d = dims_for(n);
        if n <= 1.0 || (d[0] as f64) * (d[1] as f64) * (d[2] as f64) <= cap {
            return d;
        }
        n = (n * 0.9).floor().max(1.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad_mesh(n: u32) -> Mesh {
        // n x n unit quads in the z = 0 plane.
        let mut p = Vec::new();
        let mut t = Vec::new();
        for y in 0..=n {
            for x in 0..=n {
                p.push(Vec3::new(x as f32, y as f32, 0.0));
            }
        }
        for y in 0..n {
            for x in 0..n {
                let i = y * (n + 1) + x;
                t.push([i, i + 1, i + n + 2]);
                t.push([i, i + n + 2, i + n + 1]);
            }
        }
        Mesh::new(p, t).expect("a grid of in-range triangles is a valid mesh")
    }

    /// Every triangle is in every cell whose (widened) box it overlaps, and in no other.
    #[test]
    fn assignment_is_exact() {
        let mesh = quad_mesh(16);
        let cfg = GridConfig {
            resolution: Resolution::Cells(5),
            ..GridConfig::default()
        };
        let g = NestedGrid::build(&MeshTriangles(&mesh), mesh.bounds(), &cfg)
            .expect("a 5-cell grid of a 16x16 quad mesh is within the memory bound");
        let top = &g.levels()[0];
        assert_eq!(top.dims, [5, 5, 1]);
        let mut seen = vec![0u32; mesh.triangle_count()];
        for c in &top.cells {
            for &e in &g.elements()[c.range()] {
                seen[e as usize] += 1;
                assert!(tri_box_overlap(
                    &c.tight.union(c.tight),
                    mesh.triangle_positions(e as usize)
                ));
            }
        }
        assert!(seen.iter().all(|&s| s >= 1), "every triangle lands in a cell");
        assert!(seen.iter().any(|&s| s > 1), "triangles on cell faces are shared");
    }

    #[test]
    fn nested_grid_splits_full_cells() {
        let mesh = quad_mesh(32);
        let cfg = GridConfig {
            resolution: Resolution::Cells(2),
            split_threshold: 100,
            max_depth: 2,
            ..GridConfig::default()
        };
        let g = NestedGrid::build(&MeshTriangles(&mesh), mesh.bounds(), &cfg)
            .expect("a nested grid of a quad mesh is within the memory bound");
        assert!(g.levels().len() > 1);
        for l in g.levels() {
            for c in &l.cells {
                if c.child != NO_CHILD {
                    assert!(c.count as usize > 100);
                    assert_eq!(g.levels()[c.child as usize].depth, l.depth + 1);
                    assert_eq!(g.levels()[c.child as usize].dims, [4, 4, 4]);
                } else if l.depth < 2 {
                    assert!(c.count as usize <= 100);
                }
            }
        }
        let uniform = NestedGrid::build(
            &MeshTriangles(&mesh),
            mesh.bounds(),
            &GridConfig {
                max_depth: 0,
                ..cfg.clone()
            },
        )
        .expect("a uniform grid of a quad mesh is within the memory bound");
        assert_eq!(uniform.levels().len(), 1);
    }

    #[test]
    fn bad_configs_are_errors() {
        let mesh = quad_mesh(2);
        let b = mesh.bounds();
        let e = MeshTriangles(&mesh);
        for cfg in [
            GridConfig {
                resolution: Resolution::Cells(0),
                ..GridConfig::default()
            },
            GridConfig {
                branching: 1,
                ..GridConfig::default()
            },
            GridConfig {
                split_threshold: 0,
                ..GridConfig::default()
            },
            GridConfig {
                cells_per_element: f64::NAN,
                ..GridConfig::default()
            },
        ] {
            assert!(matches!(NestedGrid::build(&e, b, &cfg), Err(GridError::BadConfig(_))));
        }
    }

    /// A resolution whose candidates alone would need terabytes is refused before allocating.
    #[test]
    fn absurd_resolution_is_refused() {
        // One huge triangle spanning the whole box: it is a candidate of every cell.
        let mesh = Mesh::new(
            vec![
                Vec3::ZERO,
                Vec3::new(1000.0, 0.0, 1000.0),
                Vec3::new(0.0, 1000.0, 1000.0),
            ],
            vec![[0, 1, 2]],
        )
        .expect("one huge in-range triangle is a valid mesh");
        let cfg = GridConfig {
            resolution: Resolution::Cells(60_000),
            cells_per_element: 1e30,
            ..GridConfig::default()
        };
        let err = NestedGrid::build(&MeshTriangles(&mesh), mesh.bounds(), &cfg).unwrap_err();
        assert!(matches!(err, GridError::TooLarge { .. }), "{err}");
        assert!(err.to_string().contains("bound"));
    }

    #[test]
    fn empty_and_degenerate_inputs() {
        let mesh = Mesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 2]]).expect("a point-sized triangle is a valid mesh");
        let g = NestedGrid::build(&MeshTriangles(&mesh), mesh.bounds(), &GridConfig::default())
            .expect("a point-sized triangle grids into one cell");
        // A point-sized triangle: one 1x1x1 level, one cell holding it.
        assert_eq!(g.levels()[0].dims, [1, 1, 1]);
        assert_eq!(g.elements(), &[0]);
        let none = WeightedBoxes {
            boxes: vec![],
            weights: vec![],
        };
        let g = NestedGrid::build(&none, Aabb::EMPTY, &GridConfig::default())
            .expect("no elements grid into an empty level");
        assert!(g.levels()[0].cells.is_empty());
    }

    #[test]
    fn small_element_counts_cap_the_resolution() {
        let boxes = WeightedBoxes {
            boxes: (0..4)
                .map(|i| Aabb::new(Vec3::splat(i as f32 * 10.0), Vec3::splat(i as f32 * 10.0 + 1.0)))
                .collect(),
            weights: vec![5; 4],
        };
        let b = Aabb::new(Vec3::ZERO, Vec3::splat(31.0));
        let g = NestedGrid::build(
            &boxes,
            b,
            &GridConfig {
                resolution: Resolution::Cells(50),
                ..GridConfig::default()
            },
        )
        .expect("four boxes in a 50-cell grid are within the memory bound");
        let d = g.levels()[0].dims;
        assert!(d[0] * d[1] * d[2] <= 4, "{d:?}");
        assert_eq!(g.levels()[0].cells.iter().map(|c| c.weight).sum::<u64>(), 20);
    }
}
