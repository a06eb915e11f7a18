//! `occult algos`: the renderers and their parameters, from the registry.

use anyhow::Result;
use occult_render::{Algorithm, ALGORITHMS};
use serde::Serialize;

use crate::args::AlgosArgs;
use crate::output::{self, ParamOut};

#[derive(Serialize)]
struct AlgorithmOut {
    name: &'static str,
    description: &'static str,
    conservative: bool,
    parameters: Vec<ParamOut>,
}

/// Runs the command.
pub fn run(a: AlgosArgs) -> Result<()> {
    let out: Vec<AlgorithmOut> = ALGORITHMS
        .iter()
        .map(|i| AlgorithmOut {
            name: i.name,
            description: i.summary,
            conservative: i.conservative,
            parameters: Algorithm::parse(i.name)
                .map(Algorithm::params)
                .unwrap_or_default()
                .iter()
                .map(|p| ParamOut::new(p.key, p.default, p.help))
                .collect(),
        })
        .collect();
    if a.json {
        say!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    say!("Renderers: use as --algo NAME or NAME:key=value,key=value; --algos takes a comma-separated list of these\n");
    for i in &out {
        let kind = if i.conservative { "exact" } else { "approximate" };
        say!("{}  ({kind}) {}", i.name, i.description);
        say!("{}", output::param_lines(&i.parameters));
    }
    Ok(())
}
