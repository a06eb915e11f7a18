//! `occult scenes`: the built-in generators and their parameters.

use anyhow::Result;
use serde::Serialize;

use crate::args::ScenesArgs;
use crate::output::{self, ParamOut};

#[derive(Serialize)]
struct GeneratorOut {
    name: &'static str,
    description: &'static str,
    parameters: Vec<ParamOut>,
}

/// Runs the command.
pub fn run(a: ScenesArgs) -> Result<()> {
    let out: Vec<GeneratorOut> = occult_scenes::spec::generators()
        .iter()
        .map(|g| GeneratorOut {
            name: g.name,
            description: g.description,
            parameters: g
                .params
                .iter()
                .map(|p| ParamOut::new(p.name, p.default, p.meaning))
                .collect(),
        })
        .collect();
    if a.json {
        say!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    say!("Scene generators: use as --scene NAME or NAME:key=value,key=value (a file path loads .obj, .ply, .gltf, .glb)\n");
    for g in &out {
        say!("{}  {}", g.name, g.description);
        say!("{}", output::param_lines(&g.parameters));
    }
    say!("Camera paths (--path, --view): circle:N, street:N, flyover:N, default, or a JSON file of cameras");
    Ok(())
}
