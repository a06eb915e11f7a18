//! Loads the real models in the folder named by `OCCULT_MODELS` (CI points it at
//! `/work/shared/models`) and checks their triangle counts. Without the variable the test prints a
//! note and passes, so that the project's own tests never need the models.
//!
//! ```text
//! OCCULT_MODELS=/work/shared/models cargo test -p occult-scenes --release --test scenes -- models:: --nocapture
//! ```

use std::path::{Path, PathBuf};
use std::time::Instant;

use occult_scenes::load::{load_file, Format};

/// Triangle instances (fan-triangulated) of the models in `/work/shared/models/README.md`.
const EXPECTED_ITEM_COUNTS: [(&str, u64); 6] = [
    ("stanford-bunny/bun_zipper.ply", 69_451),
    ("stanford-armadillo/Armadillo.ply", 345_944),
    ("dabrovic-sponza/sponza.obj", 66_450),
    ("lost-empire/lost_empire.obj", 224_998),
    ("scrub-pine/scrubPine.obj", 527),
    ("fandisk/fandisk.obj", 12_946),
];

/// Every loadable file under `folder`, recursively, sorted.
fn model_files(folder: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut pending = vec![folder.to_path_buf()];
    while let Some(dir) = pending.pop() {
        let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                pending.push(path);
            } else if Format::from_path(&path).is_some() {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

#[test]
fn real_models_load_with_expected_triangle_counts() {
    let Some(folder) = std::env::var_os("OCCULT_MODELS") else {
        println!("note: OCCULT_MODELS is not set; real-model loading not tested");
        return;
    };
    let folder = PathBuf::from(folder);
    let files = model_files(&folder);
    assert!(
        !files.is_empty(),
        "no .obj/.ply/.gltf/.glb file under {}",
        folder.display()
    );

    let mut failures = Vec::new();
    let mut found = Vec::new();
    for file in &files {
        let relative = file
            .strip_prefix(&folder)
            .unwrap_or(file)
            .to_string_lossy()
            .replace('\\', "/");
        let start = Instant::now();
        let loaded = match load_file(file) {
            Ok(loaded) => loaded,
            Err(e) => {
                failures.push(format!("{relative}: {e}"));
                continue;
            }
        };
        let seconds = start.elapsed().as_secs_f64();
        let scene = &loaded.scene;
        println!(
            "{relative}: {} triangles, {} nodes, {} warnings, loaded in {seconds:.3} s",
            scene.item_count(),
            scene.nodes().len(),
            loaded.warnings.len()
        );
        for warning in &loaded.warnings {
            println!("    warning: {warning}");
        }
        assert!(!scene.bounds().is_empty(), "{relative}: empty bounds");
        if let Some(&(_, expected)) = EXPECTED_ITEM_COUNTS.iter().find(|(name, _)| *name == relative) {
            found.push(relative.clone());
            if scene.item_count() != expected {
                failures.push(format!(
                    "{relative}: {} triangles, expected {expected}",
                    scene.item_count()
                ));
            }
        }
    }
    for (name, _) in EXPECTED_ITEM_COUNTS {
        if !found.iter().any(|f| f == name) {
            failures.push(format!(
                "{name}: expected under {} but not found (or not loaded)",
                folder.display()
            ));
        }
    }
    assert!(failures.is_empty(), "model failures:\n{}", failures.join("\n"));
}
