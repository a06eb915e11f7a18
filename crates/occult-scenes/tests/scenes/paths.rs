//! Camera paths: every kind yields `N` valid views on every generated scene, walks stay where
//! the layout conventions promise, JSON round-trips exactly, and bad specs are errors.

use occult_core::{Camera, Scene, Vec3, View};
use occult_scenes::generate::{city, plant, terrain, GENERATORS};
use occult_scenes::path::{
    parse_path, path_from_json, path_to_json, write_path_json, PathError, ViewRecord, MAX_VIEWS,
};
use occult_scenes::spec::{parse_spec, BuiltScene};
use std::path::PathBuf;

fn build(spec: &str) -> BuiltScene {
    parse_spec(spec).unwrap().build().unwrap()
}

fn small_scenes() -> Vec<BuiltScene> {
    [
        "terrain:g=16",
        "city:blocks=3,detail=1",
        "forest:trees=2,patches=2,replicate=3",
        "chessboard:n=20",
        "plant:units=2,floors=2,pipes=5,sides=5",
        "occluder:objects=3,tessellation=4",
    ]
    .into_iter()
    .map(build)
    .collect()
}

fn temp_file(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("occult-paths-{}-{name}", std::process::id()))
}

fn check_views(views: &[Camera], n: usize, scene: &Scene, what: &str) {
    assert_eq!(views.len(), n, "{what}");
    for (k, v) in views.iter().enumerate() {
        View::new(*v, 640, 360).unwrap_or_else(|e| panic!("{what}: view {k} {v:?}: {e}"));
        // The far plane reaches the scene's centre: nothing is cut off by construction.
        assert!(v.far >= v.eye.distance(scene.bounds().center()), "{what}: view {k}");
    }
}

#[test]
fn every_kind_yields_n_valid_views_on_every_generator() {
    assert_eq!(GENERATORS.len(), 6);
    for built in small_scenes() {
        for (spec, n) in [
            ("circle:12", 12),
            ("street:7", 7),
            ("flyover:9", 9),
            ("default", 1),
            ("circle:1", 1),
            ("street:1", 1),
        ] {
            let views = parse_path(spec, &built.scene, &built.default_camera).unwrap();
            check_views(&views, n, &built.scene, &format!("{} {spec}", built.name));
        }
        let bare = parse_path("flyover", &built.scene, &built.default_camera).unwrap();
        assert_eq!(bare.len(), occult_scenes::path::DEFAULT_VIEW_COUNT as usize);
    }
}

#[test]
fn default_is_the_default_camera() {
    let built = build("terrain:g=4");
    assert_eq!(
        parse_path("default", &built.scene, &built.default_camera).unwrap(),
        vec![built.default_camera]
    );
}

#[test]
fn circle_looks_at_the_centre_from_outside() {
    let built = build("chessboard:n=8");
    let views = parse_path("circle:8", &built.scene, &built.default_camera).unwrap();
    let b = built.scene.bounds();
    for v in &views {
        assert_eq!(v.target, b.center());
        assert!(!b.contains_point(v.eye));
        assert!(v.eye.y > b.center().y);
    }
    // Equal radius all round.
    let r0 = views[0].eye.distance(b.center());
    assert!(views
        .iter()
        .all(|v| (v.eye.distance(b.center()) - r0).abs() < 1e-3 * r0));
}

#[test]
fn city_street_walk_stays_on_streets_at_eye_height() {
    let built = build("city:blocks=4,detail=1");
    let views = parse_path("street:200", &built.scene, &built.default_camera).unwrap();
    let h = 0.5 * 4.0 * city::BLOCK_PITCH;
    let off_line = |v: f32| {
        let u = (v + h) / city::BLOCK_PITCH;
        (u - u.round()).abs() * city::BLOCK_PITCH
    };
    for v in &views {
        assert!((v.eye.y - city::EYE_HEIGHT).abs() < 1e-4, "{v:?}");
        assert!(
            off_line(v.eye.x) < 1e-2 || off_line(v.eye.z) < 1e-2,
            "eye off the streets: {v:?}"
        );
        assert!(v.eye.x.abs() <= h + 1e-3 && v.eye.z.abs() <= h + 1e-3);
    }
    // It walks: consecutive eyes are close and the walk covers more than one street.
    let distinct_z = views
        .iter()
        .map(|v| (v.eye.z * 10.0).round() as i64)
        .collect::<std::collections::BTreeSet<_>>();
    assert!(distinct_z.len() > 3);
}

#[test]
fn plant_walk_goes_through_unit_centres_on_floor_0() {
    let built = build("plant:units=3,floors=2,pipes=5,sides=5");
    let views = parse_path("street:50", &built.scene, &built.default_camera).unwrap();
    let h = 1.5 * plant::UNIT_SIZE;
    for v in &views {
        assert!((v.eye.y - plant::EYE_HEIGHT).abs() < 1e-4);
        let centre_line = |c: f32| {
            let u = (c + h) / plant::UNIT_SIZE - 0.5;
            (u - u.round()).abs() * plant::UNIT_SIZE < 1e-2
        };
        assert!(centre_line(v.eye.x) || centre_line(v.eye.z), "{v:?}");
    }
}

#[test]
fn generic_walk_follows_the_ground() {
    // A fine mesh, so that its surface is within centimetres of the height function.
    let built = build("terrain:g=256");
    let views = parse_path("street:40", &built.scene, &built.default_camera).unwrap();
    for v in &views {
        let ground = terrain::height(v.eye.x as f64, v.eye.z as f64) as f32;
        let above = v.eye.y - ground;
        assert!(above > 1.2 && above < 2.2, "eye {above} above the ground at {v:?}");
    }
    // The flat chessboard: eye height 1.7 over y = 0.
    let board = build("chessboard:n=10");
    for v in parse_path("street:5", &board.scene, &board.default_camera).unwrap() {
        assert!((v.eye.y - 1.7).abs() < 1e-4, "{v:?}");
    }
}

#[test]
fn generic_walk_stands_on_top_of_slabs() {
    // A 1 m thick slab: its bottom face (facing down) is lower, but the walk stands on its top.
    let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let positions = vec![
        p(-50.0, 0.0, -50.0),
        p(-50.0, 0.0, 50.0),
        p(50.0, 0.0, -50.0),
        p(50.0, 0.0, 50.0),
        p(-50.0, -1.0, -50.0),
        p(-50.0, -1.0, 50.0),
        p(50.0, -1.0, -50.0),
        p(50.0, -1.0, 50.0),
    ];
    let triangles = vec![[0, 1, 2], [2, 1, 3], [4, 6, 5], [6, 7, 5]];
    let slab = occult_core::Mesh::new(positions, triangles).unwrap();
    let scene = Scene::from_mesh("slab", slab).unwrap();
    let camera = Camera::look_at(Vec3::new(0.0, 10.0, -100.0), Vec3::ZERO);
    for v in parse_path("street:9", &scene, &camera).unwrap() {
        assert!((v.eye.y - 1.7).abs() < 1e-4, "{v:?}");
    }
}

#[test]
fn flyover_is_above_and_looks_down() {
    for built in small_scenes() {
        let b = built.scene.bounds();
        for v in parse_path("flyover:16", &built.scene, &built.default_camera).unwrap() {
            assert!(v.eye.y > b.max.y, "{}", built.name);
            assert!(v.target.y < v.eye.y, "{}", built.name);
        }
    }
}

#[test]
fn json_round_trip_is_exact() {
    let built = build("city:blocks=2,detail=1");
    let views = parse_path("flyover:25", &built.scene, &built.default_camera).unwrap();
    let file = temp_file("roundtrip.json");
    write_path_json(&file, &views).unwrap();
    let back = parse_path(file.to_str().unwrap(), &built.scene, &built.default_camera).unwrap();
    std::fs::remove_file(&file).ok();
    assert_eq!(back, views);
    assert_eq!(
        path_from_json(&path_to_json(&views), "<text>", &built.default_camera).unwrap(),
        views
    );
}

#[test]
fn json_optional_fields_default_from_the_default_camera() {
    let defaults = Camera {
        fov_y_deg: 45.0,
        near: 0.25,
        far: 500.0,
        ..Camera::look_at(Vec3::ONE, Vec3::ZERO)
    };
    let views = path_from_json(
        r#"[{"eye": [0, 2, -5], "target": [0, 0, 0]}, {"eye": [1,2,3], "target": [0,0,0], "fov_y_deg": 30}]"#,
        "t",
        &defaults,
    )
    .unwrap();
    assert_eq!(views[0].fov_y_deg, 45.0);
    assert_eq!((views[0].near, views[0].far, views[0].up), (0.25, 500.0, Vec3::Y));
    assert_eq!(views[1].fov_y_deg, 30.0);
    let record = ViewRecord::from_camera(&views[1]);
    assert_eq!(record.to_camera(&defaults), views[1]);
}

#[test]
fn bad_specs_are_errors() {
    let built = build("terrain:g=4");
    let (s, d) = (&built.scene, &built.default_camera);
    let err = |spec: &str| parse_path(spec, s, d).unwrap_err();
    assert!(matches!(err(""), PathError::Empty));
    assert!(matches!(err("circle:0"), PathError::BadCount { .. }));
    assert!(matches!(
        err(&format!("street:{}", MAX_VIEWS as u64 + 1)),
        PathError::BadCount { .. }
    ));
    assert!(matches!(err("flyover:abc"), PathError::BadCount { .. }));
    assert!(matches!(err("flyover:-3"), PathError::BadCount { .. }));
    assert!(matches!(err("spiral:3"), PathError::Unknown(_)));
    assert!(matches!(err("default:3"), PathError::Unknown(_)));
    assert!(err("circle:0").to_string().contains("circle:0"));
    assert!(matches!(err("no/such/path.json"), PathError::Io { .. }));

    let file = temp_file("bad.json");
    type Expect = fn(&PathError) -> bool;
    let cases: [(&str, Expect); 6] = [
        ("[{\"eye\": [0,0,0], \"target\": ", |e| {
            matches!(e, PathError::Json { .. })
        }),
        ("{\"eye\": [0,0,1], \"target\": [0,0,0]}", |e| {
            matches!(e, PathError::Json { .. })
        }),
        ("[{\"eye\": [0,0,1], \"target\": [0,0,0], \"zoom\": 2}]", |e| {
            matches!(e, PathError::Json { .. })
        }),
        ("[{\"eye\": [0,0,1]}]", |e| matches!(e, PathError::Json { .. })),
        ("[]", |e| matches!(e, PathError::ViewCount { count: 0, .. })),
        (
            "[{\"eye\": [1,1,1], \"target\": [0,0,0]}, {\"eye\": [0,0,0], \"target\": [0,0,0]}]",
            |e| matches!(e, PathError::BadView { index: 1, .. }),
        ),
    ];
    for (text, is_expected) in cases {
        std::fs::write(&file, text).unwrap();
        let e = parse_path(file.to_str().unwrap(), s, d).unwrap_err();
        assert!(is_expected(&e), "{text}: {e}");
        assert!(!e.to_string().is_empty());
    }
    // A view with a huge coordinate (overflows f32) or a bad fov is refused by validation.
    std::fs::write(&file, "[{\"eye\": [1e300,0,0], \"target\": [0,0,0]}]").unwrap();
    assert!(parse_path(file.to_str().unwrap(), s, d).is_err());
    std::fs::write(&file, "[{\"eye\": [1,0,0], \"target\": [0,0,0], \"fov_y_deg\": 0}]").unwrap();
    assert!(matches!(
        parse_path(file.to_str().unwrap(), s, d).unwrap_err(),
        PathError::BadView { index: 0, .. }
    ));
    std::fs::remove_file(&file).ok();
}

#[test]
fn huge_forest_paths_are_valid() {
    let built = build("forest:replicate=73,levels=2");
    for spec in ["circle:8", "flyover:8", "street:8", "default"] {
        let views = parse_path(spec, &built.scene, &built.default_camera).unwrap();
        for v in &views {
            v.validate().unwrap();
        }
    }
}

#[test]
#[ignore = "measurement: run with --ignored --nocapture in release"]
fn measure_path_times() {
    for spec in [
        "terrain",
        "terrain:tiles=10",
        "city",
        "forest",
        "forest:replicate=73,levels=2",
        "chessboard:n=10000000",
        "plant",
        "occluder",
    ] {
        let built = build(spec);
        for path in ["circle:1000", "flyover:1000", "street:1000"] {
            let start = std::time::Instant::now();
            let views = parse_path(path, &built.scene, &built.default_camera).unwrap();
            println!(
                "{spec:<32} {path:<14} {:>5} views {:>8.1} ms",
                views.len(),
                start.elapsed().as_secs_f64() * 1e3
            );
        }
    }
}

#[test]
fn json_is_one_view_per_line_and_compact() {
    let built = build("terrain:g=4");
    let views = parse_path("circle:3", &built.scene, &built.default_camera).unwrap();
    let text = path_to_json(&views);
    assert_eq!(text.lines().count(), 5, "{text}");
    assert!(text.len() < 3 * 200, "{} bytes", text.len());
    assert_eq!(path_to_json(&[]), "[\n]\n");
}
