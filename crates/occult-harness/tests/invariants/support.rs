//! DESIGN invariant 2 as reusable checks: a conservative renderer's frames are bit-identical to
//! `zbuffer`'s (depth bits and item ids, hence colors). Every renderer's module calls these
//! with each of its configurations; they panic, naming the scene and the view, on the first
//! frame that differs.
//!
//! A renderer's default configuration is checked over [`VIEWS_PER_SCENE`] random views of every
//! scene; each other configuration changes one part of a renderer the default already runs
//! over those views, so it is checked on every scene too, over [`VIEWS_PER_VARIANT`] views.

use std::sync::Arc;

use occult_core::{Camera, Scene, Vec3, View};
use occult_raster::{Frame, RasterConfig};
use occult_render::{AlgoSpec, Algorithm, RenderOptions, Renderer};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// Small instances of every generator (instancing exercised where the generator has it).
pub const SCENES: &[&str] = &[
    "terrain:g=48",
    "terrain:g=16,tiles=3",
    "city:blocks=2,detail=2",
    "forest:trees=2,patches=2,levels=1",
    "chessboard:n=40",
    "plant:units=1,floors=2,pipes=6,sides=6",
    "occluder:objects=3",
];

/// `s` parsed as a renderer spec.
///
/// # Panics
/// If it does not parse, naming it.
pub fn spec(s: &str) -> AlgoSpec {
    AlgoSpec::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"))
}

/// The renderer of spec `s` built on `scene` with the default options.
///
/// # Panics
/// If the spec does not parse or the renderer does not build, naming the spec.
pub fn renderer(s: &str, scene: &Arc<Scene>) -> Box<dyn Renderer> {
    spec(s)
        .build(scene.clone(), &RenderOptions::default())
        .unwrap_or_else(|e| panic!("{s}: {e}"))
}

/// One `#[test]` per configuration of a table, each a single call of a check of this module
/// ([`assert_identical_on_every_generator`] for a renderer's default configuration,
/// [`assert_variant_identical_on_every_generator`] for the others) on a spec and a rasterizer
/// thread count, so that every configuration fails on its own:
///
/// ```ignore
/// identical_on_every_generator! {
///     /// Why this configuration.
///     test_name: assert_variant_identical_on_every_generator("algo:key=value", 2);
/// }
/// ```
macro_rules! identical_on_every_generator {
    ($($(#[$attr:meta])* $name:ident: $check:ident($spec:expr, $threads:expr);)+) => {
        $(
            $(#[$attr])*
            #[test]
            fn $name() {
                $crate::support::$check(&$crate::support::spec($spec), $threads);
            }
        )+
    };
}
pub(crate) use identical_on_every_generator;

/// Random views per scene in [`assert_identical_on_every_generator`].
pub const VIEWS_PER_SCENE: usize = 50;

/// Random views per scene in [`assert_variant_identical_on_every_generator`].
pub const VIEWS_PER_VARIANT: usize = 20;

/// A random view of `scene` at 96×64: eyes inside and around its bounds, random fields of view,
/// near planes from tiny to large and far planes that may cut the scene.
pub fn random_view(rng: &mut Pcg64Mcg, scene: &Scene) -> View {
    let b = scene.bounds();
    let diag = b.size().length().max(1e-3);
    loop {
        let pick = |rng: &mut Pcg64Mcg, grow: f32| {
            let c = b.center();
            let h = b.half_extent() * grow + Vec3::splat(diag * 0.01);
            Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * h
                + c
        };
        let eye = pick(rng, 1.6);
        let target = pick(rng, 0.8);
        let mut cam = Camera::look_at(eye, target);
        cam.fov_y_deg = rng.random_range(15.0..110.0);
        cam.near = diag * 10f32.powf(rng.random_range(-5.0..-1.5));
        cam.far = diag * rng.random_range(0.2..3.0);
        if let Ok(view) = View::new(cam, 96, 64) {
            return view;
        }
    }
}

fn options(threads: usize) -> RenderOptions {
    RenderOptions {
        raster: RasterConfig {
            threads,
            ..RasterConfig::default()
        },
        ..RenderOptions::default()
    }
}

/// `zbuffer` and `spec` built on `scene` (called `scene_spec` in the panic messages).
fn zbuffer_and(
    spec: &AlgoSpec,
    scene_spec: &str,
    scene: &Arc<Scene>,
    options: &RenderOptions,
) -> (Box<dyn Renderer>, Box<dyn Renderer>) {
    let reference = Algorithm::ZBUFFER
        .build(scene.clone(), options)
        .unwrap_or_else(|e| panic!("zbuffer on {scene_spec}: {e}"));
    let renderer = spec
        .build(scene.clone(), options)
        .unwrap_or_else(|e| panic!("{spec} on {scene_spec}: {e}"));
    (reference, renderer)
}

/// Two cleared `width × height` frames.
pub fn two_frames(width: u32, height: u32) -> (Frame, Frame) {
    let frame = || Frame::new(width, height).unwrap_or_else(|e| panic!("a {width} × {height} frame: {e}"));
    (frame(), frame())
}

/// The generated scene of `spec`.
///
/// # Panics
/// If the spec does not build.
pub fn build_scene(spec: &str) -> occult_scenes::spec::BuiltScene {
    occult_scenes::spec::parse_spec(spec)
        .and_then(|s| s.build())
        .unwrap_or_else(|e| panic!("{spec}: {e}"))
}

/// Renders [`VIEWS_PER_SCENE`] random views of every scene of [`SCENES`] with `spec` and with
/// `zbuffer` (`threads` rasterizer threads, 0 = all), one renderer object per scene so that
/// state kept across frames is exercised, and panics on the first frame that differs. For a
/// renderer's default configuration.
pub fn assert_identical_on_every_generator(spec: &AlgoSpec, threads: usize) {
    assert_identical_on_generators(spec, threads, VIEWS_PER_SCENE);
}

/// [`assert_identical_on_every_generator`] over [`VIEWS_PER_VARIANT`] views per scene: for
/// the configurations other than a renderer's default.
pub fn assert_variant_identical_on_every_generator(spec: &AlgoSpec, threads: usize) {
    assert_identical_on_generators(spec, threads, VIEWS_PER_VARIANT);
}

/// `view_count` random views of every scene of [`SCENES`] (see
/// [`assert_identical_on_every_generator`]).
fn assert_identical_on_generators(spec: &AlgoSpec, threads: usize, view_count: usize) {
    let mut rng = Pcg64Mcg::seed_from_u64(2026);
    let options = options(threads);
    for scene_spec in SCENES {
        let scene = Arc::new(build_scene(scene_spec).scene);
        let (mut reference, mut renderer) = zbuffer_and(spec, scene_spec, &scene, &options);
        let (mut a, mut b) = two_frames(96, 64);
        let mut covered_views = 0;
        for i in 0..view_count {
            let view = random_view(&mut rng, &scene);
            reference
                .render(&view, &mut a)
                .unwrap_or_else(|e| panic!("zbuffer on {scene_spec}, view {i}: {e}"));
            renderer
                .render(&view, &mut b)
                .unwrap_or_else(|e| panic!("{spec} on {scene_spec}, view {i}: {e}"));
            assert!(
                a.same_visibility(&b),
                "{spec} differs from zbuffer on {scene_spec}, view {i} ({} of {} pixels): {:?}",
                a.differing_item_count(&b),
                u64::from(a.width()) * u64::from(a.height()),
                view.camera()
            );
            covered_views += (a.covered_pixel_count() > 0) as usize;
        }
        // The test must look at something: most random views see part of the scene.
        assert!(
            covered_views >= view_count / 4,
            "{scene_spec}: only {covered_views} views saw anything"
        );
    }
}

/// Renders every camera of `path_spec` (then the scene's default camera) on `scene_spec` at
/// `width × height` with `spec` and with `zbuffer`, the same renderer object for the whole path
/// (so temporal coherence must never leak a stale result into a frame), and panics on the
/// first frame that differs or that sees nothing.
pub fn assert_identical_on_path(spec: &AlgoSpec, scene_spec: &str, path_spec: &str, width: u32, height: u32) {
    let built = build_scene(scene_spec);
    let cams = occult_scenes::path::parse_path(path_spec, &built.scene, &built.default_camera)
        .unwrap_or_else(|e| panic!("{path_spec}: {e}"));
    let scene = Arc::new(built.scene);
    let (mut z, mut r) = zbuffer_and(spec, scene_spec, &scene, &RenderOptions::default());
    let (mut a, mut b) = two_frames(width, height);
    for (i, cam) in cams.iter().chain([&built.default_camera]).enumerate() {
        let view = View::new(*cam, width, height).unwrap_or_else(|e| panic!("{path_spec}, frame {i}: {e}"));
        z.render(&view, &mut a)
            .unwrap_or_else(|e| panic!("zbuffer on {scene_spec}, frame {i}: {e}"));
        r.render(&view, &mut b)
            .unwrap_or_else(|e| panic!("{spec} on {scene_spec}, frame {i}: {e}"));
        assert!(
            a.same_visibility(&b),
            "{spec} differs from zbuffer on {scene_spec} {path_spec}, frame {i} ({} pixels): {cam:?}",
            a.differing_item_count(&b)
        );
        assert!(
            a.covered_pixel_count() > 0,
            "{scene_spec} {path_spec}: frame {i} sees nothing: {cam:?}"
        );
    }
}
