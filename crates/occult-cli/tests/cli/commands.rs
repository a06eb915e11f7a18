//! End-to-end tests of the `occult` binary: small generated scenes, small frames, and bad input
//! that must end in one line on stderr and a non-zero status, never a panic.

use super::*;

#[test]
fn render_writes_color_and_depth_pngs_of_the_requested_size() {
    let dir = scratch("render");
    let (color, depth, json) = (dir.join("frame.png"), dir.join("depth.png"), dir.join("stats.json"));
    let stdout = ok(&[
        "render",
        "--scene",
        TERRAIN,
        "--algo",
        "zbuffer",
        "--size",
        "96x64",
        "--out",
        path_arg(&color),
        "--depth-out",
        path_arg(&depth),
        "--json",
        path_arg(&json),
    ]);
    assert!(stdout.contains("triangles rasterized"), "{stdout}");
    let img = image::open(&color).unwrap();
    assert_eq!((img.width(), img.height()), (96, 64));
    let rgba = img.to_rgba8();
    let background = rgba.get_pixel(0, 0).0;
    assert!(
        rgba.pixels().any(|p| p.0 != background),
        "the terrain is visible from its default camera"
    );
    let d = image::open(&depth).unwrap();
    assert_eq!((d.width(), d.height()), (96, 64));
    let stats = read_json(&json);
    assert_eq!(stats["algorithm"], "zbuffer");
    assert_eq!(stats["scene"]["triangles"], 2 * 24 * 24);
    assert_eq!(stats["stats"]["triangles_submitted"], 2 * 24 * 24);
    assert!(stats["triangles_visible"].as_u64().unwrap() > 0);
}

#[test]
fn render_takes_a_path_view_and_camera_overrides() {
    let dir = scratch("render_view");
    let out = dir.join("v.png");
    ok(&[
        "render",
        "--scene",
        CITY,
        "--view",
        "circle:4:2",
        "--size",
        "48x32",
        "--out",
        path_arg(&out),
    ]);
    assert!(out.exists());
    ok(&[
        "render",
        "--scene",
        TERRAIN,
        "--eye",
        "0,40,-120",
        "--target",
        "0,0,0",
        "--fov",
        "50",
        "--size",
        "32x32",
        "--out",
        path_arg(&out),
    ]);
    assert_eq!(image::open(&out).unwrap().width(), 32);
}

#[test]
fn compare_reports_frustum_identical_to_zbuffer() {
    let dir = scratch("compare");
    let (json, csv, plot) = (dir.join("c.json"), dir.join("c.csv"), dir.join("c.png"));
    let stdout = ok(&[
        "--threads",
        "2",
        "compare",
        "--scene",
        CITY,
        "--path",
        "circle:4",
        "--algos",
        "zbuffer,frustum",
        "--size",
        "80x60",
        "--json",
        path_arg(&json),
        "--csv",
        path_arg(&csv),
        "--plot",
        path_arg(&plot),
        "--peak-rss",
    ]);
    assert!(stdout.contains("oracle") && stdout.contains("4/4"), "{stdout}");
    let report = read_json(&json);
    let run = &report["runs"][0];
    assert_eq!(run["scene"]["spec"], CITY);
    assert_eq!(run["reference"], "zbuffer");
    assert_eq!(run["frames"], 4);
    assert_eq!(run["width"], 80);
    let renderers = run["renderers"].as_array().unwrap();
    assert_eq!(renderers.len(), 2);
    for r in renderers {
        for field in [
            "name",
            "mean_ms",
            "p95_ms",
            "speedup_vs_zbuffer",
            "vs_oracle",
            "triangles_rasterized",
            "triangles_visible",
            "frames_identical",
            "frames",
            "prepare_ms",
            "memory_bytes",
            "memory_bytes_after_build",
            "peak_rss_bytes",
            "per_frame",
        ] {
            assert!(r.get(field).is_some(), "{field} missing in {r}");
        }
        // Asked for: a measured peak of the whole process, or null where it cannot be measured.
        let peak = &r["peak_rss_bytes"];
        assert!(peak.is_null() || peak.as_u64().is_some_and(|b| b > 0), "{peak}");
        if cfg!(target_os = "linux") && std::fs::write("/proc/self/clear_refs", "5").is_ok() {
            assert!(peak.as_u64().is_some(), "the kernel allows the measure: {r}");
            assert!(peak.as_u64() <= run["process_peak_rss_bytes"].as_u64());
        }
        assert_eq!(r["frames"], 4);
        assert_eq!(
            r["frames_identical"], r["frames"],
            "{} must be identical to zbuffer",
            r["name"]
        );
        assert_eq!(r["per_frame"].as_array().unwrap().len(), 4);
    }
    let frustum = renderers.iter().find(|r| r["name"] == "frustum").unwrap();
    assert!(frustum["speedup_vs_zbuffer"].as_f64().unwrap() > 0.0);
    assert_eq!(run["oracle"]["frames_identical"], 4);
    assert!(stdout.contains("peak RSS"), "{stdout}");
    let csv = std::fs::read_to_string(&csv).unwrap();
    assert!(csv.starts_with("scene,triangles,renderer,frame,time_ms"));
    assert!(csv.lines().next().unwrap().split(',').any(|c| c == "peak_rss_bytes"));
    assert_eq!(
        csv.lines().count(),
        1 + 3 * 4,
        "a row per renderer (and oracle) and frame"
    );
    assert_eq!(image::open(&plot).unwrap().width(), 1100);
}

#[test]
fn compare_over_several_scenes_plots_scaling() {
    let dir = scratch("scaling");
    let (json, scaling) = (dir.join("s.json"), dir.join("s.png"));
    ok(&[
        "compare",
        "--scene",
        "terrain:g=8",
        "--scene",
        "terrain:g=16",
        "--path",
        "circle:2",
        "--algos",
        "frustum",
        "--size",
        "48x32",
        "--json",
        path_arg(&json),
        "--plot-scaling",
        path_arg(&scaling),
    ]);
    let report = read_json(&json);
    let runs = report["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!(runs[1]["scene"]["triangles"], 512);
    // zbuffer was not requested but is the reference: rendered and reported as such.
    let z = &runs[0]["renderers"][0];
    assert_eq!(
        (z["name"].as_str(), z["requested"].as_bool()),
        (Some("zbuffer"), Some(false))
    );
    assert!(image::open(&scaling).is_ok());
}

#[test]
fn compare_without_reference_plots_scaling_against_depth_complexity() {
    let dir = scratch("no-reference");
    let (json, csv, scaling) = (dir.join("n.json"), dir.join("n.csv"), dir.join("n.png"));
    let stdout = ok(&[
        "compare",
        "--scene",
        "chessboard:n=8",
        "--scene",
        "chessboard:n=64",
        "--path",
        "circle:2",
        "--algos",
        "frustum,hzb",
        "--reference",
        "none",
        "--size",
        "48x32",
        "--json",
        path_arg(&json),
        "--csv",
        path_arg(&csv),
        "--plot-scaling",
        path_arg(&scaling),
        "--plot-scaling-x",
        "depth,covered",
    ]);
    assert!(stdout.contains("reference none"), "{stdout}");
    assert!(
        !stdout.lines().any(|l| l.starts_with("oracle")),
        "no oracle row: {stdout}"
    );
    assert!(stdout.contains("depth complexity"), "{stdout}");
    let report = read_json(&json);
    let run = &report["runs"][0];
    assert!(run["reference"].is_null() && run["oracle"].is_null());
    assert_eq!(run["renderers"].as_array().unwrap().len(), 2, "no reference added");
    for r in run["renderers"].as_array().unwrap() {
        assert!(
            r["frames_identical"].is_null(),
            "nothing was checked: {}",
            r["frames_identical"]
        );
    }
    assert_eq!(run["image"]["measured_on"], "frustum");
    assert_eq!(run["image"]["projected_pixels"].as_array().unwrap().len(), 2);
    // The CSV carries every renderer counter as a column, empty where a renderer lacks it.
    let csv = std::fs::read_to_string(&csv).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    assert!(
        header.contains(&"occlusion_tests") && header.contains(&"image_complexity"),
        "{header:?}"
    );
    assert_eq!(
        csv.lines().count(),
        1 + 2 * 2 * 2,
        "a row per scene, renderer and frame, no oracle"
    );
    // Two axes: one plot each from the same run, named after the axis.
    assert!(!scaling.exists());
    assert!(image::open(dir.join("n-depth.png")).is_ok());
    assert!(image::open(dir.join("n-covered.png")).is_ok());
}

#[test]
fn compare_plots_triangles_or_a_counter_per_frame() {
    let dir = scratch("plot-y");
    for what in ["rasterized", "submitted", "occlusion_tests"] {
        let plot = dir.join(format!("{what}.png"));
        ok(&[
            "compare",
            "--scene",
            CITY,
            "--path",
            "circle:2",
            "--algos",
            "frustum,hzb",
            "--size",
            "48x32",
            "--plot",
            path_arg(&plot),
            "--plot-y",
            what,
        ]);
        assert!(image::open(&plot).is_ok(), "{what}");
    }
}

#[test]
fn walk_writes_frames_and_per_frame_stats() {
    let dir = scratch("walk");
    let (frames, csv, json) = (dir.join("frames"), dir.join("w.csv"), dir.join("w.json"));
    ok(&[
        "walk",
        "--scene",
        TERRAIN,
        "--path",
        "circle:3",
        "--size",
        "40x30",
        "--frames-out",
        path_arg(&frames),
        "--csv",
        path_arg(&csv),
        "--json",
        path_arg(&json),
    ]);
    for i in 0..3 {
        let img = image::open(frames.join(format!("frame_{i:05}.png"))).unwrap();
        assert_eq!((img.width(), img.height()), (40, 30));
    }
    assert_eq!(std::fs::read_to_string(&csv).unwrap().lines().count(), 4);
    let report = read_json(&json);
    assert_eq!(report["frames"].as_array().unwrap().len(), 3);
    assert_eq!(report["algorithm"], "frustum");
}

#[test]
fn walk_saves_its_path_and_reads_it_back() {
    let dir = scratch("path-out");
    let (cams, first, again) = (dir.join("street.json"), dir.join("a.json"), dir.join("b.json"));
    let cams_again = dir.join("again.json");
    let walk = |path: &str, json: &std::path::Path, path_out: Option<&std::path::Path>| {
        let mut args = vec![
            "walk",
            "--scene",
            CITY,
            "--path",
            path,
            "--size",
            "40x30",
            "--json",
            path_arg(json),
        ];
        if let Some(p) = path_out {
            args.extend(["--path-out", path_arg(p)]);
        }
        ok(&args);
    };
    walk("street:3", &first, Some(&cams));
    let saved = read_json(&cams);
    assert_eq!(saved.as_array().unwrap().len(), 3);
    assert!(
        saved[0]["eye"].is_array() && saved[0]["fov_y_deg"].is_number(),
        "{saved}"
    );
    walk(path_arg(&cams), &again, Some(&cams_again));
    // Read back, every field of every camera is the same (saved again byte for byte) ...
    assert_eq!(std::fs::read(&cams).unwrap(), std::fs::read(&cams_again).unwrap());
    // ... and the walk sees the same triangles, frame by frame.
    let per_frame = |p: &std::path::Path| -> Vec<(Value, Value)> {
        let report = read_json(p);
        let frames = report["frames"].as_array().unwrap();
        frames
            .iter()
            .map(|f| (f["triangles_submitted"].clone(), f["triangles_visible"].clone()))
            .collect()
    };
    assert_eq!(per_frame(&first), per_frame(&again));
}

#[test]
fn two_outputs_naming_one_file_are_refused() {
    let dir = scratch("same-output");
    let out = dir.join("w.json");
    let dotted = dir.join(".").join("w.json");
    let (code, _, e) = fails(&[
        "walk",
        "--scene",
        TERRAIN,
        "--path",
        "circle:1",
        "--json",
        path_arg(&out),
        "--path-out",
        path_arg(&dotted),
    ]);
    assert_eq!(code, Some(1));
    assert!(e.contains("name the same output file"), "{e}");
    assert!(!out.exists(), "refused before any work");
}

#[test]
fn info_describes_a_scene() {
    let out = ok(&["info", TERRAIN, "--json"]);
    let info: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(info["triangles"], 2 * 24 * 24);
    assert_eq!(info["unique_triangles"], 2 * 24 * 24);
    assert!(info["memory_bytes"].as_u64().unwrap() > 0);
    assert!(info["bounds_min"].as_array().unwrap().len() == 3);
    let text = ok(&["info", CITY]);
    assert!(text.contains("triangles") && text.contains("instances"), "{text}");
    // Variants no instance reaches are not counted: never more unique than instances.
    for spec in ["city:blocks=1", "forest:trees=1,patches=1", CITY] {
        let info: Value = serde_json::from_str(&ok(&["info", spec, "--json"])).unwrap();
        let (unique, all) = (
            info["unique_triangles"].as_u64().unwrap(),
            info["triangles"].as_u64().unwrap(),
        );
        assert!(unique <= all, "{spec}: {unique} unique of {all}");
    }
}

#[test]
fn bad_arguments_fail_before_any_work() {
    let dir = scratch("early");
    let (json, plot) = (dir.join("c.json"), dir.join("c.png"));
    let compare = |extra: &[&str]| {
        let mut args = vec![
            "compare",
            "--scene",
            CITY,
            "--path",
            "circle:2",
            "--size",
            "32x24",
            "--json",
            path_arg(&json),
        ];
        args.extend_from_slice(extra);
        fails(&args)
    };
    // A --plot-y no renderer can report: refused before the run, nothing written.
    let (_, stdout, stderr) = compare(&["--algos", "frustum,hzb", "--plot", path_arg(&plot), "--plot-y", "bogus"]);
    assert!(
        stderr.contains("bogus") && stderr.contains("occlusion_tests"),
        "{stderr}"
    );
    assert!(stdout.is_empty() && !json.exists() && !plot.exists(), "{stdout}");
    // A bad second scene: refused before the first is run.
    let (code, stdout, stderr) = compare(&["--scene", "city:blocks=A"]);
    assert_eq!(code, Some(2), "a usage error: {stderr}");
    assert!(
        stderr.contains("blocks") && stdout.is_empty() && !json.exists(),
        "{stderr}"
    );
    let missing = dir.join("missing.ply");
    let (code, stdout, stderr) = compare(&["--scene", path_arg(&missing)]);
    assert!(
        code == Some(2) && stderr.contains("missing.ply") && stdout.is_empty(),
        "{stderr}"
    );
    // Setting values are checked with the keys, as the command line is parsed.
    for bad in [
        "frustum:leaf=abc",
        "frustum:leaf=0",
        "hzb:temporal=maybe",
        "frustum:bogus=1",
    ] {
        let (code, stdout, stderr) = compare(&["--algos", bad]);
        assert_eq!(code, Some(2), "{bad}: {stderr}");
        assert!(stdout.is_empty() && stderr.contains(bad.split_once(':').unwrap().1.split('=').next().unwrap()));
    }
    let (code, _, stderr) = compare(&["--reference", "frustum:leaf=x"]);
    assert!(code == Some(2) && stderr.contains("leaf=x"), "{stderr}");
    // The same in the other commands.
    let out = dir.join("x.png");
    for args in [
        &["walk", "--scene", CITY, "--algo", "hzb:leaf=-3", "--path", "circle:1"][..],
        &[
            "render",
            "--scene",
            CITY,
            "--out",
            path_arg(&out),
            "--algo",
            "frustum:group_leaf=x",
        ],
        &["render", "--scene", "city:blocks=A", "--out", path_arg(&out)],
        &["walk", "--scene", CITY, "--path", "circle:0"],
    ] {
        let (code, stdout, stderr) = fails(args);
        assert!(code == Some(2) && stdout.is_empty(), "{args:?}: {stderr}");
    }
    let sweep = |extra: &[&str]| {
        let mut args = vec![
            "sweep", "--scene", CITY, "--path", "circle:1", "--size", "32x24", "--algos", "frustum",
        ];
        args.extend_from_slice(extra);
        fails(&args)
    };
    let (_, stdout, stderr) = sweep(&["--vary", "frustum.leaf=8,0"]);
    assert!(stdout.is_empty() && stderr.contains("leaf"), "{stderr}");
    let (_, stdout, stderr) = sweep(&["--vary", "frustum.leaf=8", "--counter", "bogus"]);
    assert!(stdout.is_empty() && stderr.contains("bogus"), "{stderr}");
}

#[test]
fn negative_and_huge_camera_values_get_our_messages() {
    let dir = scratch("camera-values");
    let out = dir.join("x.png");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--scene", TERRAIN, "--size", "32x24", "--out", path_arg(&out)];
        args.extend_from_slice(extra);
        fails(&args).2
    };
    assert!(render(&["--fov", "-10"]).contains("vertical fov -10"));
    assert!(render(&["--fov=-10"]).contains("vertical fov -10"));
    assert!(render(&["--near", "-1"]).contains("near plane -1"));
    assert!(render(&["--far", "-2"]).contains("far plane -2"));
    let e = render(&["--eye", "3e38,0,0", "--target", "-3e38,0,0"]);
    assert!(e.contains("too large") && !e.contains("coincide"), "{e}");
    // As --path circle:0, --view circle:0 is refused (not read as camera 0 of `circle`).
    let e = render(&["--view", "circle:0"]);
    assert!(e.contains("circle:0") && e.contains("at least one view"), "{e}");
    let e = fails(&["walk", "--scene", TERRAIN, "--path", "circle:0"]).2;
    assert!(e.contains("at least one view"), "{e}");
    // A distant eye is a valid camera, not a coincident one.
    ok(&[
        "render",
        "--scene",
        TERRAIN,
        "--size",
        "32x24",
        "--out",
        path_arg(&out),
        "--eye",
        "1e30,0,0",
    ]);
}

#[test]
fn model_files_get_a_working_default_camera_and_clear_header_errors() {
    let dir = scratch("models");
    let json = dir.join("r.json");
    let render = |name: &str, text: &str| {
        let model = dir.join(name);
        std::fs::write(&model, text).unwrap();
        let out = dir.join("x.png");
        ok(&[
            "render",
            "--scene",
            path_arg(&model),
            "--algo",
            "zbuffer",
            "--size",
            "64x48",
            "--out",
            path_arg(&out),
            "--json",
            path_arg(&json),
        ]);
        read_json(&json)["covered_pixels"].as_u64().unwrap()
    };
    // Coordinates of ±1e20: the default camera frames them.
    assert!(render("huge.obj", "v -1e20 -1e20 0\nv 1e20 -1e20 0\nv 0 1e20 1e20\nf 1 2 3\n") > 0);
    // A triangle in the yz plane: the default camera does not look along its plane.
    assert!(render("yz.obj", "v 0 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n") > 0);
    // A PLY header error: one line naming the file, line, column and what was expected.
    let ply = dir.join("typo.ply");
    std::fs::write(&ply, "ply\nformat ascii 1.0\nelment vertex 3\nend_header\n").unwrap();
    let e = fails(&["info", path_arg(&ply)]).2;
    assert!(
        e.contains("typo.ply line 3, column 1: bad header: cannot parse line 'elment vertex 3': expected one of"),
        "{e}"
    );
    assert!(!e.contains("ParseError") && !e.contains('{'), "{e}");
}

#[test]
fn scenes_lists_generators_and_parameters() {
    let out = ok(&["scenes"]);
    for name in ["terrain", "city", "g=", "blocks="] {
        assert!(out.contains(name), "{name} missing from:\n{out}");
    }
    let list: Value = serde_json::from_str(&ok(&["scenes", "--json"])).unwrap();
    assert!(list
        .as_array()
        .unwrap()
        .iter()
        .any(|g| g["name"] == "city" && !g["parameters"].as_array().unwrap().is_empty()));
}

#[test]
fn bad_input_is_one_line_and_a_nonzero_status() {
    let dir = scratch("bad");
    let out = dir.join("x.png");
    let out = path_arg(&out);
    let missing_obj = dir.join("missing.obj");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["render", "--scene", TERRAIN, "--out", out, "--size", "0x0"], "0x0"),
        (
            vec!["render", "--scene", TERRAIN, "--out", out, "--size", "99999x99999"],
            "99999",
        ),
        (vec!["render", "--scene", TERRAIN, "--out", out, "--size", "abc"], "WxH"),
        (
            vec!["render", "--scene", TERRAIN, "--out", out, "--algo", "warp"],
            "zbuffer",
        ),
        (vec!["compare", "--scene", TERRAIN, "--algos", "zbuffer,warp"], "warp"),
        (vec!["render", "--scene", "nosuchscene", "--out", out], "terrain"),
        (
            vec!["render", "--scene", path_arg(&missing_obj), "--out", out],
            "missing.obj",
        ),
        (vec!["info", path_arg(&missing_obj)], "missing.obj"),
        (vec!["compare", "--scene", TERRAIN, "--path", "wobble:3"], "wobble"),
        (vec!["walk", "--scene", TERRAIN, "--path", "circle:0"], "circle:0"),
        (
            vec!["render", "--scene", TERRAIN, "--out", out, "--view", "circle:4:9"],
            "index 9",
        ),
        (
            vec![
                "render", "--scene", TERRAIN, "--out", out, "--eye", "1,2,3", "--target", "1,2,3",
            ],
            "camera",
        ),
        (
            vec!["render", "--scene", TERRAIN, "--out", out, "--eye", "nan,0,0"],
            "finite",
        ),
        (vec!["render", "--scene", "terrain:g=0", "--out", out], "g"),
        (
            vec!["render", "--scene", TERRAIN, "--out", "/no/such/dir/x.png"],
            "does not exist",
        ),
        (
            vec!["compare", "--scene", TERRAIN, "--plot-scaling", out],
            "two or more",
        ),
        (vec!["--threads", "0", "scenes"], "thread"),
        (
            vec![
                "compare",
                "--scene",
                TERRAIN,
                "--path",
                "circle:1",
                "--reference",
                "rzb",
            ],
            "conservative",
        ),
        (vec!["compare", "--scene", TERRAIN, "--reference", "warp"], "warp"),
        (
            vec!["compare", "--scene", TERRAIN, "--plot-scaling-x", "colour"],
            "colour",
        ),
        (
            vec![
                "compare", "--scene", TERRAIN, "--path", "circle:1", "--algos", "frustum", "--size", "16x16", "--plot",
                out, "--plot-y", "bogus",
            ],
            "bogus",
        ),
        (vec!["render", "--scene", TERRAIN], "--out"),
        (vec!["frobnicate"], "frobnicate"),
    ];
    for (args, needle) in cases {
        let o = occult(&args);
        let stderr = text(&o.stderr);
        let code = o.status.code();
        assert!(
            matches!(code, Some(1) | Some(2)),
            "occult {args:?}: status {code:?}, stderr:\n{stderr}"
        );
        assert!(!stderr.contains("panicked"), "occult {args:?} panicked:\n{stderr}");
        let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "occult {args:?}: expected one line, got:\n{stderr}");
        assert!(lines[0].starts_with("error: "), "{stderr}");
        assert!(
            lines[0].contains(needle),
            "occult {args:?}: '{needle}' not in: {stderr}"
        );
    }
}

#[test]
fn help_and_version_succeed() {
    assert!(ok(&["--help"]).contains("compare"));
    assert!(ok(&["compare", "--help"]).contains("--plot-scaling"));
    assert!(ok(&["--version"]).contains("occult"));
}

#[test]
fn algos_lists_every_renderer_with_its_parameters() {
    let stdout = ok(&["algos"]);
    assert!(
        stdout.contains("zbuffer") && stdout.contains("group_leaf=4"),
        "{stdout}"
    );
    let json: Value = serde_json::from_str(&ok(&["algos", "--json"])).unwrap();
    let names: Vec<&str> = json
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert!(names.contains(&"zbuffer") && names.contains(&"frustum"), "{names:?}");
}

#[test]
fn compare_takes_several_configurations_of_one_renderer() {
    let dir = scratch("compare-specs");
    let json = dir.join("c.json");
    ok(&[
        "compare",
        "--scene",
        CITY,
        "--path",
        "street:3",
        "--size",
        "64x48",
        "--algos",
        "frustum,frustum:leaf=8,group_leaf=1",
        "--json",
        path_arg(&json),
    ]);
    let v = read_json(&json);
    let names: Vec<&str> = v["runs"][0]["renderers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["zbuffer", "frustum", "frustum:leaf=8,group_leaf=1"]);
    for r in v["runs"][0]["renderers"].as_array().unwrap() {
        assert_eq!(r["frames_identical"], 3, "{}", r["name"]);
        // Without --peak-rss the process's memory is not measured.
        assert!(r["peak_rss_bytes"].is_null(), "{}", r["name"]);
    }
    assert!(v["runs"][0]["process_peak_rss_bytes"].is_null());
}

#[test]
fn compare_writes_images_of_where_frames_differ() {
    let dir = scratch("compare-diff");
    let diffs = dir.join("diffs");
    let out = ok(&[
        "compare",
        "--scene",
        CITY,
        "--path",
        "circle:2",
        "--size",
        "64x48",
        "--algos",
        "frustum,rzb:large=off",
        "--diff-out",
        path_arg(&diffs),
    ]);
    let mut names: Vec<String> = std::fs::read_dir(&diffs)
        .expect("the directory was made")
        .map(|e| e.expect("an entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    // frustum is identical to the reference: no image of it.
    assert_eq!(
        names,
        ["rzb_large_off-frame_00000.png", "rzb_large_off-frame_00001.png"],
        "{out}"
    );
    let image = image::open(diffs.join(&names[0])).expect("a PNG").to_rgba8();
    assert_eq!(image.dimensions(), (64, 48));
    assert!(image
        .pixels()
        .any(|p| p.0 == [255, 0, 0, 255] || p.0 == [255, 200, 0, 255]));
    assert!(out.contains("wrote 2 images of differing frames"), "{out}");
    // A file where the directory should be: one line, non-zero.
    let file = dir.join("taken");
    std::fs::write(&file, b"x").expect("a file");
    let (code, _, err) = fails(&[
        "compare",
        "--scene",
        CITY,
        "--path",
        "circle:1",
        "--size",
        "16x16",
        "--algos",
        "rzb",
        "--diff-out",
        path_arg(&file),
    ]);
    assert_eq!(code, Some(1));
    assert!(err.contains("taken") && err.trim().lines().count() == 1, "{err}");
}

#[test]
fn sweep_varies_a_parameter_and_plots_it() {
    let dir = scratch("sweep");
    let (csv, plot, json) = (dir.join("s.csv"), dir.join("s.png"), dir.join("s.json"));
    ok(&[
        "sweep",
        "--scene",
        CITY,
        "--path",
        "street:2",
        "--size",
        "64x48",
        "--algos",
        "zbuffer,frustum:group_leaf=2",
        "--vary",
        "frustum.leaf=4,64",
        "--csv",
        path_arg(&csv),
        "--plot",
        path_arg(&plot),
        "--json",
        path_arg(&json),
    ]);
    let rows = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(rows.lines().count(), 1 + 2 * 2, "{rows}");
    assert!(rows.contains("frustum:group_leaf=2,leaf=64"), "{rows}");
    assert!(image::open(&plot).is_ok());
    assert_eq!(read_json(&json)["points"].as_array().unwrap().len(), 2);
    for bad in [
        &["--vary", "frustum.leaf=0,8"][..],
        &["--vary", "hzb.leaf=8"],
        &["--vary", "frustum.leaves=8"],
        &["--vary", "frustum.leaf=a"],
    ] {
        let mut args = vec![
            "sweep", "--scene", CITY, "--path", "street:2", "--size", "64x48", "--algos", "frustum",
        ];
        args.extend_from_slice(bad);
        let out = occult(&args);
        assert!(!out.status.success(), "{bad:?} succeeded");
        let err = text(&out.stderr);
        assert!(
            !err.contains("panicked") && err.trim().lines().count() == 1,
            "{bad:?}: {err}"
        );
    }
}

/// Without the `view` feature, `occult view` says on one line how to get it.
#[cfg(not(feature = "view"))]
#[test]
fn view_without_the_feature_names_it() {
    let (code, _, stderr) = fails(&["view", TERRAIN]);
    assert_eq!(code, Some(1));
    assert!(stderr.contains("--features view"), "{stderr}");
}
