//! `chessboard`: `n × n` black and white squares of two triangles each, the scene-complexity
//! test of the randomized z-buffer paper.
//!
//! # References
//! - Wand et al. 2001, §8.1: "a chessboard explicitly modeled of black and white triangles …
//!   increased the number of squares … the projected area and other geometric parameters
//!   remained constant for all levels of detail"; Figure 6 goes up to 10^14 triangles.
//!
//! The board always spans [`BOARD_SIDE`] × [`BOARD_SIDE`] world units centred on the origin in
//! the `y = 0` plane, whatever `n`, so that from the default camera it projects to the same
//! screen area at every size. Square `(i, j)` (i along +x, j along +z, from the `−x −z` corner)
//! is black when `i + j` is even. Triangles face +y. Exactly `2·n²` triangle instances.
//!
//! # Instancing
//! Squares are modelled in square units (integer coordinates, exact in `f32`) and the root
//! scales the board down to [`BOARD_SIDE`]. A `w × h` rectangle of squares is built
//! recursively: when both sides are at most [`BLOCK`] it is one mesh; otherwise, with `S` the
//! largest power of [`BLOCK`] below its longer side, it is a grid of `S × S` blocks plus a right
//! strip (`w mod S` wide), a top strip and a corner, each built the same way and memoized by
//! size. Every offset is a multiple of `S`, which is even, so parity (the colour pattern) is
//! preserved without colour variants. A board of any `n` thus needs `O(log n)` distinct nodes,
//! at most four leaf meshes of ≤ 512 triangles, and groups of at most `(BLOCK + 1)²` instances:
//! `n = 10^7` (2·10^14 triangles) builds in milliseconds in kilobytes. As in the paper, each
//! instancing level adds one transform per sample/triangle to renderers that descend the DAG.

use super::shapes::grid_quads;
use super::{check_budget, check_range, scene_error, GenerateError, GeneratorInfo, ParamInfo};
use occult_core::glam::Quat;
use occult_core::{Affine3A, Camera, CoreError, Instance, Mesh, MeshColors, NodeId, Rgba8, Scene, SceneBuilder, Vec3};
use std::collections::HashMap;

/// Side of the board in world units (constant whatever `n`).
pub const BOARD_SIDE: f32 = 100.0;
/// Squares per side of a leaf block (and fan-out per instancing level per axis). 16 keeps leaf
/// meshes at ≤ 512 triangles (fine-grained culling) and groups at ≤ 289 instances; larger means
/// fewer levels (fewer transforms per sample) but coarser leaves. Must be even.
pub const BLOCK: u32 = 16;
/// Largest `n`: square offsets must stay exact integers in `f32` (2^24).
pub const MAX_N: u32 = 1 << 24;
/// Color of black squares (not pure black, so Lambert shading stays readable).
pub const BLACK: Rgba8 = [28, 28, 30, 255];
/// Color of white squares.
pub const WHITE: Rgba8 = [232, 230, 222, 255];

generator_params! {
    /// Parameters of [`generate`].
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct ChessboardParams {
        /// Squares per side, `1..=16,777,216` (default 1024: 2,097,152 triangles; 10^7: 2·10^14).
        pub n: u32 = 1024,
    }
}

impl ChessboardParams {
    /// Triangle instances: `2·n²`.
    pub fn item_count(&self) -> u128 {
        2 * (self.n as u128).pow(2)
    }
}

/// Name, description and parameters, for `occult scenes`.
pub const INFO: GeneratorInfo = GeneratorInfo {
    name: "chessboard",
    description: "n x n black/white squares of constant projected area (Wand et al. 8.1), 2*n^2 triangles, hierarchically instanced",
    params: &[ParamInfo {
        name: "n",
        default: "1024",
        meaning: "squares per side, 1..=16777216 (n=10^7 gives 2*10^14 triangles)",
    }],
};

const NAME: &str = "chessboard";

/// Checks parameters without building anything: ranges, then the memory and item-id bounds
/// (the checks [`generate`] makes first).
///
/// # Errors
/// [`GenerateError::BadParameter`] for `n` out of `1..=MAX_N`.
pub fn validate(p: &ChessboardParams) -> Result<(), GenerateError> {
    check_range(NAME, "n", p.n as u64, 1, MAX_N as u64)?;
    // Unique geometry is at most four leaf meshes and O(log n) small groups.
    check_budget(NAME, "n", 1 << 20, p.item_count())?;
    Ok(())
}

/// Builds the chessboard.
///
/// # Errors
/// [`GenerateError::BadParameter`] for `n` out of `1..=MAX_N`.
pub fn generate(p: &ChessboardParams) -> Result<Scene, GenerateError> {
    validate(p)?;
    let mut board = Board {
        builder: SceneBuilder::new(),
        memo: HashMap::new(),
    };
    let node = board.rect(p.n, p.n).map_err(scene_error(NAME))?;
    let square = BOARD_SIDE / p.n as f32;
    let world_from_board = Affine3A::from_scale_rotation_translation(
        Vec3::splat(square),
        Quat::IDENTITY,
        Vec3::new(-0.5 * BOARD_SIDE, 0.0, -0.5 * BOARD_SIDE),
    );
    let root = board
        .builder
        .add_group(
            "chessboard",
            vec![Instance {
                parent_from_child: world_from_board,
                child: node,
            }],
        )
        .map_err(scene_error(NAME))?;
    board.builder.build(root).map_err(scene_error(NAME))
}

struct Board {
    builder: SceneBuilder,
    memo: HashMap<(u32, u32), NodeId>,
}

impl Board {
    /// The node of a `w × h` rectangle of squares whose `(0, 0)` square is black, in square
    /// units with its `−x −z` corner at the origin.
    fn rect(&mut self, w: u32, h: u32) -> Result<NodeId, CoreError> {
        if let Some(&id) = self.memo.get(&(w, h)) {
            return Ok(id);
        }
        let id = if w <= BLOCK && h <= BLOCK {
            self.builder.add_mesh(format!("squares {w}x{h}"), leaf(w, h)?)?
        } else {
            let longer = w.max(h);
            let mut s = BLOCK;
            while s * BLOCK < longer {
                s *= BLOCK;
            }
            let (qw, rw, qh, rh) = (w / s, w % s, h / s, h % s);
            let mut parts: Vec<(u32, u32, u32, u32)> = Vec::new(); // (w, h, offset i, offset j)
            for b in 0..qh {
                for a in 0..qw {
                    parts.push((s, s, a * s, b * s));
                }
                if rw > 0 {
                    parts.push((rw, s, qw * s, b * s));
                }
            }
            if rh > 0 {
                for a in 0..qw {
                    parts.push((s, rh, a * s, qh * s));
                }
                if rw > 0 {
                    parts.push((rw, rh, qw * s, qh * s));
                }
            }
            let mut instances = Vec::with_capacity(parts.len());
            for (pw, ph, oi, oj) in parts {
                let child = self.rect(pw, ph)?;
                // Offsets are integers below 2^24: exact in f32.
                let offset = Vec3::new(oi as f32, 0.0, oj as f32);
                instances.push(Instance {
                    parent_from_child: Affine3A::from_translation(offset),
                    child,
                });
            }
            self.builder.add_group(format!("squares {w}x{h}"), instances)?
        };
        self.memo.insert((w, h), id);
        Ok(id)
    }
}

/// One mesh of `w × h ≤ BLOCK²` squares, shared vertices, triangles row by row facing +y.
fn leaf(w: u32, h: u32) -> Result<Mesh, CoreError> {
    let positions = (0..=h)
        .flat_map(|j| (0..=w).map(move |i| Vec3::new(i as f32, 0.0, j as f32)))
        .collect();
    let (triangles, colors) = grid_quads(w, h, |i, j| if (i + j) % 2 == 0 { BLACK } else { WHITE });
    Mesh::new(positions, triangles)?.with_colors(MeshColors::PerTriangle(colors))
}

/// An oblique view of the whole board from its `−z` side; the board's projected area is the
/// same for every `n`.
pub fn default_camera(_p: &ChessboardParams, _scene: &Scene) -> Camera {
    Camera {
        eye: Vec3::new(0.0, 70.0, -95.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 60.0,
        near: 1.0,
        far: 400.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn color_at(scene: &Scene, i: u32, j: u32, n: u32) -> Rgba8 {
        // The centre of square (i, j), found by brute force over the flattened board.
        let flat = scene
            .flatten(1 << 20)
            .expect("a board of up to 37x37 squares is under 2^20 triangles");
        let square = BOARD_SIDE / n as f32;
        let c = Vec3::new(
            -50.0 + (i as f32 + 0.5) * square,
            0.0,
            -50.0 + (j as f32 + 0.5) * square,
        );
        let t = (0..flat.triangle_count())
            .find(|&t| {
                let [a, b, cc] = flat.triangle_positions(t);
                let lo = a.min(b).min(cc);
                let hi = a.max(b).max(cc);
                c.x > lo.x && c.x < hi.x && c.z > lo.z && c.z < hi.z
            })
            .expect("a triangle covers the centre of every square");
        flat.triangle_color(t).expect("a board has per-triangle colours")
    }

    #[test]
    fn counts_and_bounds_for_awkward_sizes() {
        for n in [1, 2, 15, 16, 17, 33, 255, 257, 300] {
            let s = generate(&ChessboardParams { n }).expect("every board size in range generates");
            assert_eq!(s.item_count(), 2 * (n as u64).pow(2), "n = {n}");
            let b = s.bounds();
            assert!(
                (b.min.x + 50.0).abs() < 1e-3 && (b.max.z - 50.0).abs() < 1e-3,
                "n = {n}: {b:?}"
            );
        }
    }

    #[test]
    fn parity_is_a_checkerboard_across_blocks() {
        let n = 37;
        let s = generate(&ChessboardParams { n }).expect("a 37x37 board generates");
        for (i, j) in [(0, 0), (1, 0), (16, 0), (17, 3), (32, 32), (36, 35), (36, 36)] {
            let want = if (i + j) % 2 == 0 { BLACK } else { WHITE };
            assert_eq!(color_at(&s, i, j, n), want, "square ({i}, {j})");
        }
    }

    #[test]
    fn huge_board_is_small() {
        let s = generate(&ChessboardParams { n: 10_000_000 }).expect("a 10^7 x 10^7 board generates as instances");
        assert_eq!(s.item_count(), 2 * 10u64.pow(14));
        assert!(s.memory_bytes() < 1 << 20, "{}", s.memory_bytes());
    }

    #[test]
    fn zero_and_absurd_n_are_errors() {
        assert!(generate(&ChessboardParams { n: 0 }).is_err());
        assert!(generate(&ChessboardParams { n: MAX_N + 1 }).is_err());
    }
}
