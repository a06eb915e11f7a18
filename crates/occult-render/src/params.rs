//! Algorithm specs: a renderer's name with its settings, `hzb:leaf=64,temporal=off`, the same
//! syntax as scene specs, so that every parameter of every renderer is settable from the command
//! line and several configurations of one renderer can be compared in one run.
//!
//! ```
//! use occult_render::{AlgoSpec, Algorithm};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let list = AlgoSpec::parse_list("zbuffer, frustum:leaf=64,group_leaf=2, frustum")?;
//! assert_eq!(list.len(), 3);
//! assert_eq!(list[1].algorithm, Algorithm::FRUSTUM);
//! assert_eq!(list[1].label(), "frustum:leaf=64,group_leaf=2");
//! assert_eq!(list[1].params.get("leaf", 256usize)?, 64);
//! assert!(AlgoSpec::parse("frustum:leef=64").is_err()); // unknown keys are refused
//! # Ok(())
//! # }
//! ```

use std::fmt;
use std::str::FromStr;
use std::sync::Arc;

use occult_core::{Mesh, Scene, Vec3};

use crate::{Algorithm, RenderError, Result};

/// One documented parameter of an algorithm (listed by `occult algos`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamDoc {
    /// The key, as in `key=value`.
    pub key: &'static str,
    /// The default value, as text.
    pub default: &'static str,
    /// What it does (one line; name the paper section where one applies).
    pub help: &'static str,
}

/// The `key=value` settings of one algorithm spec. Getters parse a value on demand and fall
/// back to the given default when the key is absent; a value that does not parse is a
/// [`RenderError::BadParameter`] naming the algorithm, the key and the value.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Params {
    algorithm: &'static str,
    entries: Vec<(String, String)>,
}

impl Params {
    /// No settings, for `algorithm` (its name appears in error messages).
    pub fn new(algorithm: &'static str) -> Self {
        Self {
            algorithm,
            entries: Vec::new(),
        }
    }

    /// These settings plus `key=value` (replacing an earlier value of `key`).
    #[must_use]
    pub fn with(mut self, key: &str, value: &str) -> Self {
        self.set(key, value);
        self
    }

    /// Sets `key=value`, replacing an earlier value of `key`.
    pub fn set(&mut self, key: &str, value: &str) {
        match self.entries.iter_mut().find(|(k, _)| k == key) {
            Some((_, v)) => *v = value.to_string(),
            None => self.entries.push((key.to_string(), value.to_string())),
        }
    }

    /// The settings, in the order given.
    pub fn entries(&self) -> &[(String, String)] {
        &self.entries
    }

    /// The raw text of `key`, if set.
    pub fn raw(&self, key: &str) -> Option<&str> {
        self.entries.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    fn bad(&self, key: &str, value: &str, expected: &str) -> RenderError {
        RenderError::BadParameter(format!("{}: {key}={value}: expected {expected}", self.algorithm))
    }

    /// `key` parsed as `T`, or `default` when absent.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] when the value does not parse.
    pub fn get<T: FromStr>(&self, key: &str, default: T) -> Result<T> {
        match self.raw(key) {
            None => Ok(default),
            Some(v) => v.trim().parse().map_err(|_| {
                let expected = match std::any::type_name::<T>() {
                    "usize" | "u32" | "u64" | "u16" | "u8" => "a non-negative integer",
                    "i32" | "i64" | "isize" => "an integer",
                    "f32" | "f64" => "a number",
                    other => other,
                };
                self.bad(key, v, expected)
            }),
        }
    }

    /// `key` as a switch (`on/off`, `true/false`, `yes/no`, `1/0`), or `default` when absent.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for any other value.
    pub fn flag(&self, key: &str, default: bool) -> Result<bool> {
        match self.raw(key).map(|v| v.trim().to_ascii_lowercase()) {
            None => Ok(default),
            Some(v) => match v.as_str() {
                "on" | "true" | "yes" | "1" => Ok(true),
                "off" | "false" | "no" | "0" => Ok(false),
                _ => Err(self.bad(key, &v, "on or off")),
            },
        }
    }

    /// `key` as one of `choices`, or `default` when absent.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] listing the choices for any other value.
    pub fn choice(&self, key: &str, choices: &[&'static str], default: &'static str) -> Result<&'static str> {
        match self.raw(key) {
            None => Ok(default),
            Some(v) => choices
                .iter()
                .find(|c| c.eq_ignore_ascii_case(v.trim()))
                .copied()
                .ok_or_else(|| self.bad(key, v, &format!("one of {}", choices.join(", ")))),
        }
    }
}

/// Reads option fields from [`Params`], in the order listed: `field: "key"` parses the key with
/// [`Params::get`], `field: flag "key"` with [`Params::flag`]; each absent key keeps the field's
/// current value, so a target built from the options' `Default` keeps its defaults. The first
/// value that does not parse is returned (`?`) from the enclosing function.
///
/// ```text
/// let mut o = Options::default();
/// read_params!(params, o, { leaf_size: "leaf", cache: flag "cache" });
/// ```
macro_rules! read_params {
    ($params:expr, $target:ident, { $($field:ident: $($kind:ident)? $key:literal),* $(,)? }) => {
        $( $crate::params::read_params!(@one $params, $target.$field, $($kind)? $key); )*
    };
    (@one $params:expr, $place:expr, flag $key:literal) => {
        $place = $params.flag($key, $place)?
    };
    (@one $params:expr, $place:expr, $key:literal) => {
        $place = $params.get($key, $place)?
    };
}
pub(crate) use read_params;

/// An algorithm with its settings: what `--algo` and each entry of `--algos` name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AlgoSpec {
    /// The renderer.
    pub algorithm: Algorithm,
    /// Its settings (keys checked against the algorithm's [`ParamDoc`]s).
    pub params: Params,
}

impl From<Algorithm> for AlgoSpec {
    fn from(algorithm: Algorithm) -> Self {
        Self {
            algorithm,
            params: Params::new(algorithm.name()),
        }
    }
}

impl AlgoSpec {
    /// Parses `name` or `name:key=value,key=value`.
    ///
    /// # Errors
    /// [`RenderError::UnknownAlgorithm`]; [`RenderError::BadParameter`] for a setting without
    /// `=`, an empty key or value, a repeated key, or a key the algorithm does not have (the
    /// message lists the ones it has).
    pub fn parse(spec: &str) -> Result<Self> {
        let spec = spec.trim();
        let (name, settings) = match spec.split_once(':') {
            Some((n, s)) => (n.trim(), s),
            None => (spec, ""),
        };
        let algorithm = Algorithm::parse(name)?;
        let mut out = Self::from(algorithm);
        for setting in settings.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let malformed = || {
                RenderError::BadParameter(format!(
                    "{name}: '{setting}' is not key=value (keys: {})",
                    algorithm.keys()
                ))
            };
            let (key, value) = setting.split_once('=').ok_or_else(malformed)?;
            let (key, value) = (key.trim(), value.trim());
            if key.is_empty() || value.is_empty() {
                return Err(malformed());
            }
            if out.params.raw(key).is_some() {
                return Err(RenderError::BadParameter(format!("{name}: {key} is set twice")));
            }
            out.params.set(key, value);
        }
        out.check_keys()?;
        Ok(out)
    }

    /// Parses a comma-separated list of specs. A comma starts a new spec unless the text after
    /// it is a `key=value` setting, which belongs to the spec before it:
    /// `zbuffer,hzb:leaf=64,temporal=off,frustum` is three specs.
    ///
    /// # Errors
    /// As [`AlgoSpec::parse`]; an empty entry; a setting before any algorithm name.
    pub fn parse_list(list: &str) -> Result<Vec<Self>> {
        let mut specs: Vec<String> = Vec::new();
        for part in list.split(',').map(str::trim) {
            if part.is_empty() {
                return Err(RenderError::BadParameter(format!(
                    "empty entry in algorithm list '{list}' (known: {})",
                    Algorithm::names().join(", ")
                )));
            }
            let is_setting = part.contains('=') && !part.contains(':');
            match specs.last_mut() {
                Some(last) if is_setting => {
                    last.push(if last.contains(':') { ',' } else { ':' });
                    last.push_str(part);
                }
                None if is_setting => {
                    return Err(RenderError::BadParameter(format!(
                        "'{part}' in '{list}' comes before any algorithm name"
                    )))
                }
                _ => specs.push(part.to_string()),
            }
        }
        specs.iter().map(|s| Self::parse(s)).collect()
    }

    /// Refuses keys the algorithm does not declare.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming the key and listing the valid ones.
    pub fn check_keys(&self) -> Result<()> {
        let docs = self.algorithm.params();
        for (key, _) in self.params.entries() {
            if !docs.iter().any(|d| d.key == key) {
                return Err(RenderError::BadParameter(format!(
                    "{} has no parameter '{key}' (it has: {})",
                    self.algorithm.name(),
                    self.algorithm.keys()
                )));
            }
        }
        Ok(())
    }

    /// Checks every setting's value too, not only its key, before a scene exists: by building
    /// the renderer on a scene of one triangle (a millisecond or so: no real preprocessing),
    /// with a one-thread rasterizer inside a private one-thread pool (rayon's global pool is
    /// left untouched, so it can still be configured afterwards). Only
    /// [`RenderError::BadParameter`] counts: other failures of that build belong to the scene,
    /// not to the settings. Specs without settings are not built.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for an unknown key or a value the renderer refuses, with
    /// the renderer's message naming the key and value.
    pub fn validate(&self) -> Result<()> {
        self.check_keys()?;
        if self.params.entries().is_empty() {
            return Ok(());
        }
        let Ok(pool) = rayon::ThreadPoolBuilder::new().num_threads(1).build() else {
            // Without a private pool the check would touch the global one: leave the values
            // to the real build.
            return Ok(());
        };
        let mut options = crate::RenderOptions::default();
        options.raster.threads = 1;
        // One finite, non-degenerate triangle is a valid scene; were it refused, the values
        // would be left to the real build, as without a pool.
        let Ok(triangle) = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])
            .and_then(|mesh| Scene::from_mesh("validate", mesh))
        else {
            return Ok(());
        };
        let build = || self.build(Arc::new(triangle), &options).map(drop);
        match pool.install(build) {
            Err(e @ RenderError::BadParameter(_)) => Err(e),
            _ => Ok(()),
        }
    }

    /// The canonical text: `name` alone, or `name:key=value,...` in the order given. Used as the
    /// renderer's name in comparison reports.
    pub fn label(&self) -> String {
        self.to_string()
    }
}

impl fmt::Display for AlgoSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.algorithm.name())?;
        for (i, (k, v)) in self.params.entries().iter().enumerate() {
            write!(f, "{}{k}={v}", if i == 0 { ':' } else { ',' })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn getters_parse_and_refuse() {
        let p = Params::new("x")
            .with("n", "12")
            .with("on", "OFF")
            .with("mode", "Nested")
            .with("bad", "-1");
        assert_eq!(p.get("n", 0usize).expect("n=12 is a non-negative integer"), 12);
        assert_eq!(p.get("absent", 7u32).expect("an absent key takes its default"), 7);
        assert!(!p.flag("on", true).expect("OFF is a flag, in any case"));
        assert!(p.flag("absent", true).expect("an absent flag takes its default"));
        assert_eq!(
            p.choice("mode", &["uniform", "nested"], "uniform")
                .expect("Nested is a listed choice, in any case"),
            "nested"
        );
        let e = p.get("bad", 0usize).unwrap_err().to_string();
        assert!(e.contains("x: bad=-1") && e.contains("non-negative integer"), "{e}");
        assert!(p.flag("n", true).is_err());
        let e = p
            .choice("n", &["uniform", "nested"], "uniform")
            .unwrap_err()
            .to_string();
        assert!(e.contains("uniform, nested"), "{e}");
    }

    #[test]
    fn specs_and_lists() {
        let s = AlgoSpec::parse(" frustum : leaf = 8 ").expect("a spaced spec parses");
        assert_eq!(s.label(), "frustum:leaf=8");
        assert_eq!(
            AlgoSpec::parse("zbuffer").expect("a bare name parses").label(),
            "zbuffer"
        );
        for bad in [
            "frustum:leaf",
            "frustum:=3",
            "frustum:leaf=",
            "frustum:leaf=1,leaf=2",
            "warp",
            "frustum:x=1",
        ] {
            assert!(AlgoSpec::parse(bad).is_err(), "{bad}");
        }
        let l = AlgoSpec::parse_list("zbuffer,frustum:leaf=8,group_leaf=2,frustum,leaf=4")
            .expect("a list with repeated renderers parses");
        let labels: Vec<String> = l.iter().map(AlgoSpec::label).collect();
        assert_eq!(labels, ["zbuffer", "frustum:leaf=8,group_leaf=2", "frustum:leaf=4"]);
        assert!(AlgoSpec::parse_list("leaf=3,frustum").is_err());
        assert!(AlgoSpec::parse_list("zbuffer,,frustum").is_err());
        let e = AlgoSpec::parse_list("zbuffer,warp").unwrap_err().to_string();
        assert!(e.contains("warp") && e.contains("frustum"), "{e}");
    }

    #[test]
    fn validate_checks_values_without_a_scene() {
        let check = |s: &str| {
            AlgoSpec::parse(s)
                .expect("every checked spec parses; validate judges its values")
                .validate()
        };
        for bad in [
            "frustum:leaf=abc",
            "frustum:leaf=0",
            "frustum:group_leaf=-1",
            "hzb:temporal=maybe",
            "hzb:workers=99",
            "lzb:mode=fast",
            "oqgrid:grid=hex",
            "nbuffer:cover=three",
            "rzb:eps=x",
        ] {
            let e = check(bad).expect_err(bad).to_string();
            let key = bad
                .split_once(':')
                .expect("every bad spec has a colon")
                .1
                .split('=')
                .next()
                .expect("split yields at least one piece");
            assert!(e.contains(key), "{bad}: {e}");
        }
        // Every documented default, set explicitly, is valid (beside the setting its help says
        // it needs, as `needs caster=bvh`).
        for a in Algorithm::all() {
            check(a.name()).expect("a bare renderer name is valid");
            for d in a.info().params {
                let needs = d
                    .help
                    .split_once("needs ")
                    .and_then(|(_, rest)| rest.split([' ', ',', ';', ')']).next())
                    .filter(|setting| setting.contains('='))
                    .map_or(String::new(), |setting| format!(",{setting}"));
                check(&format!("{}:{}={}{needs}", a.name(), d.key, d.default))
                    .unwrap_or_else(|e| panic!("{}: {e}", d.key));
            }
        }
        check("lzb:caster=octree,bvh_leaf=4").expect_err("bvh_leaf without caster=bvh sizes nothing");
        check("frustum:leaf=8,group_leaf=2").expect("valid frustum settings pass");
        check("rzb:eps=auto").expect("eps=auto is valid");
    }
}
