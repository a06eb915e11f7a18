//! `occluder`: one large wall in front of many finely tessellated objects, the scene where
//! occlusion culling pays the most.
//!
//! # References
//! - Georges et al. 1995, §5.2: "a simple model that had a plain box and a series of complex
//!   objects consisting of several thousand polygons … when the viewer moved so that the box
//!   obscured his view of the other objects, most of the geometry was culled".
//!
//! Layout (world units, +y up): a wall box spanning `x ∈ [−W/2, W/2]`, `y ∈ [0, WALL_HEIGHT]`,
//! `z ∈ [0, WALL_THICKNESS]` with `W = SPHERE_PITCH·objects + 4`; behind it (`z > 0`) an
//! `objects × objects` grid of UV spheres of radius 1 resting on `y = 0`, pitch
//! [`SPHERE_PITCH`], in four colors. A sphere of `tessellation = t` stacks and `2t` slices has
//! `4·t·(t − 1)` triangles (16,128 at the default 64). Triangle instances:
//! `12 + objects²·4·t·(t − 1)` (1,612,812 by default; `objects = 100` gives 1.6·10^8).
//! The wall's 12 triangles are items `0..12`.
//!
//! Any eye in front of the wall (`z < 0`) below its top sees no sphere: the wall is as high as
//! three sphere diameters and wider than the grid. The default camera stands there.

use super::shapes::{grid, MeshBuilder, BYTES_PER_BUILT_TRIANGLE, BYTES_PER_INSTANCE};
use super::{camera_for, check_budget, check_range, scene_error, GenerateError, GeneratorInfo, ParamInfo};
use occult_core::{Affine3A, Camera, Instance, Scene, SceneBuilder, Vec3};
use rayon::prelude::*;

/// Distance between sphere centres.
pub const SPHERE_PITCH: f32 = 3.0;
/// Height of the wall (three sphere diameters).
pub const WALL_HEIGHT: f32 = 6.0;
/// Thickness of the wall.
pub const WALL_THICKNESS: f32 = 0.5;
/// Largest `objects` (spheres per side).
pub const MAX_OBJECTS: u32 = 100_000;
/// Largest `tessellation` (stacks per sphere).
pub const MAX_TESSELLATION: u32 = 4096;

const SPHERE_COLORS: [[u8; 4]; 4] = [
    [200, 60, 50, 255],
    [230, 160, 40, 255],
    [40, 150, 150, 255],
    [120, 80, 170, 255],
];
const WALL_COLOR: [u8; 4] = [170, 170, 165, 255];

generator_params! {
    /// Parameters of [`generate`].
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct OccluderParams {
        /// Spheres per side of the grid behind the wall, `1..=100,000` (default 10).
        pub objects: u32 = 10,
        /// Latitude bands per sphere (with twice as many meridians), `2..=4096` (default 64:
        /// 16,128 triangles per sphere).
        pub tessellation: u32 = 64,
    }
}

impl OccluderParams {
    /// Triangles of one sphere: `4·t·(t − 1)`.
    pub fn sphere_triangle_count(&self) -> u128 {
        let t = self.tessellation as u128;
        4 * t * t.saturating_sub(1)
    }

    /// Triangle instances: `12 + objects²·4·t·(t − 1)`.
    pub fn item_count(&self) -> u128 {
        12 + (self.objects as u128).pow(2) * self.sphere_triangle_count()
    }
}

/// Name, description and parameters, for `occult scenes`.
pub const INFO: GeneratorInfo = GeneratorInfo {
    name: "occluder",
    description:
        "a large wall hiding a grid of finely tessellated spheres (Georges et al. 5.2), 1,612,812 triangles by default",
    params: &[
        ParamInfo {
            name: "objects",
            default: "10",
            meaning: "spheres per side of the grid behind the wall, 1..=100000",
        },
        ParamInfo {
            name: "tessellation",
            default: "64",
            meaning: "latitude bands per sphere (2x as many meridians; 4t(t-1) triangles), 2..=4096",
        },
    ],
};

const NAME: &str = "occluder";

/// Checks parameters without building anything: ranges, then the memory and item-id bounds
/// (the checks [`generate`] makes first).
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range; [`GenerateError::TooLarge`]
/// when the four sphere meshes exceed [`super::MAX_UNIQUE_BYTES`].
pub fn validate(p: &OccluderParams) -> Result<(), GenerateError> {
    check_range(NAME, "objects", p.objects as u64, 1, MAX_OBJECTS as u64)?;
    check_range(NAME, "tessellation", p.tessellation as u64, 2, MAX_TESSELLATION as u64)?;
    let bytes = 4 * p.sphere_triangle_count() * BYTES_PER_BUILT_TRIANGLE as u128
        + 5 * p.objects as u128 * BYTES_PER_INSTANCE as u128;
    check_budget(NAME, "tessellation", bytes, p.item_count())?;
    Ok(())
}

/// Builds the wall and the spheres.
///
/// # Errors
/// [`GenerateError::BadParameter`] for a parameter out of range; [`GenerateError::TooLarge`]
/// when the four sphere meshes exceed [`super::MAX_UNIQUE_BYTES`].
pub fn generate(p: &OccluderParams) -> Result<Scene, GenerateError> {
    validate(p)?;
    let k = p.objects;
    let width = wall_width(k);
    let mut wall = MeshBuilder::new();
    wall.cuboid(
        Vec3::new(-0.5 * width, 0.0, 0.0),
        Vec3::new(0.5 * width, WALL_HEIGHT, WALL_THICKNESS),
        WALL_COLOR,
    );
    let spheres: Vec<_> = SPHERE_COLORS
        .par_iter()
        .map(|&color| {
            let mut m = MeshBuilder::new();
            m.uv_sphere(Vec3::ZERO, 1.0, p.tessellation, 2 * p.tessellation, color);
            m.finish()
        })
        .collect();

    let err = scene_error(NAME);
    let mut b = SceneBuilder::new();
    let wall = b.add_mesh("wall", wall.finish().map_err(&err)?).map_err(&err)?;
    let mut sphere_ids = Vec::with_capacity(4);
    for (i, mesh) in spheres.into_iter().enumerate() {
        sphere_ids.push(b.add_mesh(format!("sphere {i}"), mesh.map_err(&err)?).map_err(&err)?);
    }
    let first = Vec3::new(-0.5 * SPHERE_PITCH * (k - 1) as f32, 1.0, WALL_THICKNESS + 2.5);
    let spheres = grid(
        &mut b,
        "spheres",
        k,
        k,
        SPHERE_PITCH,
        SPHERE_PITCH,
        first,
        |j| j % 4,
        |i, j| sphere_ids[((i + j) % 4) as usize],
    )
    .map_err(&err)?;
    let id = Affine3A::IDENTITY;
    let root = b
        .add_group(
            "occluder",
            vec![
                Instance {
                    parent_from_child: id,
                    child: wall,
                },
                Instance {
                    parent_from_child: id,
                    child: spheres,
                },
            ],
        )
        .map_err(&err)?;
    b.build(root).map_err(&err)
}

fn wall_width(objects: u32) -> f32 {
    SPHERE_PITCH * objects as f32 + 4.0
}

/// In front of the wall at `y = 2`, far enough back to see all of it: every sphere is hidden.
pub fn default_camera(p: &OccluderParams, scene: &Scene) -> Camera {
    let d = (0.6 * wall_width(p.objects.clamp(1, MAX_OBJECTS))).max(10.0);
    camera_for(scene, Vec3::new(0.0, 2.0, -d), Vec3::new(0.0, 2.0, 0.0), 0.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_match_formula() {
        for (objects, tessellation) in [(1, 2), (3, 5), (10, 64)] {
            let p = OccluderParams { objects, tessellation };
            let s = generate(&p).expect("small occluder params generate");
            assert_eq!(s.item_count() as u128, p.item_count());
        }
        assert_eq!(OccluderParams::default().item_count(), 1_612_812);
    }

    #[test]
    fn wall_hides_the_spheres_from_the_default_camera() {
        let p = OccluderParams {
            objects: 4,
            tessellation: 4,
        };
        let s = generate(&p).expect("small occluder params generate");
        let cam = default_camera(&p, &s);
        cam.validate()
            .expect("the default camera of a generated scene is valid");
        // Every sphere vertex: the segment to the eye crosses the wall's plane inside the wall.
        let flat = s
            .flatten(1 << 20)
            .expect("four spheres and a wall are under 2^20 triangles");
        for v in flat.positions() {
            if v.z <= WALL_THICKNESS {
                continue;
            }
            let t = (0.0 - cam.eye.z) / (v.z - cam.eye.z);
            let hit = cam.eye + (*v - cam.eye) * t;
            assert!(
                hit.y < WALL_HEIGHT && hit.x.abs() < 0.5 * wall_width(4),
                "{v:?} seen over the wall"
            );
        }
    }

    #[test]
    fn bad_parameters_are_errors() {
        assert!(generate(&OccluderParams {
            objects: 0,
            tessellation: 8
        })
        .is_err());
        assert!(generate(&OccluderParams {
            objects: 1,
            tessellation: 1
        })
        .is_err());
        assert!(matches!(
            generate(&OccluderParams {
                objects: 1,
                tessellation: 4096
            }),
            Err(GenerateError::TooLarge { .. })
        ));
    }
}
