//! Replays the committed fuzz corpus (`fuzz/corpus/<target>/`, a minimized set of the inputs
//! the campaigns found interesting) through the targets on stable: no input may panic, and an
//! error must name the file (`Target::run` asserts both). `OCCULT_FUZZ_CORPUS` points it at
//! another folder of the same layout (a campaign's working corpus, a seed folder).

use std::path::PathBuf;
use std::time::Instant;

use occult_fuzz::Target;

#[test]
fn every_corpus_input_loads_or_fails_cleanly() {
    let root = std::env::var_os("OCCULT_FUZZ_CORPUS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus"));
    for target in Target::ALL {
        let dir = root.join(target.name());
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|entry| entry.expect("directory entry").path())
            .collect();
        files.sort();
        assert!(!files.is_empty(), "{}: no corpus inputs", dir.display());
        let (mut loaded, mut refused) = (0usize, 0usize);
        let start = Instant::now();
        for file in &files {
            let input = std::fs::read(file).expect("read corpus input");
            let outcome = std::panic::catch_unwind(|| target.run(&input).is_ok());
            match outcome {
                Ok(true) => loaded += 1,
                Ok(false) => refused += 1,
                Err(_) => panic!("{}: the {} target panicked on it", file.display(), target.name()),
            }
        }
        println!(
            "{}: {} inputs, {loaded} loaded, {refused} refused, {:.2?}",
            target.name(),
            files.len(),
            start.elapsed()
        );
    }
}
