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
    let generators = occult_scenes::spec::generators();
    if a.json {
        let out: Vec<GeneratorOut> = generators
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
        say!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    say!("Scene generators: use as --scene NAME or NAME:key=value,key=value (a file path loads .obj, .ply, .gltf, .glb)\n");
    for g in generators {
        say!("{}  {}", g.name, g.description);
        let params: Vec<ParamOut> = g
            .params
            .iter()
            .map(|p| ParamOut::new(p.name, p.default, p.meaning))
            .collect();
        say!("{}", output::param_lines(&params));
    }
    say!("Camera paths (--path, --view): circle:N, street:N, flyover:N, default, or a JSON file of cameras");
    Ok(())
}
