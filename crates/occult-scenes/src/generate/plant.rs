//! `plant`: a power-plant-like interior, the CAD-assembly case: floors, walls with doors and
//! windows, thousands of densely tessellated pipes, tanks; repeated units instanced.
//!
//! # Layout (the conventions [`crate::path`]'s `street` walk relies on)
//! - A hall of `units × units` square units of side [`UNIT_SIZE`], centred on the origin: with
//!   `H = units·UNIT_SIZE/2` unit `(i, j)` spans `x ∈ [−H + i·U, −H + (i+1)·U]` (and likewise `z`).
//!   Each unit has `floors` storeys of [`FLOOR_HEIGHT`]; floor `f`'s walking surface is at
//!   `y = f·FLOOR_HEIGHT` (a slab of [`SLAB_THICKNESS`] below it), the roof slab on top.
//! - A unit owns the walls on its `−x` and `−z` sides (thickness [`WALL_THICKNESS`], centred on
//!   the unit's edge); walls on the hall's `+x` and `+z` edges close it. Every wall has, on every
//!   storey, a door ([`DOOR_WIDTH`] × [`DOOR_HEIGHT`]) at its middle and two windows 6 m either
//!   side. So the lines through unit centres, at eye height ([`EYE_HEIGHT`]) on floor 0, pass
//!   through doors only: the generator keeps them clear (pipes run overhead above 3.2 m or rise
//!   within 2.4 m of a wall, away from the middle; tanks stand in the unit's quadrants).
//! - The root node is named `"plant"`.
//!
//! # Geometry
//! `variants` unit variants, each a group of: a structure mesh (slabs), two instances of the
//! shared wall mesh, one pipe mesh per storey and one tank mesh. A storey holds `pipes` pipe
//! runs: straight overhead runs across the unit (60 %), L-shaped runs from a wall down to the
//! floor through a tessellated elbow (25 %), and vertical risers (15 %), radius 5–30 cm, tubes of
//! `sides` sides with a ring every 0.5 m (so a 20 m run is ≈ 1,300 triangles), capped. Each
//! quadrant of a storey holds a tank (vertical cylinder with an elliptical head, 32 sides) with
//! probability ½. Units are placed by a seeded hash of their cell; rows are stored once up to
//! 64, then repeat.
//!
//! Sizes: the default (4 × 4 units, 3 storeys, 40 pipes) is ≈ 2.3 M triangle instances
//! (2,278,816) with 1,920 pipe runs; `units=28` ≈ 1.1·10^8. Unique geometry is `variants·floors` pipe meshes
//! (≈ 40 k triangles each by default), built in parallel.

use super::shapes::{grid, quarter_turn_y, MeshBuilder, BYTES_PER_BUILT_TRIANGLE, BYTES_PER_INSTANCE};
use super::{camera_for, check_budget, check_range, mix, scene_error, GenerateError, GeneratorInfo, ParamInfo};
use occult_core::{Affine3A, Camera, CoreError, Instance, Mesh, Rgba8, Scene, SceneBuilder, Vec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// Side of a unit, metres.
pub const UNIT_SIZE: f32 = 20.0;
/// Storey height (slab top to slab top), metres.
pub const FLOOR_HEIGHT: f32 = 6.0;
/// Thickness of floor slabs, metres.
pub const SLAB_THICKNESS: f32 = 0.3;
/// Thickness of walls, metres.
pub const WALL_THICKNESS: f32 = 0.3;
/// Width of a door opening, metres.
pub const DOOR_WIDTH: f32 = 2.0;
/// Height of a door opening, metres.
pub const DOOR_HEIGHT: f32 = 2.6;
/// Eye height of a walker, metres.
pub const EYE_HEIGHT: f32 = 1.7;
/// Name of the root node, by which paths recognise a plant.
pub const ROOT_NAME: &str = "plant";
/// Largest `units` (units per side).
pub const MAX_UNITS: u32 = 10_000;
/// Rows of units stored individually before rows repeat.
const UNIQUE_ROWS: u32 = 64;
/// Ring spacing along pipes and tank walls, metres.
const RING_SPACING: f32 = 0.5;
/// Segments of a pipe elbow (a quarter torus).
const ELBOW_SEGMENTS: u32 = 8;
/// Sides of a tank.
const TANK_SIDES: u32 = 32;

const SLAB_COLOR: Rgba8 = [150, 148, 140, 255];
const WALL_COLOR: Rgba8 = [205, 198, 182, 255];
const TANK_COLOR: Rgba8 = [215, 215, 208, 255];
const PIPE_COLORS: [Rgba8; 6] = [
    [190, 50, 40, 255],
    [230, 190, 40, 255],
    [60, 140, 70, 255],
    [50, 90, 170, 255],
    [170, 175, 180, 255],
    [220, 120, 40, 255],
];

generator_params! {
    /// Parameters of [`generate`].
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct PlantParams {
        /// Units per side of the hall, `1..=10,000` (default 4).
        pub units: u32 = 4,
        /// Storeys, `1..=50` (default 3).
        pub floors: u32 = 3,
        /// Pipe runs per unit storey, `0..=2000` (default 40).
        pub pipes: u32 = 40,
        /// Sides of a pipe's cross-section, `3..=256` (default 16).
        pub sides: u32 = 16,
        /// Unit variants, `1..=64` (default 3).
        pub variants: u32 = 3,
        /// Random seed of pipes, tanks and placement (default 1).
        pub seed: u64 = 1,
    }
}

impl PlantParams {
    /// Half the side of the hall (units only, walls excluded).
    pub fn half_side(&self) -> f32 {
        0.5 * self.units as f32 * UNIT_SIZE
    }

    /// Upper bound of the triangles of one pipe run.
    fn max_pipe_triangles(&self) -> u128 {
        let rings = (2.0 * UNIT_SIZE / RING_SPACING) as u128 + ELBOW_SEGMENTS as u128 + 4;
        2 * self.sides as u128 * rings
    }

    /// Upper bound of the triangles of one tank.
    fn max_tank_triangles() -> u128 {
        2 * TANK_SIDES as u128 * (4.5 / RING_SPACING + 12.0) as u128
    }
}

/// Name, description and parameters, for `occult scenes`.
pub const INFO: GeneratorInfo = GeneratorInfo {
    name: "plant",
    description: "power-plant interior: storeys, walls with doors/windows, thousands of tessellated pipes, tanks; ~2.3M triangles",
    params: &[
        ParamInfo { name: "units", default: "4", meaning: "20 m units per side of the hall (instanced), 1..=10000; 28 gives ~1.1e8" },
        ParamInfo { name: "floors", default: "3", meaning: "storeys of 6 m, 1..=50" },
        ParamInfo { name: "pipes", default: "40", meaning: "pipe runs per unit storey, 0..=2000" },
        ParamInfo { name: "sides", default: "16", meaning: "sides of a pipe's cross-section (tessellation), 3..=256" },
        ParamInfo { name: "variants", default: "3", meaning: "unique unit variants, 1..=64" },
        ParamInfo { name: "seed", default: "1", meaning: "random seed for pipes, tanks and placement" },
    ],
};

const NAME: &str = "plant";

/// Checks parameters without building anything: ranges, then the memory and item-id bounds
/// (the checks [`generate`] makes first).
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range; [`GenerateError::TooLarge`]
/// past [`super::MAX_UNIQUE_BYTES`].
pub fn validate(p: &PlantParams) -> Result<(), GenerateError> {
    check_range(NAME, "units", p.units as u64, 1, MAX_UNITS as u64)?;
    check_range(NAME, "floors", p.floors as u64, 1, 50)?;
    check_range(NAME, "pipes", p.pipes as u64, 0, 2000)?;
    check_range(NAME, "sides", p.sides as u64, 3, 256)?;
    check_range(NAME, "variants", p.variants as u64, 1, 64)?;
    let per_storey = p.pipes as u128 * p.max_pipe_triangles() + 4 * PlantParams::max_tank_triangles();
    let per_unit = p.floors as u128 * (per_storey + 120) + 12 * (p.floors as u128 + 1);
    let rows = p.units.min(UNIQUE_ROWS) as u128;
    let bytes = p.variants as u128 * per_unit * BYTES_PER_BUILT_TRIANGLE as u128
        + (rows * p.units as u128 + 4 * p.units as u128 + 8 * p.variants as u128) * BYTES_PER_INSTANCE as u128;
    let parameter = if p.pipes as u128 * p.max_pipe_triangles() > 4 * PlantParams::max_tank_triangles() {
        "pipes"
    } else {
        "floors"
    };
    check_budget(NAME, parameter, bytes, (p.units as u128).pow(2) * per_unit)?;
    Ok(())
}

/// Builds the plant.
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range; [`GenerateError::TooLarge`]
/// past [`super::MAX_UNIQUE_BYTES`].
pub fn generate(p: &PlantParams) -> Result<Scene, GenerateError> {
    validate(p)?;
    let err = scene_error(NAME);
    let jobs: Vec<(u32, u32)> = (0..p.variants)
        .flat_map(|v| (0..p.floors).map(move |f| (v, f)))
        .collect();
    let pipe_meshes: Vec<_> = jobs.par_iter().map(|&(v, f)| pipe_mesh(p, v, f)).collect();
    let tank_meshes: Vec<_> = (0..p.variants).into_par_iter().map(|v| tank_mesh(p, v)).collect();

    let mut sb = SceneBuilder::new();
    let wall = sb.add_mesh("wall", wall_mesh(p.floors).map_err(&err)?).map_err(&err)?;
    let mut slabs = MeshBuilder::new();
    for f in 0..=p.floors {
        let top = f as f32 * FLOOR_HEIGHT;
        slabs.cuboid(
            Vec3::new(0.0, top - SLAB_THICKNESS, 0.0),
            Vec3::new(UNIT_SIZE, top, UNIT_SIZE),
            SLAB_COLOR,
        );
    }
    let slabs = sb.add_mesh("slabs", slabs.finish().map_err(&err)?).map_err(&err)?;
    let along_x = Affine3A::IDENTITY;
    let along_z = Affine3A::from_mat3(quarter_turn_y(3)); // +x → +z
    let mut pipe_meshes = pipe_meshes.into_iter();
    let mut unit_ids = Vec::with_capacity(p.variants as usize);
    for (v, tanks) in tank_meshes.into_iter().enumerate() {
        let mut parts = vec![
            Instance {
                parent_from_child: Affine3A::IDENTITY,
                child: slabs,
            },
            Instance {
                parent_from_child: along_x,
                child: wall,
            },
            Instance {
                parent_from_child: along_z,
                child: wall,
            },
        ];
        for f in 0..p.floors {
            // `jobs` lists (variant, floor) in this order: one mesh per iteration.
            let Some(mesh) = pipe_meshes.next() else { break };
            let id = sb
                .add_mesh(format!("pipes {v}/{f}"), mesh.map_err(&err)?)
                .map_err(&err)?;
            parts.push(Instance {
                parent_from_child: Affine3A::IDENTITY,
                child: id,
            });
        }
        let tanks = sb.add_mesh(format!("tanks {v}"), tanks.map_err(&err)?).map_err(&err)?;
        parts.push(Instance {
            parent_from_child: Affine3A::IDENTITY,
            child: tanks,
        });
        unit_ids.push(sb.add_group(format!("unit {v}"), parts).map_err(&err)?);
    }

    let h = p.half_side();
    let n = p.units;
    let seed = p.seed;
    let variants = p.variants as u64;
    let row_key = |j: u32| j % UNIQUE_ROWS;
    let units = grid(
        &mut sb,
        "units",
        n,
        n,
        UNIT_SIZE,
        UNIT_SIZE,
        Vec3::new(-h, 0.0, -h),
        row_key,
        |i, j| unit_ids[(mix(seed, i, row_key(j)) % variants) as usize],
    )
    .map_err(&err)?;
    // Closing walls on the +z edge (along x) and the +x edge (along z).
    let wall_z = sb
        .add_group(
            "wall along z",
            vec![Instance {
                parent_from_child: along_z,
                child: wall,
            }],
        )
        .map_err(&err)?;
    let north = grid(
        &mut sb,
        "north wall",
        n,
        1,
        UNIT_SIZE,
        0.0,
        Vec3::new(-h, 0.0, h),
        |_| 0,
        |_, _| wall,
    )
    .map_err(&err)?;
    let east = grid(
        &mut sb,
        "east wall",
        1,
        n,
        0.0,
        UNIT_SIZE,
        Vec3::new(h, 0.0, -h),
        |_| 0,
        |_, _| wall_z,
    )
    .map_err(&err)?;
    let root = sb
        .add_group(
            ROOT_NAME,
            [units, north, east]
                .map(|child| Instance {
                    parent_from_child: Affine3A::IDENTITY,
                    child,
                })
                .to_vec(),
        )
        .map_err(&err)?;
    sb.build(root).map_err(&err)
}

/// The wall along +x from 0 to [`UNIT_SIZE`], centred on `z = 0`, all storeys, with a door at
/// the middle and windows 6 m either side on every storey; built from boxes around the openings.
fn wall_mesh(floors: u32) -> Result<Mesh, CoreError> {
    let mut m = MeshBuilder::new();
    let mid = 0.5 * UNIT_SIZE;
    // Openings along x: (from, to, sill, lintel).
    let openings = [
        (mid - 6.0 - 0.8, mid - 6.0 + 0.8, 1.0, 2.2),
        (mid - 0.5 * DOOR_WIDTH, mid + 0.5 * DOOR_WIDTH, 0.0, DOOR_HEIGHT),
        (mid + 6.0 - 0.8, mid + 6.0 + 0.8, 1.0, 2.2),
    ];
    let (z0, z1) = (-0.5 * WALL_THICKNESS, 0.5 * WALL_THICKNESS);
    for f in 0..floors {
        let (bottom, top) = (f as f32 * FLOOR_HEIGHT, (f + 1) as f32 * FLOOR_HEIGHT - SLAB_THICKNESS);
        let mut x = 0.0;
        for &(a, b, sill, lintel) in &openings {
            m.cuboid(Vec3::new(x, bottom, z0), Vec3::new(a, top, z1), WALL_COLOR);
            m.cuboid(Vec3::new(a, bottom, z0), Vec3::new(b, bottom + sill, z1), WALL_COLOR);
            m.cuboid(Vec3::new(a, bottom + lintel, z0), Vec3::new(b, top, z1), WALL_COLOR);
            x = b;
        }
        m.cuboid(Vec3::new(x, bottom, z0), Vec3::new(UNIT_SIZE, top, z1), WALL_COLOR);
    }
    m.finish()
}

/// Points every [`RING_SPACING`] from `a` to `b`, `a` excluded.
fn line(points: &mut Vec<Vec3>, a: Vec3, b: Vec3) {
    let steps = ((a.distance(b) / RING_SPACING).ceil() as u32).max(1);
    points.extend((1..=steps).map(|k| a.lerp(b, k as f32 / steps as f32)));
}

/// A coordinate within 2.4 m of one of the unit's walls (clear of the walkway and tanks).
fn near_wall(rng: &mut Pcg64Mcg) -> f32 {
    let d = rng.random_range(0.8..2.4f32);
    if rng.random_bool(0.5) {
        d
    } else {
        UNIT_SIZE - d
    }
}

/// A coordinate at least 2.5 m from the unit's middle line and 3 m from its walls.
fn off_centre(rng: &mut Pcg64Mcg) -> f32 {
    let d = rng.random_range(3.0..0.5 * UNIT_SIZE - 2.5);
    if rng.random_bool(0.5) {
        d
    } else {
        UNIT_SIZE - d
    }
}

/// The pipes of storey `floor` of unit variant `variant`, in unit coordinates.
fn pipe_mesh(p: &PlantParams, variant: u32, floor: u32) -> Result<Mesh, CoreError> {
    let mut rng = Pcg64Mcg::seed_from_u64(mix(p.seed, variant, floor));
    let mut m = MeshBuilder::new();
    let base = floor as f32 * FLOOR_HEIGHT;
    let wall = 0.5 * WALL_THICKNESS;
    for _ in 0..p.pipes {
        let radius = [0.05, 0.08, 0.1, 0.1, 0.15, 0.2, 0.3][rng.random_range(0..7)];
        let color = PIPE_COLORS[rng.random_range(0..PIPE_COLORS.len())];
        let overhead = base + rng.random_range(3.2 + radius..FLOOR_HEIGHT - SLAB_THICKNESS - 0.4 - radius);
        let kind = rng.random_range(0..20);
        // Build along x in (u, y, w) coordinates, then swap to run along z half of the time.
        let mut pts = Vec::new();
        if kind < 12 {
            let w = rng.random_range(0.8..UNIT_SIZE - 0.8);
            let start = Vec3::new(wall, overhead, w);
            pts.push(start);
            line(&mut pts, start, Vec3::new(UNIT_SIZE - wall, overhead, w));
        } else if kind < 17 {
            let (w, corner) = (near_wall(&mut rng), off_centre(&mut rng));
            let bend = (2.0 * radius).max(0.3);
            let start = Vec3::new(wall, overhead, w);
            pts.push(start);
            line(&mut pts, start, Vec3::new(corner - bend, overhead, w));
            let centre = Vec3::new(corner - bend, overhead - bend, w);
            for k in 1..=ELBOW_SEGMENTS {
                let theta = std::f32::consts::FRAC_PI_2 * (1.0 - k as f32 / ELBOW_SEGMENTS as f32);
                pts.push(centre + bend * Vec3::new(theta.cos(), theta.sin(), 0.0));
            }
            let last = *pts.last().unwrap_or(&centre);
            line(&mut pts, last, Vec3::new(corner, base, w));
        } else {
            let (u, w) = (off_centre(&mut rng), near_wall(&mut rng));
            let start = Vec3::new(u, base, w);
            pts.push(start);
            line(&mut pts, start, Vec3::new(u, base + FLOOR_HEIGHT - SLAB_THICKNESS, w));
        }
        if rng.random_bool(0.5) {
            for q in &mut pts {
                *q = Vec3::new(q.z, q.y, q.x);
            }
        }
        let radii = vec![radius; pts.len()];
        m.tube(&pts, &radii, p.sides, true, color);
    }
    m.finish()
}

/// The tanks of all storeys of unit variant `variant`: in each quadrant, with probability ½, a
/// vertical cylinder with an elliptical head.
fn tank_mesh(p: &PlantParams, variant: u32) -> Result<Mesh, CoreError> {
    let mut rng = Pcg64Mcg::seed_from_u64(mix(p.seed ^ 0x7A4C, variant, 0));
    let mut m = MeshBuilder::new();
    for f in 0..p.floors {
        for (qx, qz) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
            if !rng.random_bool(0.5) {
                continue;
            }
            let r = rng.random_range(1.2..2.2f32);
            let height = rng.random_range(2.5..4.5f32);
            let mut profile = vec![(0.0, 0.0)];
            let bands = (height / RING_SPACING).ceil() as u32;
            profile.extend((0..=bands).map(|k| (r, height * k as f32 / bands as f32)));
            profile.extend((1..8).map(|k| {
                let phi = std::f32::consts::FRAC_PI_2 * k as f32 / 8.0;
                (r * phi.cos(), height + 0.5 * r * phi.sin())
            }));
            profile.push((0.0, height + 0.5 * r));
            let base = Vec3::new(qx * UNIT_SIZE, f as f32 * FLOOR_HEIGHT, qz * UNIT_SIZE);
            m.lathe(base, &profile, TANK_SIDES, TANK_COLOR);
        }
    }
    m.finish()
}

/// On floor 0 just inside the corner unit at `−x −z`, on its centre line (the walkway), at eye
/// height, looking along the line of doors and slightly right, past the unit's tanks and risers.
pub fn default_camera(p: &PlantParams, scene: &Scene) -> Camera {
    let h = 0.5 * p.units.clamp(1, MAX_UNITS) as f32 * UNIT_SIZE;
    let centre = -h + 0.5 * UNIT_SIZE;
    let eye = Vec3::new(centre, EYE_HEIGHT, -h + 0.6);
    let target = Vec3::new(centre + 4.0, EYE_HEIGHT - 0.2, -h + 12.0);
    camera_for(scene, eye, target, 0.1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::{intersect_ray_triangle, Ray};

    #[test]
    fn walkway_through_unit_centres_is_clear() {
        // Rays along the unit centre lines on floor 0, at eye height and just above the floor,
        // hit nothing: doors are open, pipes overhead or by the walls, tanks in the quadrants.
        let p = PlantParams {
            units: 2,
            floors: 2,
            pipes: 60,
            sides: 6,
            variants: 2,
            seed: 9,
        };
        let s = generate(&p).expect("small plant params generate");
        let flat = s.flatten(1 << 24).expect("a small plant is under 2^24 triangles");
        let h = p.half_side();
        for k in 0..2 {
            let c = -h + (k as f32 + 0.5) * UNIT_SIZE;
            for ray in [
                Ray::new(Vec3::new(-h - 1.0, EYE_HEIGHT, c), Vec3::X),
                Ray::new(Vec3::new(c, EYE_HEIGHT, -h - 1.0), Vec3::Z),
                Ray::new(Vec3::new(-h - 1.0, 0.3, c), Vec3::X),
            ] {
                let ray = Ray {
                    t_max: 2.0 * h + 2.0,
                    ..ray
                };
                for t in 0..flat.triangle_count() {
                    let [a, b, cc] = flat.triangle_positions(t);
                    assert!(
                        intersect_ray_triangle(&ray, a, b, cc).is_none(),
                        "{ray:?} hits triangle {t}"
                    );
                }
            }
        }
    }

    #[test]
    fn default_plant_has_thousands_of_pipes() {
        let p = PlantParams::default();
        assert!(p.units * p.units * p.floors * p.pipes >= 1000);
    }

    #[test]
    fn bad_parameters_are_errors() {
        for p in [
            PlantParams {
                units: 0,
                ..Default::default()
            },
            PlantParams {
                floors: 0,
                ..Default::default()
            },
            PlantParams {
                sides: 2,
                ..Default::default()
            },
            PlantParams {
                variants: 0,
                ..Default::default()
            },
            PlantParams {
                units: MAX_UNITS + 1,
                ..Default::default()
            },
        ] {
            assert!(matches!(generate(&p), Err(GenerateError::BadParameter { .. })), "{p:?}");
        }
        let huge = PlantParams {
            pipes: 2000,
            sides: 256,
            floors: 50,
            variants: 64,
            ..Default::default()
        };
        assert!(matches!(generate(&huge), Err(GenerateError::TooLarge { .. })));
    }
}
