//! `terrain`: the anchor benchmark scene, a regular heightfield.
//!
//! Exactly: a `g × g`-quad grid over `[−100, 100]²` in `(x, z)` with `(g + 1)²` vertices
//! `x = −100 + 200·i/g`, `z = −100 + 200·j/g` and height
//!
//! `y = h(x, z) = 6·sin(0.07x)·cos(0.05z) + 2·sin(0.31x + 0.17z) + 0.7·cos(1.3x − 0.9z)`
//!
//! (evaluated in `f64`, stored as `f32`), two triangles per quad, `2·g²` triangles: `g = 724`
//! (the default) gives 1,048,352. Triangles run row by row (`j` outer, `i` inner; quad `(i, j)`
//! owns triangles `2·(j·g + i)` and `+1`), so item ids follow the grid with good locality. Both
//! triangles face +y. Colors are per triangle, by height (green valleys, brown slopes, pale tops).
//!
//! `tiles > 1` places `tiles × tiles` instances of the heightfield side by side (pitch 200,
//! centred on the origin; tile rows nested so that `2·tiles` instances are stored) to reach
//! 10^8+ triangle instances: `2·g²·tiles²`. The field is not periodic, so neighbouring tiles
//! meet with small steps at their shared edges. With `tiles = 1` the scene's root is the mesh
//! itself and item `k` is triangle `k`.
//!
//! The default view ([`default_camera`]) is fixed: eye `(0, 25, −110)` looking at the origin,
//! up +y, vertical fov 60°, near 0.1, far 1000, at [`ANCHOR_RESOLUTION`].
//!
//! Cost: `O(g²)` time, parallel over rows; 10^7 triangles (`g = 2237`) build in well under a
//! second on 2 cores. Memory ≈ 12·(g+1)² + 16·2g² bytes.

use super::shapes::{grid, BYTES_PER_INSTANCE};
use super::{check_budget, check_range, scene_error, GenerateError, GeneratorInfo, ParamInfo};
use occult_core::{Camera, Mesh, MeshColors, Rgba8, Scene, SceneBuilder, Vec3};
use rayon::prelude::*;

/// Side of the heightfield in world units (it spans `[−SIDE/2, SIDE/2]²`).
pub const SIDE: f32 = 200.0;
/// Resolution of the anchor benchmark's default view, width × height in pixels.
pub const ANCHOR_RESOLUTION: (u32, u32) = (1920, 1080);
/// Largest `g`: `(g + 1)²` vertices must fit 32-bit indices (the memory bound refuses far less).
pub const MAX_G: u32 = 65_534;
/// Largest `tiles` (tiles per side): a 2000 km field; beyond, `f32` positions lose centimetres.
pub const MAX_TILES: u32 = 10_000;

generator_params! {
    /// Parameters of [`generate`].
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct TerrainParams {
        /// Quads per side of the heightfield, `1..=65534` (default 724: 1,048,352 triangles).
        pub g: u32 = 724,
        /// Copies of the heightfield per side, `1..=10,000` (default 1).
        pub tiles: u32 = 1,
    }
}

impl TerrainParams {
    /// Triangle instances the scene will hold: `2·g²·tiles²`.
    pub fn item_count(&self) -> u128 {
        2 * (self.g as u128).pow(2) * (self.tiles as u128).pow(2)
    }
}

/// Name, description and parameters, for `occult scenes`.
pub const INFO: GeneratorInfo = GeneratorInfo {
    name: "terrain",
    description:
        "anchor benchmark heightfield over [-100,100]^2, 2*g^2 triangles (1,048,352 at g=724), tiled tiles x tiles",
    params: &[
        ParamInfo {
            name: "g",
            default: "724",
            meaning: "quads per side of the heightfield, 1..=65534",
        },
        ParamInfo {
            name: "tiles",
            default: "1",
            meaning: "heightfield copies per side (instanced, pitch 200), 1..=10000; 10 gives ~1e8",
        },
    ],
};

const NAME: &str = "terrain";

/// The anchor height function `h(x, z)`.
pub fn height(x: f64, z: f64) -> f64 {
    6.0 * (0.07 * x).sin() * (0.05 * z).cos() + 2.0 * (0.31 * x + 0.17 * z).sin() + 0.7 * (1.3 * x - 0.9 * z).cos()
}

/// Checks parameters without building anything: ranges, then the memory and item-id bounds
/// (the checks [`generate`] makes first).
///
/// # Errors
/// [`GenerateError::BadParameter`] for `g` or `tiles` out of range; [`GenerateError::TooLarge`]
/// when the heightfield exceeds [`super::MAX_UNIQUE_BYTES`].
pub fn validate(p: &TerrainParams) -> Result<(), GenerateError> {
    check_range(NAME, "g", p.g as u64, 1, MAX_G as u64)?;
    check_range(NAME, "tiles", p.tiles as u64, 1, MAX_TILES as u64)?;
    let g = p.g as u128;
    let bytes = (g + 1).pow(2) * 12 + 2 * g * g * 16 + 2 * p.tiles as u128 * BYTES_PER_INSTANCE as u128;
    check_budget(NAME, "g", bytes, p.item_count())?;
    Ok(())
}

/// Builds the terrain.
///
/// # Errors
/// [`GenerateError::BadParameter`] for `g` or `tiles` out of range; [`GenerateError::TooLarge`]
/// when the heightfield exceeds [`super::MAX_UNIQUE_BYTES`].
pub fn generate(p: &TerrainParams) -> Result<Scene, GenerateError> {
    validate(p)?;
    let mesh = heightfield(p.g).map_err(scene_error(NAME))?;
    let mut builder = SceneBuilder::new();
    let field = builder.add_mesh("terrain", mesh).map_err(scene_error(NAME))?;
    let root = if p.tiles == 1 {
        field
    } else {
        let first = -0.5 * SIDE * (p.tiles - 1) as f32;
        grid(
            &mut builder,
            "terrain",
            p.tiles,
            p.tiles,
            SIDE,
            SIDE,
            Vec3::new(first, 0.0, first),
            |_| 0,
            |_, _| field,
        )
        .map_err(scene_error(NAME))?
    };
    builder.build(root).map_err(scene_error(NAME))
}

/// The heightfield mesh of `g × g` quads (see the module doc for layout and order).
fn heightfield(g: u32) -> Result<Mesh, occult_core::CoreError> {
    let n = g as usize + 1;
    let step = SIDE as f64 / g as f64;
    let coord = |k: usize| -(SIDE as f64) * 0.5 + step * k as f64;
    let mut positions = vec![Vec3::ZERO; n * n];
    positions.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
        let z = coord(j);
        for (i, p) in row.iter_mut().enumerate() {
            let x = coord(i);
            *p = Vec3::new(x as f32, height(x, z) as f32, z as f32);
        }
    });
    let g = g as usize;
    let mut triangles = vec![[0u32; 3]; 2 * g * g];
    triangles.par_chunks_mut(2 * g).enumerate().for_each(|(j, row)| {
        for i in 0..g {
            // Corners of quad (i, j); indices fit u32 because (g + 1)² ≤ (MAX_G + 1)² < 2^32.
            let v00 = (j * n + i) as u32;
            let v10 = v00 + 1;
            let v01 = v00 + n as u32;
            let v11 = v01 + 1;
            // Counter-clockwise seen from +y: (v00, v01, v10) has normal (+z) × (+x) = +y.
            row[2 * i] = [v00, v01, v10];
            row[2 * i + 1] = [v10, v01, v11];
        }
    });
    let colors: Vec<Rgba8> = triangles
        .par_iter()
        .map(|t| {
            height_color((positions[t[0] as usize].y + positions[t[1] as usize].y + positions[t[2] as usize].y) / 3.0)
        })
        .collect();
    Mesh::new(positions, triangles)?.with_colors(MeshColors::PerTriangle(colors))
}

/// Color by height: green valleys, brown slopes, pale tops (heights span about ±8.7).
fn height_color(y: f32) -> Rgba8 {
    let t = ((y + 8.7) / 17.4).clamp(0.0, 1.0);
    let stops: [(f32, [f32; 3]); 4] = [
        (0.0, [48.0, 110.0, 52.0]),
        (0.45, [96.0, 150.0, 70.0]),
        (0.75, [140.0, 115.0, 80.0]),
        (1.0, [235.0, 235.0, 230.0]),
    ];
    let k = stops.iter().position(|s| s.0 >= t).unwrap_or(3).max(1);
    let (t0, c0) = stops[k - 1];
    let (t1, c1) = stops[k];
    let f = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
    let c = |a: usize| (c0[a] + (c1[a] - c0[a]) * f).round() as u8;
    [c(0), c(1), c(2), 255]
}

/// The anchor view: eye `(0, 25, −110)` looking at the origin, up +y, vertical fov 60°,
/// near 0.1, far 1000 (the same whatever `tiles`; render it at [`ANCHOR_RESOLUTION`]).
pub fn default_camera(_p: &TerrainParams, _scene: &Scene) -> Camera {
    Camera {
        eye: Vec3::new(0.0, 25.0, -110.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 60.0,
        near: 0.1,
        far: 1000.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_grid_layout_and_winding() {
        let s = generate(&TerrainParams { g: 2, tiles: 1 }).expect("a 2x2 terrain generates");
        assert_eq!(s.item_count(), 8);
        let m = s
            .node(s.root())
            .mesh()
            .expect("the root of a one-tile terrain is its mesh");
        assert_eq!(m.positions().len(), 9);
        assert_eq!(m.positions()[0].x, -100.0);
        assert_eq!(m.positions()[8].z, 100.0);
        for k in 0..8 {
            let [a, b, c] = m.triangle_positions(k);
            assert!((b - a).cross(c - a).y > 0.0, "triangle {k} faces down");
        }
    }

    #[test]
    fn height_matches_formula_at_a_point() {
        let h = height(10.0, -20.0);
        let want = 6.0 * 0.7f64.sin() * (-1.0f64).cos() + 2.0 * (3.1f64 - 3.4).sin() + 0.7 * (13.0f64 + 18.0).cos();
        assert!((h - want).abs() < 1e-12);
    }

    #[test]
    fn zero_and_absurd_parameters_are_errors() {
        assert!(matches!(
            generate(&TerrainParams { g: 0, tiles: 1 }),
            Err(GenerateError::BadParameter { .. })
        ));
        assert!(matches!(
            generate(&TerrainParams { g: 1, tiles: 0 }),
            Err(GenerateError::BadParameter { .. })
        ));
        assert!(matches!(
            generate(&TerrainParams { g: 60_000, tiles: 1 }),
            Err(GenerateError::TooLarge { .. })
        ));
        assert!(matches!(
            generate(&TerrainParams {
                g: 65_534,
                tiles: 10_000
            }),
            Err(GenerateError::TooLarge { .. })
        ));
    }
}
