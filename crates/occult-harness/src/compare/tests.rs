//! The comparison on a small scene of instanced cubes: line-ups, references, reports, errors.

use super::*;
use occult_core::NO_ITEM;
use occult_core::{Affine3A, Camera, Instance, Mesh, SceneBuilder, Vec3, View};
use occult_raster::Frame;
use oracle::{fine_size, paper_error};

/// A 6×6 grid of unit cubes (instanced) on a ground quad: cubes hide each other and the
/// ground from most views.
fn cubes() -> Arc<Scene> {
    // The cube's corners are the bit patterns of 0..8 (x from bit 0, y bit 1, z bit 2); each
    // face is two triangles wound outwards.
    let corners = (0..8u32)
        .map(|i| Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32) - 0.5)
        .collect();
    let faces = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let triangles = faces.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
    let mut builder = SceneBuilder::new();
    let cube = builder
        .add_mesh(
            "cube",
            Mesh::new(corners, triangles).expect("a cube of in-range triangles is a valid mesh"),
        )
        .expect("a valid mesh adds");
    let ground = [[-8.0, -8.0], [8.0, -8.0], [8.0, 8.0], [-8.0, 8.0]].map(|[x, z]| Vec3::new(x, -0.5, z));
    let ground =
        Mesh::new(ground.to_vec(), vec![[0, 2, 1], [0, 3, 2]]).expect("a quad of in-range triangles is a valid mesh");
    let ground = builder.add_mesh("ground", ground).expect("a valid mesh adds");
    let at = (0..36).map(|k| Vec3::new((k / 6) as f32 * 2.0 - 5.0, 0.0, (k % 6) as f32 * 2.0 - 5.0));
    let mut instances = vec![Instance {
        parent_from_child: Affine3A::IDENTITY,
        child: ground,
    }];
    instances.extend(at.map(|at| Instance {
        parent_from_child: Affine3A::from_translation(at),
        child: cube,
    }));
    let root = builder
        .add_group("cubes", instances)
        .expect("a group of known nodes adds");
    Arc::new(builder.build(root).expect("the cubes have triangles and build"))
}

fn circle(n: usize) -> Vec<Camera> {
    (0..n)
        .map(|i| {
            let a = i as f32 / n as f32 * std::f32::consts::TAU;
            Camera::look_at(Vec3::new(9.0 * a.cos(), 2.0, 9.0 * a.sin()), Vec3::new(0.0, 0.0, 0.0))
        })
        .collect()
}

fn run(algorithms: Vec<Algorithm>, cameras: &[Camera]) -> Result<CompareReport> {
    let mut config = CompareConfig::new(algorithms, 96, 64);
    config.options.raster.threads = 2;
    compare(cubes(), cameras, &config, &mut |_| {})
}

#[test]
fn frustum_is_identical_to_zbuffer_on_every_frame() {
    let cameras = circle(6);
    let report =
        run(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], &cameras).expect("zbuffer and frustum compare on the cubes");
    assert_eq!(report.reference.as_deref(), Some("zbuffer"));
    assert_eq!(report.frames, 6);
    for r in &report.renderers {
        assert_eq!(r.frames, 6);
        assert_eq!(r.frames_identical, Some(6), "{} differs from the reference", r.name);
        assert!(r
            .per_frame
            .iter()
            .all(|f| f.identical && f.item_error.is_none() && f.psnr_db.is_none()));
        assert_eq!(r.mean_item_error, 0.0);
        assert!(r.min_psnr_db.is_none());
    }
    assert_eq!(
        report
            .oracle
            .as_ref()
            .expect("a brute-force reference comes with an oracle")
            .frames_identical,
        6,
        "rasterizing the visible set must reproduce the frame"
    );
}

#[test]
fn report_numbers_are_consistent() {
    let cameras = circle(5);
    let report = run(
        vec![Algorithm::FRUSTUM, Algorithm::ZBUFFER, Algorithm::FRUSTUM],
        &cameras,
    )
    .expect("zbuffer and frustum compare on the cubes");
    let names: Vec<_> = report.renderers.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["frustum", "zbuffer"], "requested order, duplicates dropped");
    assert_eq!(report.scene_triangles, 2 + 36 * 12);
    let z = report.renderer("zbuffer").expect("zbuffer is in the report");
    let f = report.renderer("frustum").expect("frustum is in the report");
    assert!(z.is_reference && !f.is_reference && z.requested && f.requested);
    assert_eq!(z.speedup_vs_zbuffer, Some(1.0));
    assert!(
        (f.speedup_vs_zbuffer
            .expect("frustum is timed against a zbuffer in the report")
            - z.mean_ms / f.mean_ms)
            .abs()
            < 1e-9
    );
    // zbuffer submits everything; frustum never more.
    assert_eq!(z.stats.triangles_submitted, report.scene_triangles as f64);
    for r in [z, f] {
        assert_eq!(r.per_frame.len(), 5);
        let total: u64 = r.per_frame.iter().map(|p| p.triangles_rasterized).sum();
        assert_eq!(r.triangles_rasterized_total, total);
        assert!((r.triangles_rasterized - total as f64 / 5.0).abs() < 1e-9);
        assert_eq!(r.stats.triangles_rasterized, r.triangles_rasterized);
        let mean_ms = r.per_frame.iter().map(|p| p.time_ms).sum::<f64>() / 5.0;
        assert!((r.mean_ms - mean_ms).abs() < 1e-9);
        assert!(r.time.min_ms <= r.time.median_ms && r.time.median_ms <= r.p95_ms && r.p95_ms <= r.time.max_ms);
        assert!(r.vs_oracle.expect("every renderer is compared with the oracle") > 0.0);
        assert!(r.prepare_ms >= 0.0);
        assert!(!r.phases.is_empty());
    }
    assert!(f.stats.triangles_submitted <= z.stats.triangles_submitted);
    // Visible triangles: from the item buffer, never more than rasterized.
    assert_eq!(
        report
            .oracle
            .as_ref()
            .expect("a brute-force reference comes with an oracle")
            .triangles_visible
            .len(),
        5
    );
    let visible: u64 = report
        .oracle
        .as_ref()
        .expect("a brute-force reference comes with an oracle")
        .triangles_visible
        .iter()
        .sum();
    assert_eq!(z.triangles_visible_total, visible);
    assert!(visible > 0);
    for (i, &v) in report
        .oracle
        .as_ref()
        .expect("a brute-force reference comes with an oracle")
        .triangles_visible
        .iter()
        .enumerate()
    {
        assert!(v <= z.per_frame[i].triangles_rasterized && v < report.scene_triangles);
    }
    assert!(report.process_peak_rss_bytes.is_none_or(|b| b > 0));
}

#[test]
fn peak_memory_is_measured_per_renderer_where_the_kernel_allows() {
    let mut config = CompareConfig::new(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], 96, 64);
    config.options.raster.threads = 2;
    config.peak_rss = Some(PeakRss::new());
    let report = compare(cubes(), &circle(2), &config, &mut |_| {}).expect("zbuffer and frustum compare on the cubes");
    let process = report.process_peak_rss_bytes;
    let measurable = cfg!(target_os = "linux") && std::fs::write("/proc/self/clear_refs", "5").is_ok();
    for r in &report.renderers {
        match r.peak_rss_bytes {
            Some(peak) => {
                assert!(measurable, "{}: a peak where none can be measured", r.name);
                assert!(peak > 0);
                // Each reading is of the whole process, so never above its peak.
                assert!(
                    peak <= process.expect("a renderer's peak implies the process peak"),
                    "{}: {peak} > {process:?}",
                    r.name
                );
            }
            None => assert!(!measurable, "{}: no peak although the mark can be reset", r.name),
        }
    }
}

#[test]
fn process_memory_is_left_alone_unless_asked_for() {
    let report = run(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], &circle(2))
        .expect("zbuffer and frustum compare on the cubes");
    assert_eq!(report.process_peak_rss_bytes, None);
    assert!(report.renderers.iter().all(|r| r.peak_rss_bytes.is_none()));
}

#[test]
fn reference_is_added_when_not_requested() {
    let report = run(vec![Algorithm::FRUSTUM], &circle(2)).expect("frustum compares on the cubes");
    let z = &report.renderers[0];
    assert_eq!((z.name.as_str(), z.is_reference, z.requested), ("zbuffer", true, false));
    assert!(report.reference_note.contains("not requested"));
    assert_eq!(report.renderers[1].frames_identical, Some(2));
}

/// The frames checked against come from a second, untimed instance of the reference: every
/// build is announced, that one last, and the timed reference is checked like any renderer.
#[test]
fn reference_frames_come_from_an_untimed_instance() {
    let config = CompareConfig::new(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], 96, 64);
    let mut builds = Vec::new();
    let report = compare(cubes(), &circle(3), &config, &mut |p| {
        if let CompareProgress::Building { label, index, count } = p {
            builds.push((label.to_string(), index, count));
        }
    })
    .expect("zbuffer and frustum compare on the cubes");
    assert_eq!(
        builds,
        [
            ("zbuffer".to_string(), 0, 3),
            ("frustum".to_string(), 1, 3),
            ("zbuffer (reference frames)".to_string(), 2, 3)
        ]
    );
    let z = report.renderer("zbuffer").expect("zbuffer is in the report");
    assert!(z.is_reference);
    assert_eq!((z.frames, z.frames_identical), (3, Some(3)));
    let none = CompareConfig {
        reference: Reference::None,
        ..config
    };
    let mut builds = 0;
    compare(cubes(), &circle(1), &none, &mut |p| {
        builds += usize::from(matches!(p, CompareProgress::Building { .. }));
    })
    .expect("no reference");
    assert_eq!(builds, 2, "nothing to check, no second instance");
}

#[test]
fn scenes_too_large_for_brute_force_use_frustum_as_reference() {
    // 10^10 triangle instances along +x, ten times farther apart at each level; the camera
    // sees only the first few.
    let mut b = SceneBuilder::new();
    let tri = Mesh::new(
        vec![Vec3::ZERO, Vec3::new(0.8, 0.0, 0.0), Vec3::new(0.0, 0.8, 0.0)],
        vec![[0, 1, 2]],
    )
    .expect("one in-range triangle is a valid mesh");
    let mut id = b.add_mesh("tri", tri).expect("a valid mesh adds");
    for level in 0..10 {
        let pitch = 10f32.powi(level);
        let row: Vec<_> = (0..10)
            .map(|i| Instance {
                parent_from_child: Affine3A::from_translation(Vec3::X * pitch * i as f32),
                child: id,
            })
            .collect();
        id = b
            .add_group(format!("level{level}"), row)
            .expect("a row of a known node adds");
    }
    let scene = Arc::new(b.build(id).expect("10^10 instances build"));
    assert!(scene.item_count() > MAX_BRUTE_FORCE_ITEMS);
    let mut camera = Camera::look_at(Vec3::new(4.0, 0.5, 6.0), Vec3::new(4.0, 0.5, 0.0));
    camera.far = 30.0;
    let config = CompareConfig::new(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], 64, 48);
    let report = compare(scene, &[camera, camera], &config, &mut |_| {})
        .expect("frustum compares as the reference on a scene too large for brute force");
    assert_eq!(report.reference.as_deref(), Some("frustum"));
    assert!(
        report.reference_note.contains("more than brute force accepts"),
        "{}",
        report.reference_note
    );
    assert_eq!(report.skipped.len(), 1);
    assert_eq!(report.skipped[0].name, "zbuffer");
    assert_eq!(report.renderers.len(), 1);
    let f = &report.renderers[0];
    assert!(f.is_reference && f.requested && f.speedup_vs_zbuffer.is_none());
    assert_eq!(f.frames_identical, Some(2));
    assert!(
        report
            .oracle
            .as_ref()
            .expect("a frustum reference comes with an oracle")
            .triangles_visible[0]
            > 0
    );
    assert_eq!(
        report
            .oracle
            .as_ref()
            .expect("a frustum reference comes with an oracle")
            .frames_identical,
        2
    );
}

#[test]
fn empty_inputs_are_errors() {
    assert!(matches!(run(vec![Algorithm::FRUSTUM], &[]), Err(CompareError::NoViews)));
    assert!(matches!(run(vec![], &circle(1)), Err(CompareError::NoAlgorithms)));
}

#[test]
fn degenerate_camera_and_bad_size_are_errors() {
    let mut cameras = circle(3);
    cameras[1].target = cameras[1].eye;
    assert!(matches!(
        run(vec![Algorithm::FRUSTUM], &cameras),
        Err(CompareError::BadView { view_index: 1, .. })
    ));
    let config = CompareConfig::new(vec![Algorithm::FRUSTUM], 0, 64);
    assert!(matches!(
        compare(cubes(), &circle(1), &config, &mut |_| {}),
        Err(CompareError::BadView { .. })
    ));
}

#[test]
fn views_that_see_nothing_are_fine() {
    let away = Camera::look_at(Vec3::new(0.0, 50.0, 0.0), Vec3::new(0.0, 100.0, 1.0));
    let report = run(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], &[away])
        .expect("zbuffer and frustum compare on a view of nothing");
    assert_eq!(
        report
            .oracle
            .as_ref()
            .expect("a brute-force reference comes with an oracle")
            .triangles_visible,
        vec![0]
    );
    assert!(report.renderers.iter().all(|r| r.frames_identical == Some(1)));
}

/// The paper's criterion: a pixel is right when its item is visible somewhere in it (a
/// subpixel of the supersampled reference shows it), or is the reference's own.
#[test]
fn paper_error_accepts_what_is_visible_in_the_pixel() {
    let frame_of = |w: u32, h: u32, items: &[ItemId]| {
        let mut f = Frame::new(w, h).expect("frame");
        let (depth, ids) = f.buffers_mut();
        for (k, &i) in items.iter().enumerate() {
            ids[k] = i;
            depth[k] = if i == NO_ITEM { 0.0 } else { 0.5 };
        }
        f
    };
    // Pixel 0 sees items 1 and 3 (and the background), pixel 1 only item 2.
    let reference = frame_of(2, 1, &[1, 2]);
    let fine = frame_of(4, 2, &[1, 3, 2, 2, 1, NO_ITEM, 2, 2]);
    assert_eq!(paper_error(&reference, &reference, &fine), 0.0);
    assert_eq!(
        paper_error(&frame_of(2, 1, &[3, 4]), &reference, &fine),
        0.5,
        "3 is seen in pixel 0, 4 nowhere"
    );
    assert_eq!(
        paper_error(&frame_of(2, 1, &[NO_ITEM, NO_ITEM]), &reference, &fine),
        0.5,
        "the background shows in pixel 0 only"
    );
    assert_eq!(
        paper_error(&frame_of(2, 1, &[2, 1]), &reference, &fine),
        1.0,
        "each item is the other pixel's"
    );
    assert_eq!(fine_size(640, 480), (2560, 1920));
    assert_eq!(fine_size(4000, 3000), (4000, 3000), "no room for subsamples");
}

#[test]
fn differing_frames_are_measured() {
    let scene = cubes();
    let view = View::new(circle(1)[0], 32, 24).expect("a 32x24 view of the cubes");
    let mut a = Frame::new(32, 24).expect("a 32x24 frame");
    let mut r = Algorithm::ZBUFFER
        .build(Arc::clone(&scene), &RenderOptions::default())
        .expect("zbuffer builds for any scene");
    r.render(&view, &mut a).expect("zbuffer renders the cubes");
    let mut b = a.clone();
    assert_eq!(item_error(&a, &b), 0.0);
    b.clear();
    assert_eq!(item_error(&b, &a), 1.0, "all covered pixels lost");
    assert_eq!(item_error(&b, &b), 0.0);
}

#[test]
fn reference_can_be_chosen_or_none() {
    let cameras = circle(4);
    let mut config = CompareConfig::new(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], 96, 64);
    config.reference = Reference::Spec(AlgoSpec::from(Algorithm::FRUSTUM));
    let report = compare(cubes(), &cameras, &config, &mut |_| {})
        .expect("zbuffer and frustum compare with frustum as the reference");
    assert_eq!(report.reference.as_deref(), Some("frustum"));
    assert!(
        report
            .renderer("frustum")
            .expect("frustum is in the report")
            .is_reference
    );
    assert_eq!(
        report
            .renderer("zbuffer")
            .expect("zbuffer is in the report")
            .frames_identical,
        Some(4)
    );
    assert!(report.oracle.is_some());

    config.algorithms = vec![AlgoSpec::from(Algorithm::FRUSTUM)];
    config.reference = Reference::None;
    let report = compare(cubes(), &cameras, &config, &mut |_| {}).expect("frustum compares with no reference");
    assert_eq!(report.reference, None);
    assert!(report.oracle.is_none());
    assert_eq!(report.renderers.len(), 1, "no reference is added");
    let f = report.renderer("frustum").expect("frustum is in the report");
    assert!(!f.is_reference);
    assert_eq!(f.frames_identical, None, "nothing is checked");
    assert_eq!(f.vs_oracle, None);
    assert_eq!(report.image.measured_on, "frustum");
    assert_eq!(report.image.covered_pixels.len(), 4);
    assert!(report.image.covered_pixels.iter().all(|&c| c > 0));
    assert!(
        f.triangles_visible > 0.0,
        "visible triangles come from the first renderer's frames"
    );
}

#[test]
fn approximate_or_impossible_references_are_refused() {
    // One view: with large=off the ground's two triangles are sampled as points, millions of
    // them from views where the ground passes close to the eye.
    let cameras = circle(1);
    let mut config = CompareConfig::new(vec![Algorithm::FRUSTUM], 32, 32);
    config.reference = Reference::Spec(AlgoSpec::parse("rzb").expect("rzb is a known renderer"));
    let e = compare(cubes(), &cameras, &config, &mut |_| {}).unwrap_err();
    assert!(matches!(e, CompareError::BadReference { .. }), "{e}");
    assert!(e.to_string().contains("conservative"), "{e}");
    config.reference = Reference::Spec(AlgoSpec::parse("lzb:mode=naive").expect("lzb:mode=naive is a valid spec"));
    let e = compare(cubes(), &cameras, &config, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("approximate"), "{e}");
}

#[test]
fn image_complexity_is_the_clipped_screen_area_of_every_layer() {
    // Two full-screen squares, one behind the other, facing the camera: every pixel is
    // covered twice, so image complexity is 2 w h and depth complexity 2.
    let quad = |z: f32| {
        Mesh::new(
            vec![
                Vec3::new(-100.0, -100.0, z),
                Vec3::new(100.0, -100.0, z),
                Vec3::new(100.0, 100.0, z),
                Vec3::new(-100.0, 100.0, z),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .expect("a quad of in-range triangles is a valid mesh")
    };
    let mut b = SceneBuilder::new();
    let near = b.add_mesh("near", quad(0.0)).expect("a valid mesh adds");
    let far = b.add_mesh("far", quad(-5.0)).expect("a valid mesh adds");
    let root = b
        .add_group(
            "layers",
            [near, far]
                .map(|child| Instance {
                    parent_from_child: Affine3A::IDENTITY,
                    child,
                })
                .to_vec(),
        )
        .expect("a group of known nodes adds");
    let scene = Arc::new(b.build(root).expect("the layers have triangles and build"));
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO);
    let view = View::new(camera, 64, 48).expect("a 64x48 view of the layers");
    let area = image_complexity(&scene, &view);
    assert!((area - 2.0 * 64.0 * 48.0).abs() < 1e-3 * area, "{area}");

    // A triangle wholly inside the view: its projected area.
    let tri = Mesh::new(
        vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ],
        vec![[0, 1, 2]],
    )
    .expect("one in-range triangle is a valid mesh");
    let scene = Arc::new(Scene::from_mesh("tri", tri).expect("one triangle is a valid scene"));
    let view = View::new(camera, 100, 100).expect("a 100x100 view of the triangle");
    let c = view.clip_from_world();
    let px = |p: Vec3| {
        let v = c * p.extend(1.0);
        (v.x as f64 / v.w as f64 * 50.0, v.y as f64 / v.w as f64 * 50.0)
    };
    let (a, b2, d) = (px(Vec3::ZERO), px(Vec3::X), px(Vec3::Y));
    let expected = ((b2.0 - a.0) * (d.1 - a.1) - (d.0 - a.0) * (b2.1 - a.1)).abs() / 2.0;
    let area = image_complexity(&scene, &view);
    assert!((area - expected).abs() < 1e-3 * expected, "{area} vs {expected}");

    let mut config = CompareConfig::new(vec![Algorithm::ZBUFFER], 64, 48);
    config.image_complexity = true;
    let report = compare(cubes(), &circle(2), &config, &mut |_| {}).expect("zbuffer compares on the cubes");
    let dc = report
        .image
        .mean_depth_complexity()
        .expect("image complexity was asked for");
    assert!(dc >= 1.0, "depth complexity {dc}");
}

#[test]
fn time_summary_uses_nearest_rank() {
    let t: Vec<f64> = (1..=20).map(f64::from).collect();
    let s = TimeSummary::of(&t);
    assert_eq!(
        (s.mean_ms, s.median_ms, s.p95_ms, s.min_ms, s.max_ms),
        (10.5, 10.0, 19.0, 1.0, 20.0)
    );
    assert_eq!(TimeSummary::of(&[3.0]).p95_ms, 3.0);
    assert_eq!(TimeSummary::of(&[]), TimeSummary::default());
}

#[test]
fn differing_frames_come_with_an_image_of_where_only_when_asked() {
    let cameras = circle(1);
    // Every box sampled (no z-buffered large triangles): point samples, not the exact frame.
    let rzb = AlgoSpec::parse("rzb:large=off").expect("a valid spec");
    let mut config = CompareConfig::new([AlgoSpec::from(Algorithm::FRUSTUM), rzb], 96, 64);
    config.options.raster.threads = 2;
    let mut images = Vec::new();
    let count = |config: &CompareConfig, images: &mut Vec<(String, usize, image::RgbaImage)>| {
        let report = compare(cubes(), &cameras, config, &mut |e| {
            if let CompareProgress::Differs { label, index, image } = e {
                images.push((label.to_string(), index, image.clone()));
            }
        })
        .expect("the comparison runs");
        let rzb = report
            .renderers
            .iter()
            .find(|r| r.name.starts_with("rzb"))
            .expect("rzb took part");
        rzb.frames - rzb.frames_identical.expect("frames are checked")
    };
    count(&config, &mut images);
    assert!(images.is_empty(), "no images unless asked");
    config.diff_images = true;
    let differing = count(&config, &mut images);
    assert!(differing > 0, "rzb's point samples differ from zbuffer on these views");
    assert_eq!(
        images.len(),
        differing,
        "one image per differing frame, none for frustum's"
    );
    for (label, index, image) in &images {
        assert_eq!(label, "rzb:large=off");
        assert!(*index < cameras.len());
        assert_eq!(image.dimensions(), (96, 64));
        let red = image.pixels().filter(|p| p.0 == [255, 0, 0, 255]).count();
        let yellow = image.pixels().filter(|p| p.0 == [255, 200, 0, 255]).count();
        assert!(red + yellow > 0, "a differing frame marks where it differs");
    }
}
