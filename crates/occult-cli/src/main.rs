//! # occult
//!
//! The command-line tool: parses arguments, validates them into a configuration, and calls the
//! libraries (`occult-scenes` for scenes and camera paths, `occult-render` for renderers and the
//! comparison harness). Everything it knows of algorithms is their names.
//!
//! | command | does |
//! | --- | --- |
//! | `occult render` | one frame to PNG (color, optional depth), its statistics |
//! | `occult walk` | a camera path with one renderer: per-frame statistics, optional PNGs |
//! | `occult compare` | several renderers on the same scenes and path: table, JSON, CSV, plots |
//! | `occult info` | what a scene file or spec holds |
//! | `occult scenes` | the built-in generators and their parameters |
//! | `occult particles` | sprites among a scene, culled with an N-buffer or not |
//! | `occult shadows` | spot-light shadow volumes, clamped with litmaps and N-buffers or not |
//! | `occult suite` | the performance yardstick: every renderer on a fixed, versioned matrix of cases |
//! | `occult view` | a window (feature `view`): fly through a scene, switch renderers live |
//! | `occult mpi-model` | sort-last compositing's communication per frame and rank, measured and modelled |
//!
//! Under `mpirun` (feature `mpi`) `render`, `walk` and `compare` run unchanged on every rank,
//! their renderers sort-last over the ranks (`--mpi-lzb`: `lzb` as the paper's parallel local
//! z-buffer); rank 0 alone prints and writes.
//!
//! Default sizes: 1920x1080 for `render` (a picture to look at), 640x480 for `walk` and
//! `compare` (many frames, several renderers; brute force must stay bearable); `suite` fixes its
//! own (1280x720, 640x360 with `--quick`) so that its figures compare across commits.
//!
//! Errors: one line on stderr, `error: ` and the cause chain joined by `: `; exit status 1, or 2
//! for usage errors (clap's convention). Never a panic trace for bad input.

#[macro_use]
mod output;
mod args;
mod commands;
mod plot;
mod progress;
mod ranks;
mod scene;
#[cfg(feature = "view")]
mod view;

use std::process::ExitCode;

use clap::Parser;

use crate::args::{Cli, Command};

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    install_panic_hook();
    // Under `mpirun` (feature `mpi`): this rank's communicator, dropped (MPI finalised) last.
    let comm = match ranks::start() {
        Ok(comm) => comm,
        Err(e) => {
            eprintln!("error: cannot start MPI: {}", one_line(&e));
            return ExitCode::from(1);
        }
    };
    let code = match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        // The reader of our stdout went away (`occult compare ... | head`): not an error.
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            if ranks::is_root() {
                eprintln!("error: {}", one_line(&e));
            }
            if let Some(comm) = &comm {
                // An error every rank has ends every rank alike; one of this rank alone ends
                // the run at once, as the others may be waiting on this rank.
                if !ranks::is_agreed(&e) {
                    if !ranks::is_root() {
                        eprintln!("error: rank {} of {}: {}", comm.rank(), comm.size(), one_line(&e));
                    }
                    ranks::abort(comm);
                }
            }
            ExitCode::from(1)
        }
    };
    drop(comm);
    code
}

fn run(cli: Cli) -> anyhow::Result<()> {
    ranks::set_parallel_lzb(cli.mpi_lzb);
    if let Some(threads) = cli.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .map_err(|e| anyhow::anyhow!("cannot start {threads} worker threads: {e}"))?;
    }
    match cli.command {
        Command::Render(a) => commands::render::run(a),
        Command::Walk(a) => commands::walk::run(a),
        Command::Compare(a) => commands::compare::run(a),
        Command::Info(a) => commands::info::run(a),
        Command::Scenes(a) => commands::scenes::run(a),
        Command::Algos(a) => commands::algos::run(a),
        Command::Sweep(a) => commands::sweep::run(a),
        Command::Particles(a) => commands::particles::run(a),
        Command::Shadows(a) => commands::shadows::run(a),
        Command::Suite(a) => commands::suite::run(a),
        #[cfg(feature = "view")]
        Command::View(a) => view::run(a),
        #[cfg(not(feature = "view"))]
        Command::View { .. } => anyhow::bail!(
            "this occult was built without the viewer: build it with `cargo build --release -p occult-cli --features view`"
        ),
        Command::MpiModel(a) => commands::mpi_model::run(a),
    }
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// A panic is a bug, never the answer to bad input; should one happen, say so on one line
/// (with its location) instead of a trace, unless RUST_BACKTRACE asks for the trace.
fn install_panic_hook() {
    if std::env::var_os("RUST_BACKTRACE").is_some_and(|v| v != "0") {
        return;
    }
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown cause".into());
        let location = info
            .location()
            .map_or(String::new(), |l| format!(" at {}:{}", l.file(), l.line()));
        let message = message.split_whitespace().collect::<Vec<_>>().join(" ");
        eprintln!("error: internal error (a bug in occult, please report it): {message}{location}");
    }));
}

/// Help and version go to stdout as clap writes them; a usage error becomes one line on stderr
/// (clap's first line, which names the argument and the problem) and exit status 2.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    // Under `mpirun` every rank parses the same arguments: rank 0 alone speaks.
    if ranks::launcher_rank() != 0 {
        return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
    }
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        let _ = e.print();
        return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
    }
    // Clap's first paragraph says what is wrong (a missing argument is on its second line);
    // the tips and the usage follow after a blank line.
    let text = e.to_string();
    let first: Vec<&str> = text.lines().map(str::trim).take_while(|l| !l.is_empty()).collect();
    let mut message = first.join(" ");
    if message.is_empty() {
        message = "error: bad arguments".into();
    } else if !message.starts_with("error:") {
        message = format!("error: {message}");
    }
    eprintln!("{message} (see 'occult --help')");
    ExitCode::from(2)
}

/// The error and its causes on one line, joined by `: `. A cause whose text its parent already
/// ends with (errors that print their source inline) is not repeated.
fn one_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
        if text.is_empty() || line.ends_with(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chains_join_without_repeats() {
        #[derive(Debug)]
        struct Inner;
        impl std::fmt::Display for Inner {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "degenerate camera: eye and target coincide")
            }
        }
        impl std::error::Error for Inner {}
        #[derive(Debug)]
        struct Outer(Inner);
        impl std::fmt::Display for Outer {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "view 3: {}", self.0)
            }
        }
        impl std::error::Error for Outer {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.0)
            }
        }
        let e = anyhow::Error::new(Outer(Inner)).context("compare\nfailed");
        assert_eq!(
            one_line(&e),
            "compare failed: view 3: degenerate camera: eye and target coincide"
        );
    }
}
