//! Shadow-volume clamping (Décoret 2005 §3.3): shadows identical with and without clamping on
//! views of `city` and `terrain`; clamping saves fill; bad lights are errors.

use crate::support::build_scene;
use std::sync::Arc;

use occult_core::{Aabb, Vec3, View};
use occult_raster::{Frame, RasterConfig, Rasterizer};
use occult_render::nbuffer::shadows::{Clamping, Shade, ShadowCasters, ShadowFrame, SpotLight};
use occult_render::{Algorithm, RenderOptions};

/// A generated scene, the cameras of a path on it, its casters, a zbuffer and a rasterizer.
struct Setup {
    scene: Arc<occult_core::Scene>,
    cams: Vec<occult_core::Camera>,
    casters: ShadowCasters,
    z: Box<dyn occult_render::Renderer>,
    raster: Rasterizer,
}

impl Setup {
    /// Renders the scene from `view`, then its shadows under `light` without and with clamping.
    fn shadows_both_ways(&mut self, view: &View, light: &SpotLight) -> (ShadowFrame, ShadowFrame) {
        let mut frame = Frame::new(view.width(), view.height()).unwrap();
        self.z.render(view, &mut frame).unwrap();
        let [off, on] = [Clamping::Off, Clamping::On].map(|clamping| {
            self.casters
                .shadows(&mut self.raster, view, &frame, light, clamping)
                .unwrap()
        });
        (off, on)
    }
}

fn setup(scene_spec: &str, path: &str, leaf: usize) -> Setup {
    let built = build_scene(scene_spec);
    let cams = occult_scenes::path::parse_path(path, &built.scene, &built.default_camera).unwrap();
    let scene = Arc::new(built.scene);
    Setup {
        casters: ShadowCasters::new(scene.clone(), leaf).unwrap(),
        z: Algorithm::ZBUFFER
            .build(scene.clone(), &RenderOptions::default())
            .unwrap(),
        raster: Rasterizer::new(RasterConfig::default()).unwrap(),
        scene,
        cams,
    }
}

/// Renders each camera of `path` on `scene_spec` and compares shadow flags with and without
/// clamping; returns (unclamped, clamped) stencil fragments summed over the path.
fn compare(scene_spec: &str, path: &str, leaf: usize, w: u32, h: u32, lights: &[SpotLight]) -> (u64, u64) {
    let mut setup = setup(scene_spec, path, leaf);
    let (mut off_fill, mut on_fill) = (0, 0);
    let mut shadowed = 0;
    let mut lights: Vec<SpotLight> = lights.to_vec();
    let mut default = SpotLight::for_bounds(&setup.scene.bounds());
    default.resolution = 128;
    lights.push(default);
    for (k, cam) in setup.cams.clone().iter().enumerate() {
        let light = &lights[k % lights.len()];
        let view = View::new(*cam, w, h).unwrap();
        let (off, on) = setup.shadows_both_ways(&view, light);
        let differ = off.shades.iter().zip(&on.shades).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "{scene_spec} view {k}: {differ} pixels differ with clamping");
        assert_eq!(off.counts.casters_culled, 0);
        assert!(on.counts.stencil.fragments <= off.counts.stencil.fragments);
        shadowed += on.counts.shadowed_pixels;
        off_fill += off.counts.stencil.fragments;
        on_fill += on.counts.stencil.fragments;
    }
    assert!(shadowed > 0, "{scene_spec}: no shadow at all");
    (off_fill, on_fill)
}

#[test]
fn city_shadows_are_identical_with_and_without_clamping() {
    let (off, on) = compare("city:blocks=2,detail=1", "street:6", 4096, 96, 64, &[]);
    assert!(on < off, "clamping saved no fill: {on} vs {off}");
    let b = Aabb::new(Vec3::new(-76.0, 0.0, -76.0), Vec3::new(76.0, 60.0, 76.0));
    let low = SpotLight {
        position: Vec3::new(90.0, 40.0, 20.0),
        target: b.center(),
        cone_deg: 100.0,
        resolution: 97,
    };
    compare("city:blocks=2,detail=0", "circle:4", 4096, 80, 60, &[low]);
}

#[test]
fn terrain_shadows_are_identical_with_and_without_clamping() {
    let low = SpotLight {
        position: Vec3::new(-120.0, 30.0, 0.0),
        target: Vec3::ZERO,
        cone_deg: 90.0,
        resolution: 128,
    };
    let (off, on) = compare("terrain:g=48", "flyover:6", 256, 96, 64, &[low]);
    assert!(on < off, "clamping saved no fill: {on} vs {off}");
}

#[test]
fn bad_lights_are_errors() {
    let built = build_scene("city:blocks=1,detail=0");
    let view = View::new(built.default_camera, 32, 24).unwrap();
    let scene = Arc::new(built.scene);
    assert!(ShadowCasters::new(scene.clone(), 0).is_err());
    let casters = ShadowCasters::new(scene.clone(), 64).unwrap();
    let mut raster = Rasterizer::new(RasterConfig::default()).unwrap();
    let frame = Frame::new(32, 24).unwrap();
    let good = SpotLight::for_bounds(&scene.bounds());
    for bad in [
        SpotLight { cone_deg: 0.0, ..good },
        SpotLight {
            cone_deg: 180.0,
            ..good
        },
        SpotLight {
            cone_deg: f32::NAN,
            ..good
        },
        SpotLight { resolution: 0, ..good },
        SpotLight {
            resolution: 100_000,
            ..good
        },
        SpotLight {
            target: good.position,
            ..good
        },
        SpotLight {
            position: Vec3::new(f32::INFINITY, 0.0, 0.0),
            ..good
        },
    ] {
        assert!(
            casters.shadows(&mut raster, &view, &frame, &bad, Clamping::On).is_err(),
            "{bad:?}"
        );
    }
    let wrong = Frame::new(16, 16).unwrap();
    assert!(casters
        .shadows(&mut raster, &view, &wrong, &good, Clamping::Off)
        .is_err());
    // An empty frame: nothing visible, every caster culled, nothing shadowed.
    let r = casters
        .shadows(&mut raster, &view, &frame, &good, Clamping::On)
        .unwrap();
    assert!(r.shades.iter().all(|&s| s == Shade::Sky));
    assert_eq!(r.counts.casters_culled, r.counts.casters);
    assert_eq!(r.counts.stencil.fragments, 0);
}

#[test]
fn a_point_on_a_shadow_boundary_is_classified_alike_with_and_without_clamping() {
    // `terrain`, camera 7 of `flyover:8`, 640×480, the default light: one visible point lies on
    // a side face of a clamped caster's volume. When the unclamped sides ran to the far plane in
    // one quad, their snapped corners differed from the clamped ones and this pixel flipped.
    let mut setup = setup("terrain", "flyover:8", 4096);
    let light = SpotLight::for_bounds(&setup.scene.bounds());
    let view = View::new(setup.cams[7], 640, 480).unwrap();
    let (off, on) = setup.shadows_both_ways(&view, &light);
    assert!(on.counts.casters_clamped > 0 && on.counts.shadowed_pixels > 10_000);
    let differ: Vec<usize> = (0..off.shades.len())
        .filter(|&i| off.shades[i] != on.shades[i])
        .collect();
    assert!(differ.is_empty(), "pixels differ with clamping: {differ:?}");
    assert!(on.counts.stencil.fragments < off.counts.stencil.fragments);
}
