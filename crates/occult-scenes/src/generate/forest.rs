//! `forest`: a fractal landscape covered by instanced, procedurally grown trees, replicated
//! through nested instancing up to 1.4·10^14 triangles.
//!
//! # References
//! - Wand et al. 2001, §7.3 (scene encoding by hierarchical instantiation) and §8.6: "replicated
//!   trees: … 5.9·10^9 instances of complex tree models consisting of about 23,300 triangles each
//!   replicated on a quadratic grid" (1.37·10^14 triangles in 36 MB), and the "landscape scene"
//!   of tree instances on a fractal landscape.
//!
//! # Structure
//! - **Trees**: `variants` meshes of exactly [`TREE_TRIANGLES`] (19,500) triangles: a bent,
//!   tapered trunk, 7 limbs, 4 branches per limb, 3 twigs per branch (tubes), and 100 leaves (a
//!   quad each) around every twig; bark and leaf colors per variant.
//! - **Patches**: a group of `trees × trees` tree instances on a jittered grid (pitch
//!   [`TREE_SPACING`]), each with a random variant, rotation about +y and scale 0.8–1.2, standing
//!   on the terrain (heights read from the terrain's own triangles).
//! - **Tiles**: a periodic fractal terrain mesh (midpoint displacement, diamond-square on a
//!   wrapped `2^k` grid, so copies tile seamlessly) plus `patches × patches` patch groups; side
//!   `T = patches·trees·TREE_SPACING` (128 m by default).
//! - **Replication**: `levels` nested levels, each a `replicate × replicate` grid of the level
//!   below (rows nested, see `shapes::grid`); `replicate^(2·levels)` tiles in all, centred on
//!   the origin. The root node is named `"forest"`.
//!
//! Triangle instances: `tiles·((patches·trees)²·19,500 + 2·g²)` with `g` the terrain grid
//! (`min(1024, next_pow2(T/2))`, 64 by default). Default: 5,000,192. `replicate=73,levels=2`
//! gives 1.42·10^14 (28,398,241 tiles; ≈ 3 MB, milliseconds); so does `replicate=5292`
//! (1.40·10^14). Unique geometry is a few MB whatever the replication.
//!
//! Deviation: trees have 19,500 triangles rather than the paper's ≈ 23,300, and tiles carry a
//! terrain (the paper's replicated trees stand on a plain grid); the 1.4·10^14 total is reached
//! with correspondingly more instances.

use super::shapes::{grid, grid_quads, MeshBuilder, BYTES_PER_BUILT_TRIANGLE, BYTES_PER_INSTANCE};
use super::{camera_for, check_budget, check_range, scene_error, GenerateError, GeneratorInfo, ParamInfo};
use occult_core::glam::Quat;
use occult_core::{Affine3A, Camera, CoreError, Instance, Mesh, MeshColors, Rgba8, Scene, SceneBuilder, Vec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// Triangles of every tree variant.
pub const TREE_TRIANGLES: u64 = TRUNK_TRIANGLES
    + LIMBS * (LIMB_TRIANGLES + BRANCHES * (BRANCH_TRIANGLES + TWIGS * (TWIG_TRIANGLES + 2 * LEAVES_PER_TWIG)));
/// Distance between neighbouring trees of a patch (before jitter), metres.
pub const TREE_SPACING: f32 = 8.0;
/// Name of the root node.
pub const ROOT_NAME: &str = "forest";
/// Largest side of the whole forest, metres: beyond, `f32` positions lose centimetres.
pub const MAX_SIDE: f64 = 2.0e6;
/// Largest terrain grid per tile (quads per side).
const MAX_TERRAIN_GRID: u32 = 1024;

const TRUNK_SIDES: u32 = 10;
const TRUNK_RINGS: u32 = 9;
const TRUNK_TRIANGLES: u64 = 2 * TRUNK_SIDES as u64 * (TRUNK_RINGS as u64 - 1) + 2 * TRUNK_SIDES as u64;
const LIMBS: u64 = 7;
const LIMB_SIDES: u32 = 6;
const LIMB_RINGS: u32 = 5;
const LIMB_TRIANGLES: u64 = 2 * LIMB_SIDES as u64 * (LIMB_RINGS as u64 - 1);
const BRANCHES: u64 = 4;
const BRANCH_SIDES: u32 = 5;
const BRANCH_RINGS: u32 = 4;
const BRANCH_TRIANGLES: u64 = 2 * BRANCH_SIDES as u64 * (BRANCH_RINGS as u64 - 1);
const TWIGS: u64 = 3;
const TWIG_SIDES: u32 = 4;
const TWIG_RINGS: u32 = 3;
const TWIG_TRIANGLES: u64 = 2 * TWIG_SIDES as u64 * (TWIG_RINGS as u64 - 1);
const LEAVES_PER_TWIG: u64 = 100;

const BARK: [Rgba8; 3] = [[95, 70, 50, 255], [110, 85, 60, 255], [80, 65, 55, 255]];
const LEAF_GREENS: [Rgba8; 6] = [
    [60, 120, 45, 255],
    [80, 140, 50, 255],
    [45, 100, 50, 255],
    [110, 150, 60, 255],
    [70, 110, 35, 255],
    [130, 140, 50, 255],
];

generator_params! {
    /// Parameters of [`generate`].
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct ForestParams {
        /// Trees per side of a patch, `1..=64` (default 4).
        pub trees: u32 = 4,
        /// Patches per side of a tile, `1..=64`, with `trees·patches ≤ 1024` (default 4).
        pub patches: u32 = 4,
        /// Tiles per side of each replication level, `1..=1,000,000` (default 1).
        pub replicate: u32 = 1,
        /// Nested replication levels, `1..=8` (default 1; ignored when `replicate = 1`).
        pub levels: u32 = 1,
        /// Unique tree meshes, `1..=64` (default 4).
        pub variants: u32 = 4,
        /// Random seed of terrain, trees and placement (default 1).
        pub seed: u64 = 1,
    }
}

impl ForestParams {
    /// The setting with ≥ 1.4·10^14 triangle instances (Wand et al.'s replicated trees).
    pub fn replicated_1e14() -> Self {
        Self {
            replicate: 73,
            levels: 2,
            ..Self::default()
        }
    }

    /// Side of one tile, metres.
    pub fn tile_side(&self) -> f32 {
        (self.patches as u64 * self.trees as u64) as f32 * TREE_SPACING
    }

    /// Quads per side of a tile's terrain.
    pub fn terrain_grid(&self) -> u32 {
        // Clamp before rounding up: MAX_TERRAIN_GRID is a power of two, so this cannot overflow.
        ((self.tile_side() / 2.0).ceil() as u32)
            .clamp(1, MAX_TERRAIN_GRID)
            .next_power_of_two()
    }

    /// Tiles in the whole forest (saturating).
    pub fn tile_count(&self) -> u128 {
        if self.replicate <= 1 {
            return 1;
        }
        (self.replicate as u128).saturating_pow(2 * self.levels)
    }

    /// Triangle instances (saturating): `tiles·((patches·trees)²·TREE_TRIANGLES + 2·g²)`.
    pub fn item_count(&self) -> u128 {
        let trees = (self.patches as u128 * self.trees as u128).pow(2);
        let per_tile = trees * TREE_TRIANGLES as u128 + 2 * (self.terrain_grid() as u128).pow(2);
        self.tile_count().saturating_mul(per_tile)
    }
}

/// Name, description and parameters, for `occult scenes`.
pub const INFO: GeneratorInfo = GeneratorInfo {
    name: "forest",
    description: "fractal terrain with instanced 19,500-triangle trees in patches and tiles, nested replication (replicate=73,levels=2: 1.4e14 triangles)",
    params: &[
        ParamInfo { name: "trees", default: "4", meaning: "trees per side of a patch (pitch 8 m), 1..=64" },
        ParamInfo { name: "patches", default: "4", meaning: "patches per side of a tile, 1..=64, trees*patches <= 1024" },
        ParamInfo {
            name: "replicate",
            default: "1",
            meaning: "tiles per side of each replication level, 1..=1000000 (forest side <= 2000 km)",
        },
        ParamInfo { name: "levels", default: "1", meaning: "nested replication levels (replicate^(2*levels) tiles), 1..=8" },
        ParamInfo { name: "variants", default: "4", meaning: "unique tree meshes, 1..=64" },
        ParamInfo { name: "seed", default: "1", meaning: "random seed for terrain, trees and placement" },
    ],
};

const NAME: &str = "forest";

/// Checks parameters without building anything: ranges, then the memory and item-id bounds
/// (the checks [`generate`] makes first).
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range or a forest wider than
/// [`MAX_SIDE`]; [`GenerateError::TooLarge`] past the memory or item-id bounds.
pub fn validate(p: &ForestParams) -> Result<(), GenerateError> {
    check_range(NAME, "trees", p.trees as u64, 1, 64)?;
    check_range(NAME, "patches", p.patches as u64, 1, 64)?;
    check_range(NAME, "patches", (p.trees * p.patches) as u64, 1, 1024).map_err(|_| GenerateError::BadParameter {
        generator: NAME,
        parameter: "patches".into(),
        value: p.patches.to_string(),
        reason: format!("trees*patches = {} exceeds 1024", p.trees * p.patches),
    })?;
    check_range(NAME, "replicate", p.replicate as u64, 1, 1_000_000)?;
    check_range(NAME, "levels", p.levels as u64, 1, 8)?;
    check_range(NAME, "variants", p.variants as u64, 1, 64)?;
    let side = p.tile_side() as f64 * (p.tile_count() as f64).sqrt();
    if side > MAX_SIDE {
        return Err(GenerateError::BadParameter {
            generator: NAME,
            parameter: "replicate".into(),
            value: p.replicate.to_string(),
            reason: format!(
                "the forest would be {:.0} km wide, over {:.0} km",
                side / 1e3,
                MAX_SIDE / 1e3
            ),
        });
    }
    let g = p.terrain_grid() as u128;
    let trees_per_tile = ((p.trees * p.patches) as u128).pow(2);
    let bytes = p.variants as u128 * TREE_TRIANGLES as u128 * BYTES_PER_BUILT_TRIANGLE as u128
        + 2 * g * g * 16
        + (g + 1).pow(2) * 12
        + (trees_per_tile + 2 * p.replicate as u128 * p.levels as u128) * BYTES_PER_INSTANCE as u128;
    check_budget(NAME, "replicate", bytes, p.item_count())?;
    Ok(())
}

/// Builds the forest.
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range or a forest wider than
/// [`MAX_SIDE`]; [`GenerateError::TooLarge`] past the memory or item-id bounds.
pub fn generate(p: &ForestParams) -> Result<Scene, GenerateError> {
    validate(p)?;
    let err = scene_error(NAME);
    let trees: Vec<_> = (0..p.variants).into_par_iter().map(|v| tree_mesh(p.seed, v)).collect();
    let field = Heightfield::new(p.seed, p.terrain_grid(), p.tile_side());
    let mut sb = SceneBuilder::new();
    let mut tree_ids = Vec::with_capacity(trees.len());
    for (v, mesh) in trees.into_iter().enumerate() {
        tree_ids.push(sb.add_mesh(format!("tree {v}"), mesh.map_err(&err)?).map_err(&err)?);
    }
    let terrain = sb
        .add_mesh("forest terrain", field.mesh().map_err(&err)?)
        .map_err(&err)?;

    let mut tile = vec![Instance {
        parent_from_child: Affine3A::IDENTITY,
        child: terrain,
    }];
    let mut rng = Pcg64Mcg::seed_from_u64(p.seed.wrapping_mul(31).wrapping_add(17));
    for pj in 0..p.patches {
        for pi in 0..p.patches {
            let mut instances = Vec::with_capacity((p.trees * p.trees) as usize);
            for b in 0..p.trees {
                for a in 0..p.trees {
                    let jitter = TREE_SPACING * 0.3;
                    let x = ((pi * p.trees + a) as f32 + 0.5) * TREE_SPACING + rng.random_range(-jitter..jitter);
                    let z = ((pj * p.trees + b) as f32 + 0.5) * TREE_SPACING + rng.random_range(-jitter..jitter);
                    let y = field.height_at(x, z);
                    let transform = Affine3A::from_scale_rotation_translation(
                        Vec3::splat(rng.random_range(0.8..1.2)),
                        Quat::from_rotation_y(rng.random_range(0.0..std::f32::consts::TAU)),
                        Vec3::new(x, y, z),
                    );
                    let v = rng.random_range(0..p.variants) as usize;
                    instances.push(Instance {
                        parent_from_child: transform,
                        child: tree_ids[v],
                    });
                }
            }
            let patch = sb.add_group(format!("patch {pi},{pj}"), instances).map_err(&err)?;
            tile.push(Instance {
                parent_from_child: Affine3A::IDENTITY,
                child: patch,
            });
        }
    }
    let mut node = sb.add_group("tile", tile).map_err(&err)?;
    let mut side = p.tile_side();
    if p.replicate > 1 {
        for level in 0..p.levels {
            node = grid(
                &mut sb,
                &format!("replication {level}"),
                p.replicate,
                p.replicate,
                side,
                side,
                Vec3::ZERO,
                |_| 0,
                |_, _| node,
            )
            .map_err(&err)?;
            side *= p.replicate as f32;
        }
    }
    let centre = Affine3A::from_translation(Vec3::new(-0.5 * side, 0.0, -0.5 * side));
    let root = sb
        .add_group(
            ROOT_NAME,
            vec![Instance {
                parent_from_child: centre,
                child: node,
            }],
        )
        .map_err(&err)?;
    sb.build(root).map_err(&err)
}

/// A periodic fractal heightfield over one tile: `g × g` samples on a torus.
struct Heightfield {
    g: u32,
    side: f32,
    heights: Vec<f32>,
}

impl Heightfield {
    /// Midpoint displacement (diamond-square) with wrap-around, so that the field tiles
    /// seamlessly; relief scaled to 10 % of the tile side, at most 40 m.
    fn new(seed: u64, g: u32, side: f32) -> Self {
        let n = g as usize;
        let mut h = vec![0.0f32; n * n];
        let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x07E4_4A1D_u64);
        let at = |i: usize, j: usize| (j % n) * n + (i % n);
        let mut step = n;
        let mut amplitude = 1.0f32;
        while step > 1 {
            let half = step / 2;
            // Diamond step: centres of squares.
            for j in (0..n).step_by(step) {
                for i in (0..n).step_by(step) {
                    let avg =
                        (h[at(i, j)] + h[at(i + step, j)] + h[at(i, j + step)] + h[at(i + step, j + step)]) * 0.25;
                    h[at(i + half, j + half)] = avg + rng.random_range(-amplitude..=amplitude);
                }
            }
            // Square step: edge midpoints, from their four wrapped neighbours.
            for j in (0..n).step_by(half) {
                let start = if (j / half).is_multiple_of(2) { half } else { 0 };
                for i in (start..n).step_by(step) {
                    let avg =
                        (h[at(i + n - half, j)] + h[at(i + half, j)] + h[at(i, j + n - half)] + h[at(i, j + half)])
                            * 0.25;
                    h[at(i, j)] = avg + rng.random_range(-amplitude..=amplitude);
                }
            }
            amplitude *= 0.55;
            step = half;
        }
        let (lo, hi) = h
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let relief = (0.1 * side).min(40.0);
        let scale = if hi > lo { relief / (hi - lo) } else { 0.0 };
        for v in &mut h {
            *v = (*v - lo) * scale;
        }
        Self { g, side, heights: h }
    }

    fn sample(&self, i: u32, j: u32) -> f32 {
        let n = self.g;
        self.heights[((j % n) * n + (i % n)) as usize]
    }

    /// Height of the triangulated surface at tile coordinates `(x, z)` (wrapped).
    fn height_at(&self, x: f32, z: f32) -> f32 {
        let cell = self.side / self.g as f32;
        let (u, v) = (
            (x / cell).rem_euclid(self.g as f32),
            (z / cell).rem_euclid(self.g as f32),
        );
        let (i, j) = ((u as u32).min(self.g - 1), (v as u32).min(self.g - 1));
        let (fx, fz) = (u - i as f32, v - j as f32);
        let (h00, h10, h01, h11) = (
            self.sample(i, j),
            self.sample(i + 1, j),
            self.sample(i, j + 1),
            self.sample(i + 1, j + 1),
        );
        // The two triangles of the quad, as the mesh splits it (see `mesh`).
        if fx + fz <= 1.0 {
            h00 + fx * (h10 - h00) + fz * (h01 - h00)
        } else {
            h11 + (1.0 - fx) * (h01 - h11) + (1.0 - fz) * (h10 - h11)
        }
    }

    /// The tile's terrain mesh over `[0, side]²`, triangles facing +y, colored by height.
    fn mesh(&self) -> Result<Mesh, CoreError> {
        let (g, n) = (self.g, self.g + 1);
        let cell = self.side / g as f32;
        let positions = (0..n)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .map(|(i, j)| Vec3::new(i as f32 * cell, self.sample(i, j), j as f32 * cell))
            .collect();
        let relief = (0.1 * self.side).clamp(1e-3, 40.0);
        let (triangles, colors) = grid_quads(g, g, |i, j| {
            let t = (self.sample(i, j) / relief).clamp(0.0, 1.0);
            [
                (70.0 + 60.0 * t) as u8,
                (95.0 + 20.0 * t) as u8,
                (45.0 + 20.0 * t) as u8,
                255,
            ]
        });
        Mesh::new(positions, triangles)?.with_colors(MeshColors::PerTriangle(colors))
    }
}

/// A unit direction rotated away from `dir` by `angle` radians, about a random axis.
fn deviate(rng: &mut Pcg64Mcg, dir: Vec3, angle: f32) -> Vec3 {
    let axis = Quat::from_axis_angle(dir, rng.random_range(0.0..std::f32::consts::TAU)) * dir.any_orthonormal_vector();
    (Quat::from_axis_angle(axis, angle) * dir).normalize()
}

/// Points and radii of a slightly drooping branch from `start` along `dir`.
fn branch(start: Vec3, dir: Vec3, length: f32, rings: u32, r0: f32, r1: f32, droop: f32) -> (Vec<Vec3>, Vec<f32>) {
    (0..rings)
        .map(|k| {
            let t = k as f32 / (rings - 1) as f32;
            (
                start + dir * (length * t) - Vec3::Y * (droop * length * t * t),
                r0 + (r1 - r0) * t,
            )
        })
        .unzip()
}

/// Tree variant `variant`: exactly [`TREE_TRIANGLES`] triangles, base at the origin, +y up,
/// about 9–13 m tall.
fn tree_mesh(seed: u64, variant: u32) -> Result<Mesh, CoreError> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0xA5A5_0000_0000u64 ^ (variant as u64).wrapping_mul(0x9E37_79B9));
    let bark = BARK[variant as usize % BARK.len()];
    let greens = [
        LEAF_GREENS[variant as usize % LEAF_GREENS.len()],
        LEAF_GREENS[(variant as usize + 3) % LEAF_GREENS.len()],
    ];
    let mut m = MeshBuilder::new();
    let height = rng.random_range(9.0..13.0f32);
    let lean = Vec3::new(rng.random_range(-0.3..0.3), 0.0, rng.random_range(-0.3..0.3));
    let trunk_radius = rng.random_range(0.25..0.4f32);
    let (trunk, trunk_r): (Vec<Vec3>, Vec<f32>) = (0..TRUNK_RINGS)
        .map(|k| {
            let t = k as f32 / (TRUNK_RINGS - 1) as f32;
            (
                Vec3::new(0.0, -0.5 + (height + 0.5) * t, 0.0) + lean * (t * t),
                trunk_radius * (1.0 - 0.75 * t),
            )
        })
        .unzip();
    m.tube(&trunk, &trunk_r, TRUNK_SIDES, true, bark);
    let trunk_at = |t: f32| {
        let f = t * (TRUNK_RINGS - 1) as f32;
        let k = (f as usize).min(TRUNK_RINGS as usize - 2);
        trunk[k].lerp(trunk[k + 1], f - k as f32)
    };
    let azimuth0 = rng.random_range(0.0..std::f32::consts::TAU);
    for l in 0..LIMBS {
        let t = 0.35 + 0.55 * (l as f32 + rng.random_range(0.0..1.0)) / LIMBS as f32;
        let az = azimuth0 + l as f32 * 2.4 + rng.random_range(-0.3..0.3);
        let el = rng.random_range(0.35..0.9f32);
        let dir = Vec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin());
        let len = rng.random_range(3.0..4.5) * (1.2 - 0.6 * t);
        let start = trunk_at(t);
        let (pts, r) = branch(start, dir, len, LIMB_RINGS, 0.12, 0.05, 0.08);
        m.tube(&pts, &r, LIMB_SIDES, false, bark);
        for _ in 0..BRANCHES {
            let s = rng.random_range(0.3..0.95f32);
            let bstart = pts[0].lerp(pts[LIMB_RINGS as usize - 1], s);
            let angle = rng.random_range(0.5..0.9);
            let bdir = (deviate(&mut rng, dir, angle) + Vec3::Y * 0.3).normalize();
            let blen = len * rng.random_range(0.4..0.6);
            let (bpts, br) = branch(bstart, bdir, blen, BRANCH_RINGS, 0.05, 0.02, 0.1);
            m.tube(&bpts, &br, BRANCH_SIDES, false, bark);
            for _ in 0..TWIGS {
                let s = rng.random_range(0.4..1.0f32);
                let tstart = bpts[0].lerp(bpts[BRANCH_RINGS as usize - 1], s);
                let angle = rng.random_range(0.4..0.8);
                let tdir = (deviate(&mut rng, bdir, angle) + Vec3::Y * 0.2).normalize();
                let tlen = blen * rng.random_range(0.4..0.6);
                let (tpts, tr) = branch(tstart, tdir, tlen, TWIG_RINGS, 0.02, 0.01, 0.1);
                m.tube(&tpts, &tr, TWIG_SIDES, false, bark);
                let tip = tpts[TWIG_RINGS as usize - 1];
                for k in 0..LEAVES_PER_TWIG {
                    // A leaf: a rhombus around a point near the twig, randomly oriented.
                    let along = tstart.lerp(tip, rng.random_range(0.3..1.0));
                    let offset = Vec3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-0.6..0.8),
                        rng.random_range(-1.0..1.0),
                    );
                    let c = along + offset * 0.7;
                    let axis = Vec3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    )
                    .normalize_or(Vec3::X);
                    let side = axis.any_orthonormal_vector();
                    let (l2, w2) = (0.16, 0.07);
                    m.quad(
                        c - axis * l2,
                        c - side * w2,
                        c + axis * l2,
                        c + side * w2,
                        greens[(k % 2) as usize],
                    );
                }
            }
        }
    }
    debug_assert_eq!(m.triangle_count() as u64, TREE_TRIANGLES);
    m.finish()
}

/// Above the forest's centre, just over the tallest tree, looking towards +z and down at the
/// canopy: the near field in detail, the replicated far field up to the horizon.
pub fn default_camera(_p: &ForestParams, scene: &Scene) -> Camera {
    let b = scene.bounds();
    let c = b.center();
    let eye = Vec3::new(c.x, b.max.y + 8.0, c.z);
    let target = Vec3::new(c.x, b.min.y + 5.0, c.z + 120.0);
    camera_for(scene, eye, target, 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trees_have_the_documented_count() {
        assert_eq!(TREE_TRIANGLES, 19_500);
        for v in 0..3 {
            let t = tree_mesh(5, v).expect("a tree of every variant builds");
            assert_eq!(t.triangle_count() as u64, TREE_TRIANGLES);
            let b = t.bounds();
            assert!(b.max.y > 8.0 && b.max.y < 20.0 && b.min.y >= -0.6, "{b:?}");
        }
    }

    #[test]
    fn heightfield_is_periodic_and_matches_its_mesh() {
        let f = Heightfield::new(3, 16, 64.0);
        assert_eq!(f.height_at(0.0, 10.0), f.height_at(64.0, 10.0));
        let mesh = f.mesh().expect("a 16x16 heightfield is a valid mesh");
        // A vertex's height is the surface height at its position.
        for p in mesh.positions().iter().step_by(7) {
            assert!((f.height_at(p.x, p.z) - p.y).abs() < 1e-4);
        }
        // The last column repeats the first: copies tile without cracks.
        let n = 17;
        for j in 0..n {
            assert_eq!(mesh.positions()[j * n].y, mesh.positions()[j * n + 16].y);
        }
    }

    #[test]
    fn default_count_matches_formula() {
        let p = ForestParams::default();
        assert_eq!(p.item_count(), 5_000_192);
        let huge = ForestParams::replicated_1e14();
        assert!(huge.item_count() >= 140_000_000_000_000);
    }

    #[test]
    fn bad_parameters_are_errors() {
        let bad = |p: ForestParams| generate(&p).unwrap_err();
        assert!(matches!(
            bad(ForestParams {
                trees: 0,
                ..Default::default()
            }),
            GenerateError::BadParameter { .. }
        ));
        assert!(matches!(
            bad(ForestParams {
                trees: 64,
                patches: 64,
                ..Default::default()
            }),
            GenerateError::BadParameter { .. }
        ));
        assert!(matches!(
            bad(ForestParams {
                replicate: 1_000_000,
                levels: 8,
                ..Default::default()
            }),
            GenerateError::BadParameter { .. }
        ));
        assert!(matches!(
            bad(ForestParams {
                levels: 0,
                ..Default::default()
            }),
            GenerateError::BadParameter { .. }
        ));
    }
}
