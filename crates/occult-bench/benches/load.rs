//! Load speed of the file loaders, in MB/s of input on one thread: OBJ, PLY ascii, PLY binary
//! (both byte orders) and GLB, on a mesh of 524,288 triangles (a 512 × 512 height field) that
//! the bench writes with `occult_scenes::save`; and on the real models of `OCCULT_MODELS` when
//! it is set. Files are read into memory first: the figures are parsing and mesh building, not
//! the disk. Goals (issue 25): OBJ and ascii PLY ≥ 100 MB/s, binary PLY and GLB ≥ 1 GB/s.

use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occult_scenes::load::load_bytes;

fn bench_load(c: &mut Criterion, group_name: &str, files: &[(String, PathBuf, Vec<u8>)]) {
    let mut group = c.benchmark_group(group_name);
    group.sample_size(10);
    for (name, path, bytes) in files {
        group.throughput(Throughput::Bytes(bytes.len() as u64));
        group.bench_function(name.as_str(), |b| {
            b.iter(|| load_bytes(path, bytes).expect("the bench's files load"));
        });
    }
    group.finish();
}

fn generated(c: &mut Criterion) {
    let files = occult_bench::load_grid_files();
    for (name, _, bytes) in &files {
        eprintln!("load/{name}: {:.1} MB", bytes.len() as f64 / 1e6);
    }
    bench_load(c, "load_grid_524k", &files);
}

/// The real models (OBJ and PLY files directly under each folder of `OCCULT_MODELS`).
fn real_models(c: &mut Criterion) {
    let Some(root) = std::env::var_os("OCCULT_MODELS") else {
        eprintln!("load: OCCULT_MODELS not set; the real models are not measured");
        return;
    };
    let files = occult_bench::model_files(Path::new(&root));
    bench_load(c, "load_models", &files);
}

criterion_group!(benches, generated, real_models);
criterion_main!(benches);
