//! `occult` under `mpirun` (feature `mpi`): frames identical to the single process's on every
//! generator at 1, 2 and 4 ranks; `compare` and `walk` unchanged, with the ranks' times in
//! their reports; a failed rank ends the run with one error from rank 0. Each test says why
//! and passes when `mpirun` is absent.

use std::process::{Command, Output};

use super::{path_arg, read_json, scratch, text};

/// Scenes of every generator, small enough for 4 ranks on 2 cores.
const SCENES: &[&str] = &[
    "terrain:g=24",
    "terrain:g=8,tiles=3",
    "city:blocks=2,detail=1",
    "forest:trees=2,patches=2,levels=1",
    "chessboard:n=20",
    "plant:units=1,floors=2,pipes=6,sides=6",
    "occluder:objects=3",
];

fn mpirun_present() -> bool {
    let found = Command::new("mpirun")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        eprintln!("skipped: mpirun is not installed (apt-get install openmpi-bin libopenmpi-dev)");
    }
    found
}

/// `occult ARGS` on `ranks` MPI ranks, one rasterizer thread each.
fn mpirun(ranks: usize, args: &[&str]) -> Output {
    Command::new("mpirun")
        .args(["-np", &ranks.to_string(), "--oversubscribe", "--allow-run-as-root"])
        .arg(env!("CARGO_BIN_EXE_occult"))
        .args(["--threads", "1"])
        .args(args)
        .output()
        .expect("mpirun runs")
}

#[test]
fn render_under_mpirun_is_identical_on_every_generator() {
    if !mpirun_present() {
        return;
    }
    let dir = scratch("mpi-render");
    for (s, scene) in SCENES.iter().enumerate() {
        let single = dir.join(format!("{s}-single.png"));
        let single_depth = dir.join(format!("{s}-single-depth.png"));
        let base = ["render", "--scene", scene, "--algo", "zbuffer", "--size", "96x64"];
        let out = Command::new(env!("CARGO_BIN_EXE_occult"))
            .args(base)
            .args(["--out", path_arg(&single), "--depth-out", path_arg(&single_depth)])
            .output()
            .expect("occult runs");
        assert!(out.status.success(), "{scene}: {}", text(&out.stderr));
        for ranks in [1, 2, 4] {
            for algo in ["zbuffer", "frustum"] {
                let color = dir.join(format!("{s}-{ranks}-{algo}.png"));
                let depth = dir.join(format!("{s}-{ranks}-{algo}-depth.png"));
                let mut args = base.to_vec();
                args[4] = algo;
                args.extend(["--out", path_arg(&color), "--depth-out", path_arg(&depth)]);
                let out = mpirun(ranks, &args);
                assert!(out.status.success(), "{scene}, {ranks} ranks: {}", text(&out.stderr));
                let same = |a: &std::path::Path, b: &std::path::Path| {
                    std::fs::read(a).expect("written") == std::fs::read(b).expect("written")
                };
                assert!(same(&color, &single), "{scene}, {algo}, {ranks} ranks: color differs");
                assert!(
                    same(&depth, &single_depth),
                    "{scene}, {algo}, {ranks} ranks: depth differs"
                );
                // Rank 0 alone prints: one statistics block.
                let stdout = text(&out.stdout);
                assert_eq!(stdout.matches("wrote").count(), 2, "{stdout}");
            }
        }
    }
}

#[test]
fn compare_and_walk_under_mpirun_report_the_ranks() {
    if !mpirun_present() {
        return;
    }
    let dir = scratch("mpi-compare");
    let json = dir.join("c.json");
    let out = mpirun(
        2,
        &[
            "compare",
            "--scene",
            "city:blocks=2,detail=1",
            "--algos",
            "zbuffer,frustum,hzb",
            "--path",
            "circle:3",
            "--size",
            "96x64",
            "--json",
            path_arg(&json),
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report = read_json(&json);
    let text_json = report.to_string();
    assert!(text_json.contains("mpi_ranks"), "the ranks' counters are reported");
    assert!(text_json.contains("mpi_rank1_render_us") && text_json.contains("mpi_comm_us"));
    let csv = dir.join("w.csv");
    let out = mpirun(
        2,
        &[
            "walk",
            "--scene",
            "terrain:g=24",
            "--algo",
            "zbuffer",
            "--path",
            "circle:3",
            "--size",
            "96x64",
            "--csv",
            path_arg(&csv),
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let csv = std::fs::read_to_string(&csv).expect("written");
    assert!(
        csv.lines().next().is_some_and(|h| h.contains("mpi_rank1_render_us")),
        "{csv}"
    );
    assert_eq!(csv.lines().count(), 4, "a header and three frames, written once");
}

#[test]
fn a_failed_rank_ends_the_run_with_one_error() {
    if !mpirun_present() {
        return;
    }
    let dir = scratch("mpi-fail");
    let png = dir.join("x.png");
    // A scene file that does not exist: every rank fails to load it; one error.
    let out = mpirun(
        2,
        &[
            "render",
            "--scene",
            "/nonexistent/scene.obj",
            "--size",
            "32x32",
            "--out",
            path_arg(&png),
        ],
    );
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert_eq!(stderr.matches("error:").count(), 1, "{stderr}");
    assert!(stderr.contains("scene.obj"), "{stderr}");
    // One rank alone fails to build its renderer: rank 0 names it, nobody hangs.
    let out = Command::new("mpirun")
        .args([
            "-np",
            "2",
            "--oversubscribe",
            "--allow-run-as-root",
            "-x",
            "OCCULT_MPI_FAIL_RANK=1",
        ])
        .arg(env!("CARGO_BIN_EXE_occult"))
        .args([
            "render",
            "--scene",
            "terrain:g=8",
            "--size",
            "32x32",
            "--out",
            path_arg(&png),
        ])
        .output()
        .expect("mpirun runs");
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert_eq!(stderr.matches("error:").count(), 1, "{stderr}");
    assert!(stderr.contains("rank 1 of 2"), "{stderr}");
}

/// `occult ARGS` on `ranks` MPI ranks with `OCCULT_MPI_FAIL_RANK=fault`, ended by `timeout`
/// if it has not finished in 300 s (it takes a second or two): a hang fails the test instead
/// of stopping the test run. `timeout` sends `mpirun` a SIGTERM, which `mpirun` passes on to
/// its ranks.
fn mpirun_failing(ranks: usize, fault: &str, args: &[&str]) -> Output {
    let out = Command::new("timeout")
        .args(["--kill-after=10", "300", "mpirun"])
        .args(["-np", &ranks.to_string(), "--oversubscribe", "--allow-run-as-root"])
        .args(["-x", &format!("OCCULT_MPI_FAIL_RANK={fault}")])
        .arg(env!("CARGO_BIN_EXE_occult"))
        .args(["--threads", "1"])
        .args(args)
        .output()
        .expect("timeout and mpirun run");
    assert_ne!(
        out.status.code(),
        Some(124),
        "fault {fault}: the ranks hung (ended by timeout): {}",
        text(&out.stderr)
    );
    out
}

#[test]
fn a_rank_that_fails_mid_frame_ends_the_run_with_one_error() {
    if !mpirun_present() {
        return;
    }
    let walk = |algo: &'static str| {
        [
            "walk",
            "--scene",
            "terrain:g=8",
            "--algo",
            algo,
            "--path",
            "circle:3",
            "--size",
            "32x32",
        ]
    };
    let lzb = walk("lzb:payoff=off");
    let mut parallel_lzb = vec!["--mpi-lzb"];
    parallel_lzb.extend(lzb);
    // The parallel local z-buffer: rank 0 fails before the depth broadcast of frame 1 (the
    // others waited for it there), rank 1 before the PVL gather (rank 0 waited for it);
    // sort-last: rank 1 fails after compositing frame 1.
    let cases: [(usize, &str, &[&str]); 4] = [
        (2, "0:1:1", &parallel_lzb),
        (2, "1:1:2", &parallel_lzb),
        (4, "3:1:1", &parallel_lzb),
        (2, "1:1:1", &walk("zbuffer")),
    ];
    for (ranks, fault, args) in cases {
        let out = mpirun_failing(ranks, fault, args);
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "fault {fault}: {stderr}");
        assert_eq!(stderr.matches("error:").count(), 1, "fault {fault}: {stderr}");
        let rank = fault.split(':').next().expect("a rank");
        assert!(
            stderr.contains(&format!("rank {rank} of {ranks}: failure injected for a test (frame 1")),
            "fault {fault}: {stderr}"
        );
    }
}
