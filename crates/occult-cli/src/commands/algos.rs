//! `occult algos`: the renderers and their parameters, from the registry.

use anyhow::Result;
use occult_render::ALGORITHMS;
use serde::Serialize;

use crate::args::AlgosArgs;

#[derive(Serialize)]
struct ParamOut {
    name: &'static str,
    default: &'static str,
    meaning: &'static str,
}

#[derive(Serialize)]
struct AlgorithmOut {
    name: &'static str,
    description: &'static str,
    conservative: bool,
    parameters: Vec<ParamOut>,
}

/// Runs the command.
pub fn run(a: AlgosArgs) -> Result<()> {
    if a.json {
        let out: Vec<AlgorithmOut> = ALGORITHMS
            .iter()
            .map(|i| AlgorithmOut {
                name: i.name,
                description: i.summary,
                conservative: i.conservative,
                parameters: i
                    .params
                    .iter()
                    .map(|p| ParamOut {
                        name: p.key,
                        default: p.default,
                        meaning: p.help,
                    })
                    .collect(),
            })
            .collect();
        say!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    say!("Renderers: use as --algo NAME or NAME:key=value,key=value; --algos takes a comma-separated list of these\n");
    for i in ALGORITHMS {
        let kind = if i.conservative { "exact" } else { "approximate" };
        say!("{}  ({kind}) {}", i.name, i.summary);
        let width = i
            .params
            .iter()
            .map(|p| p.key.len() + p.default.len() + 1)
            .max()
            .unwrap_or(0);
        for p in i.params {
            let kv = format!("{}={}", p.key, p.default);
            say!("    {kv:<width$}  {}", p.help);
        }
        say!();
    }
    Ok(())
}
