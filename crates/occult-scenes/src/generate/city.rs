//! `city`: a densely occluded city of streets and blocks of windowed buildings.
//!
//! # Layout (the conventions [`crate::path`]'s `street` walk relies on)
//! - The city is `blocks × blocks` square blocks on a grid of pitch [`BLOCK_PITCH`]
//!   (= [`BLOCK_SIZE`] + [`STREET_WIDTH`]) centred on the origin: with `H = blocks·BLOCK_PITCH/2`,
//!   the ground (one quad at `y = 0`, asphalt) spans exactly `[−H, H]²` in `(x, z)`, and street
//!   centre lines run along both axes at `−H + k·BLOCK_PITCH`, `k = 0..=blocks` (the outermost
//!   ones are half streets at the city's edge). Streets are free of geometry up to the sky, so
//!   a walk at [`EYE_HEIGHT`] along a centre line never enters a building.
//! - A block is a curbed slab ([`CURB_HEIGHT`]) with a [`SIDEWALK`] border and four lots of
//!   27 m; each lot holds one building (footprint 16–26 m, rotated by a multiple of 90°).
//! - The scene's root node is named `"city"`; its first two triangles (items 0 and 1) are the
//!   ground.
//!
//! # Geometry
//! A few unique building meshes (`variants`) are instanced everywhere. A building has
//! `floors` storeys of [`FLOOR_HEIGHT`]; 3–14 storeys, or 18–40 for one variant in four
//! (towers). Each facade storey is `detail` window cells, each real geometry: wall strips around
//! a window recessed 0.25 m (four jambs and a glass pane: 18 triangles per cell), and a ledge
//! (10 triangles) at every storey line; a flat roof with a machine room. A building has
//! `4·F·18·D + 40·(F − 1) + 12` triangles (`F` storeys, `D = detail ≥ 1`), about 7,400 on
//! average at `detail = 8`; `detail = 0` gives plain boxes of 20 triangles.
//! 16 block variants (four random buildings each) are placed by a seeded hash; rows of blocks
//! are stored once each up to 64 rows, then repeat, so stored instances grow as `O(blocks)`.
//!
//! Sizes: the default (`blocks = 8`) is ≈ 2.0 M triangle instances (1,966,522); `blocks = 64`
//! ≈ 1.2·10^8.
//! Build cost is the unique buildings (≈ 10^5 triangles, parallel over variants) plus
//! `O(blocks)` instances: milliseconds at any size.

use super::shapes::{grid, quarter_turn_y, MeshBuilder, BYTES_PER_BUILT_TRIANGLE, BYTES_PER_INSTANCE};
use super::{camera_for, check_budget, check_range, mix, scene_error, GenerateError, GeneratorInfo, ParamInfo};
use occult_core::{Affine3A, Camera, Instance, Mesh, Rgba8, Scene, SceneBuilder, Vec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// Side of a block (slab and sidewalk included), metres.
pub const BLOCK_SIZE: f32 = 60.0;
/// Width of a street between two blocks, metres.
pub const STREET_WIDTH: f32 = 16.0;
/// Distance between the centre lines of neighbouring streets (and between block corners).
pub const BLOCK_PITCH: f32 = BLOCK_SIZE + STREET_WIDTH;
/// Sidewalk border of a block, metres.
pub const SIDEWALK: f32 = 3.0;
/// Height of a block's slab above the street, metres.
pub const CURB_HEIGHT: f32 = 0.15;
/// Storey height, metres.
pub const FLOOR_HEIGHT: f32 = 3.2;
/// Eye height of a pedestrian above the street, metres.
pub const EYE_HEIGHT: f32 = 1.7;
/// Name of the root node, by which paths recognise a city.
pub const ROOT_NAME: &str = "city";
/// Largest `blocks` (a 760 km city; beyond, `f32` positions lose centimetres).
pub const MAX_BLOCKS: u32 = 10_000;
/// Largest `detail` (window cells per facade storey).
pub const MAX_DETAIL: u32 = 64;
/// Largest `variants` (unique building meshes).
pub const MAX_VARIANTS: u32 = 256;
/// Block variants (distinct arrangements of four buildings).
const BLOCK_VARIANTS: u32 = 16;
/// Rows of blocks stored individually before rows repeat.
const UNIQUE_ROWS: u32 = 64;
/// Most storeys a building variant can have.
const MAX_FLOORS: u32 = 40;

const FACADE_COLORS: [Rgba8; 8] = [
    [200, 185, 160, 255],
    [170, 90, 70, 255],
    [150, 155, 160, 255],
    [215, 205, 180, 255],
    [120, 130, 150, 255],
    [190, 150, 110, 255],
    [225, 225, 215, 255],
    [110, 105, 100, 255],
];
const GLASS: Rgba8 = [60, 85, 115, 255];
const ROOF: Rgba8 = [95, 95, 100, 255];
const ASPHALT: Rgba8 = [62, 62, 66, 255];
const PAVEMENT: Rgba8 = [165, 160, 150, 255];

generator_params! {
    /// Parameters of [`generate`].
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct CityParams {
        /// Blocks per side, `1..=10,000` (default 8).
        pub blocks: u32 = 8,
        /// Window cells per facade storey, `0..=64` (default 8; 0 = plain boxes).
        pub detail: u32 = 8,
        /// Unique building meshes, `1..=256` (default 8).
        pub variants: u32 = 8,
        /// Random seed of heights, footprints and placement (default 1).
        pub seed: u64 = 1,
    }
}

impl CityParams {
    /// Half the side of the city: it spans `[−H, H]²`.
    pub fn half_side(&self) -> f32 {
        0.5 * self.blocks as f32 * BLOCK_PITCH
    }
}

/// Name, description and parameters, for `occult scenes`.
pub const INFO: GeneratorInfo = GeneratorInfo {
    name: "city",
    description:
        "densely occluded city: street grid, blocks of instanced buildings with real window geometry, ~2.0M triangles",
    params: &[
        ParamInfo {
            name: "blocks",
            default: "8",
            meaning: "blocks per side (pitch 76 m), 1..=10000; 64 gives ~1.2e8 triangles",
        },
        ParamInfo {
            name: "detail",
            default: "8",
            meaning: "window cells per facade storey (18 triangles each), 0..=64",
        },
        ParamInfo {
            name: "variants",
            default: "8",
            meaning: "unique building meshes instanced over the city, 1..=256",
        },
        ParamInfo {
            name: "seed",
            default: "1",
            meaning: "random seed for heights, footprints and placement",
        },
    ],
};

const NAME: &str = "city";

/// Triangles of one building of `floors` storeys at `detail`.
fn building_triangles(floors: u32, detail: u32) -> u64 {
    if detail == 0 {
        20
    } else {
        4 * floors as u64 * 18 * detail as u64 + 40 * (floors as u64 - 1) + 12
    }
}

/// A building variant: footprint (x, z), storeys, facade color.
#[derive(Clone, Copy, Debug)]
struct Building {
    width: f32,
    depth: f32,
    floors: u32,
    color: Rgba8,
}

fn building_variant(seed: u64, index: u32) -> Building {
    let mut rng = Pcg64Mcg::seed_from_u64(seed ^ (0x9E37_79B9_7F4A_7C15u64.wrapping_mul(index as u64 + 1)));
    let half_metres = |rng: &mut Pcg64Mcg| rng.random_range(32..=52) as f32 * 0.5;
    let width = half_metres(&mut rng);
    let depth = half_metres(&mut rng);
    let floors = if index % 4 == 3 {
        rng.random_range(18..=MAX_FLOORS)
    } else {
        rng.random_range(3..=14)
    };
    Building {
        width,
        depth,
        floors,
        color: FACADE_COLORS[index as usize % FACADE_COLORS.len()],
    }
}

/// Checks parameters without building anything: ranges, then the memory and item-id bounds
/// (the checks [`generate`] makes first).
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range; [`GenerateError::TooLarge`]
/// past [`super::MAX_UNIQUE_BYTES`].
pub fn validate(p: &CityParams) -> Result<(), GenerateError> {
    check_range(NAME, "blocks", p.blocks as u64, 1, MAX_BLOCKS as u64)?;
    check_range(NAME, "detail", p.detail as u64, 0, MAX_DETAIL as u64)?;
    check_range(NAME, "variants", p.variants as u64, 1, MAX_VARIANTS as u64)?;
    let max_building = building_triangles(MAX_FLOORS, p.detail) as u128;
    let rows = p.blocks.min(UNIQUE_ROWS) as u128;
    let bytes = p.variants as u128 * max_building * BYTES_PER_BUILT_TRIANGLE as u128
        + (BLOCK_VARIANTS as u128 * 5 + rows * p.blocks as u128 + p.blocks as u128) * BYTES_PER_INSTANCE as u128;
    check_budget(NAME, "blocks", bytes, (p.blocks as u128).pow(2) * 4 * max_building)?;
    Ok(())
}

/// Builds the city.
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range; [`GenerateError::TooLarge`]
/// past [`super::MAX_UNIQUE_BYTES`].
pub fn generate(p: &CityParams) -> Result<Scene, GenerateError> {
    validate(p)?;
    let err = scene_error(NAME);
    let buildings: Vec<Building> = (0..p.variants).map(|v| building_variant(p.seed, v)).collect();
    let meshes: Vec<_> = buildings.par_iter().map(|b| building_mesh(b, p.detail)).collect();
    let mut sb = SceneBuilder::new();
    let mut building_ids = Vec::with_capacity(meshes.len());
    for (v, mesh) in meshes.into_iter().enumerate() {
        building_ids.push(
            sb.add_mesh(format!("building {v}"), mesh.map_err(&err)?)
                .map_err(&err)?,
        );
    }
    let mut slab = MeshBuilder::new();
    slab.cuboid_faces(
        Vec3::ZERO,
        Vec3::new(BLOCK_SIZE, CURB_HEIGHT, BLOCK_SIZE),
        PAVEMENT,
        [true, true, false, true, true, true],
    );
    let slab = sb.add_mesh("block slab", slab.finish().map_err(&err)?).map_err(&err)?;

    // Block variants: the slab and four buildings, one per lot, each rotated by quarter turns.
    let mut rng = Pcg64Mcg::seed_from_u64(p.seed.wrapping_add(0x5EED));
    let lot_centres = [0.25, 0.75].map(|f| SIDEWALK + f * (BLOCK_SIZE - 2.0 * SIDEWALK));
    let mut block_ids = Vec::with_capacity(BLOCK_VARIANTS as usize);
    for k in 0..BLOCK_VARIANTS {
        let mut instances = vec![Instance {
            parent_from_child: Affine3A::IDENTITY,
            child: slab,
        }];
        for &lz in &lot_centres {
            for &lx in &lot_centres {
                let v = rng.random_range(0..p.variants) as usize;
                let turn = rng.random_range(0..4u32);
                let parent_from_child =
                    Affine3A::from_mat3_translation(quarter_turn_y(turn), Vec3::new(lx, CURB_HEIGHT, lz));
                instances.push(Instance {
                    parent_from_child,
                    child: building_ids[v],
                });
            }
        }
        block_ids.push(sb.add_group(format!("block {k}"), instances).map_err(&err)?);
    }

    let h = p.half_side();
    let first = Vec3::new(-h + 0.5 * STREET_WIDTH, 0.0, -h + 0.5 * STREET_WIDTH);
    let row_key = |j: u32| j % UNIQUE_ROWS;
    let seed = p.seed;
    let blocks = grid(
        &mut sb,
        "blocks",
        p.blocks,
        p.blocks,
        BLOCK_PITCH,
        BLOCK_PITCH,
        first,
        row_key,
        |i, j| block_ids[(mix(seed, i, row_key(j)) % BLOCK_VARIANTS as u64) as usize],
    )
    .map_err(&err)?;
    let mut ground = MeshBuilder::new();
    ground.rect(
        Vec3::new(-h, 0.0, h),
        Vec3::X * (2.0 * h),
        Vec3::Z * (-2.0 * h),
        ASPHALT,
    );
    let ground = sb.add_mesh("ground", ground.finish().map_err(&err)?).map_err(&err)?;
    let root = sb
        .add_group(
            ROOT_NAME,
            vec![
                Instance {
                    parent_from_child: Affine3A::IDENTITY,
                    child: ground,
                },
                Instance {
                    parent_from_child: Affine3A::IDENTITY,
                    child: blocks,
                },
            ],
        )
        .map_err(&err)?;
    sb.build(root).map_err(&err)
}

/// One building, footprint centred on the origin, standing on `y = 0`.
fn building_mesh(b: &Building, detail: u32) -> Result<Mesh, occult_core::CoreError> {
    let mut m = MeshBuilder::new();
    let (hw, hd) = (0.5 * b.width, 0.5 * b.depth);
    let top = b.floors as f32 * FLOOR_HEIGHT;
    let ledge_color = shade(b.color, 0.8);
    // (outward normal, bottom-left corner seen from outside, facade width).
    let facades = [
        (Vec3::Z, Vec3::new(-hw, 0.0, hd), b.width),
        (Vec3::NEG_Z, Vec3::new(hw, 0.0, -hd), b.width),
        (Vec3::X, Vec3::new(hw, 0.0, hd), b.depth),
        (Vec3::NEG_X, Vec3::new(-hw, 0.0, -hd), b.depth),
    ];
    for &(n, corner, width) in &facades {
        let u = Vec3::Y.cross(n); // right, seen from outside: u × y = n
        if detail == 0 {
            m.rect(corner, u * width, Vec3::Y * top, b.color);
            continue;
        }
        let cell = width / detail as f32;
        let (margin, sill, lintel, inset) = (0.2 * cell, 0.9, 2.4, 0.25);
        let window = cell - 2.0 * margin;
        let opening = lintel - sill;
        for f in 0..b.floors {
            let storey = corner + Vec3::Y * (f as f32 * FLOOR_HEIGHT);
            for c in 0..detail {
                let o = storey + u * (c as f32 * cell);
                let y = Vec3::Y;
                m.rect(o, u * cell, y * sill, b.color);
                m.rect(o + y * lintel, u * cell, y * (FLOOR_HEIGHT - lintel), b.color);
                m.rect(o + y * sill, u * margin, y * opening, b.color);
                m.rect(o + u * (cell - margin) + y * sill, u * margin, y * opening, b.color);
                // The recess: glass at the back, then the jambs, sill and lintel facing into it.
                let w0 = o + u * margin + y * sill;
                m.rect(w0 - n * inset, u * window, y * opening, GLASS);
                m.rect(w0, -n * inset, y * opening, b.color);
                m.rect(w0 + u * window - n * inset, n * inset, y * opening, b.color);
                m.rect(w0, u * window, -n * inset, b.color);
                m.rect(w0 + y * opening - n * inset, u * window, n * inset, b.color);
            }
            if f > 0 {
                // A ledge along the storey line, its face against the wall omitted.
                let a = storey - Vec3::Y * 0.12;
                let bmax = storey + u * width + n * 0.35 + Vec3::Y * 0.12;
                let (lo, hi) = (a.min(bmax), a.max(bmax));
                let mut faces = [true; 6];
                faces[face_index(-n)] = false;
                m.cuboid_faces(lo, hi, ledge_color, faces);
            }
        }
    }
    m.rect(Vec3::new(-hw, top, hd), Vec3::X * b.width, Vec3::Z * -b.depth, ROOF);
    let room = Vec3::new(b.width / 6.0, 3.0, b.depth / 6.0);
    let mut faces = [true; 6];
    faces[2] = false;
    m.cuboid_faces(
        Vec3::new(-room.x, top, -room.z),
        Vec3::new(room.x, top + room.y, room.z),
        ROOF,
        faces,
    );
    debug_assert_eq!(m.triangle_count() as u64, building_triangles(b.floors, detail));
    m.finish()
}

/// Index of the cuboid face (−x, +x, −y, +y, −z, +z) with outward normal `n` (axis-aligned).
fn face_index(n: Vec3) -> usize {
    let axis = n.abs().max_position();
    2 * axis + usize::from(n[axis] > 0.0)
}

fn shade(c: Rgba8, f: f32) -> Rgba8 {
    [
        (c[0] as f32 * f) as u8,
        (c[1] as f32 * f) as u8,
        (c[2] as f32 * f) as u8,
        c[3],
    ]
}

/// Above the street line nearest the centre, at the city's `−z` edge, 20 m up, looking down the
/// street canyon towards the centre: most buildings are hidden behind the first rows.
pub fn default_camera(p: &CityParams, scene: &Scene) -> Camera {
    let blocks = p.blocks.clamp(1, MAX_BLOCKS);
    let h = 0.5 * blocks as f32 * BLOCK_PITCH;
    let x = -h + (blocks / 2) as f32 * BLOCK_PITCH;
    let ahead = (-h + 3.0 * BLOCK_PITCH).min(h);
    camera_for(scene, Vec3::new(x, 20.0, -h - 10.0), Vec3::new(x, 2.0, ahead), 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn building_counts_match_formula() {
        for detail in [0, 1, 3, 8] {
            for v in 0..8 {
                let b = building_variant(7, v);
                let m = building_mesh(&b, detail).expect("every building variant builds at every detail");
                assert_eq!(m.triangle_count() as u64, building_triangles(b.floors, detail));
            }
        }
    }

    #[test]
    fn buildings_fit_their_lots() {
        for v in 0..64 {
            let b = building_variant(3, v);
            let m = building_mesh(&b, 2).expect("every building variant builds");
            let half_lot = 0.25 * (BLOCK_SIZE - 2.0 * SIDEWALK);
            // Ledges protrude 0.35 m: the footprint stays inside the lot.
            assert!(
                m.bounds().max.x < half_lot && m.bounds().max.z < half_lot,
                "{:?}",
                m.bounds()
            );
        }
    }

    #[test]
    fn streets_are_free_of_geometry() {
        let p = CityParams {
            blocks: 3,
            detail: 1,
            ..CityParams::default()
        };
        let s = generate(&p).expect("a 3x3 city generates");
        let h = p.half_side();
        assert_eq!(s.bounds().min.x, -h);
        assert_eq!(s.bounds().max.z, h);
        // Every block child's box stays off the street centre lines (plus half a street).
        let flat = s.flatten(1 << 24).expect("a 3x3 city is under 2^24 triangles");
        for t in 2..flat.triangle_count() {
            for c in flat.triangle_positions(t) {
                let along = |v: f32| ((v + h) / BLOCK_PITCH - ((v + h) / BLOCK_PITCH).round()).abs() * BLOCK_PITCH;
                assert!(along(c.x) >= 0.5 * STREET_WIDTH - 1e-3 || along(c.z) >= 0.5 * STREET_WIDTH - 1e-3);
                assert!(
                    along(c.x) >= 0.5 * STREET_WIDTH - 1e-3 && along(c.z) >= 0.5 * STREET_WIDTH - 1e-3,
                    "{c:?} on a street"
                );
            }
        }
    }

    #[test]
    fn face_indices() {
        assert_eq!(face_index(Vec3::NEG_X), 0);
        assert_eq!(face_index(Vec3::X), 1);
        assert_eq!(face_index(Vec3::NEG_Z), 4);
        assert_eq!(face_index(Vec3::Z), 5);
    }
}
