//! The suite's definition: **the one place** that says which cases the yardstick measures.
//!
//! Figures of two runs compare only when both ran the same definition, so any change here
//! (a case added, removed or renamed; a scene, path, frame count, size or the quick subset
//! changed) bumps [`SUITE_VERSION`], which every report carries.
//!
//! The matrix: each generator at two sizes (the default and a larger instancing of it), the real
//! models of the shared models folder, along street, orbit (`circle`) and flyover paths. It
//! holds cases where culling pays (streets through a city or a plant), cases where it barely
//! can (orbits of a forest, a single scanned model) and one where it cannot (`terrain-flyover`:
//! half of what is in view is visible). Frame counts are set so that the full suite with every
//! renderer stays within minutes on two cores: `lzb`, the slowest renderer, spends seconds a
//! frame on the largest cases, which therefore get fewer frames.

use serde::Serialize;

use super::SuiteError;

/// Version of the definition below; bumped on any change to it (module doc).
pub const SUITE_VERSION: u32 = 1;

/// Frame size of a full run, pixels.
pub const DEFAULT_SIZE: (u32, u32) = (1280, 720);

/// Frame size of a quick run (`--quick`), pixels.
pub const QUICK_SIZE: (u32, u32) = (640, 360);

/// Most frames a case gets in a quick run.
pub const QUICK_MAX_FRAMES: u32 = 4;

/// Where a case's scene comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", content = "spec", rename_all = "snake_case")]
pub enum CaseScene {
    /// A generator spec, as `occult --scene` takes it (`city:blocks=32`).
    Generated(&'static str),
    /// A model file, relative to the models folder (`lost-empire/lost_empire.obj`).
    Model(&'static str),
}

impl std::fmt::Display for CaseScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Generated(spec) | Self::Model(spec) => f.write_str(spec),
        }
    }
}

/// One case of the suite: a scene, a camera path through it and its length.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Case {
    /// Short, stable name (`city-street`), what `--cases` takes and reports show.
    pub name: &'static str,
    /// The scene.
    pub scene: CaseScene,
    /// Camera path kind, as `occult --path` takes it without its count: `street`, `circle`
    /// (an orbit) or `flyover`.
    pub path: &'static str,
    /// Frames, the path's view count.
    pub frames: u32,
    /// In the quick subset (`--quick`, for CI).
    pub quick: bool,
}

impl Case {
    /// The path spec, `kind:frames` (`street:32`).
    pub fn path_spec(&self) -> String {
        format!("{}:{}", self.path, self.frames)
    }
}

/// Shorthand for the table below.
const fn case(name: &'static str, scene: CaseScene, path: &'static str, frames: u32, quick: bool) -> Case {
    Case {
        name,
        scene,
        path,
        frames,
        quick,
    }
}

use CaseScene::{Generated as G, Model as M};

/// The suite, in report order.
pub const CASES: [Case; 15] = [
    case("city-street", G("city"), "street", 32, true),
    case("city-orbit", G("city"), "circle", 32, false),
    case("city32-street", G("city:blocks=32"), "street", 16, false),
    case("city32-orbit", G("city:blocks=32"), "circle", 8, false),
    case("plant-orbit", G("plant"), "circle", 32, true),
    case("plant-street", G("plant"), "street", 16, false),
    case("plant8-street", G("plant:units=8"), "street", 16, false),
    case("plant8-orbit", G("plant:units=8"), "circle", 16, false),
    case("forest-orbit", G("forest"), "circle", 16, true),
    case("forest3-flyover", G("forest:replicate=3"), "flyover", 8, false),
    case("terrain-flyover", G("terrain"), "flyover", 24, true),
    case(
        "lost-empire-orbit",
        M("lost-empire/lost_empire.obj"),
        "circle",
        24,
        false,
    ),
    case(
        "lost-empire-street",
        M("lost-empire/lost_empire.obj"),
        "street",
        8,
        false,
    ),
    case("sponza-orbit", M("dabrovic-sponza/sponza.obj"), "circle", 24, true),
    case(
        "armadillo-orbit",
        M("stanford-armadillo/Armadillo.ply"),
        "circle",
        24,
        false,
    ),
];

/// The cases a run measures: those named (in the order given, repeats dropped), else the quick
/// subset when `quick`, else all; with `frames` as every case's frame count when given, and at
/// most [`QUICK_MAX_FRAMES`] when `quick` and not.
///
/// # Errors
/// [`SuiteError::UnknownCase`] for a name not in [`CASES`] (the message lists the valid ones);
/// [`SuiteError::NoCases`] for an empty list of names.
pub fn select(names: Option<&[String]>, quick: bool, frames: Option<u32>) -> Result<Vec<Case>, SuiteError> {
    let mut chosen: Vec<Case> = match names {
        Some(names) => {
            let mut chosen: Vec<Case> = Vec::new();
            for name in names.iter().map(|n| n.trim()) {
                let case = CASES
                    .iter()
                    .find(|c| c.name == name)
                    .ok_or_else(|| SuiteError::UnknownCase {
                        name: name.to_string(),
                        valid: CASES.iter().map(|c| c.name).collect::<Vec<_>>().join(", "),
                    })?;
                if !chosen.iter().any(|c| c.name == case.name) {
                    chosen.push(*case);
                }
            }
            chosen
        }
        None => CASES.iter().filter(|c| c.quick || !quick).copied().collect(),
    };
    if chosen.is_empty() {
        return Err(SuiteError::NoCases);
    }
    for c in &mut chosen {
        c.frames = match frames {
            Some(n) => n,
            None if quick => c.frames.min(QUICK_MAX_FRAMES),
            None => c.frames,
        };
    }
    Ok(chosen)
}

/// The frame size of a run, `(width, height)`: [`QUICK_SIZE`] when `quick`, else
/// [`DEFAULT_SIZE`].
pub fn default_size(quick: bool) -> (u32, u32) {
    if quick {
        QUICK_SIZE
    } else {
        DEFAULT_SIZE
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_scenes::{parse_spec, PathSpec, SceneSpec};

    #[test]
    fn every_case_is_well_formed() {
        for (i, c) in CASES.iter().enumerate() {
            assert!(
                !c.name.is_empty()
                    && c.name
                        .chars()
                        .all(|ch| ch.is_ascii_lowercase() || ch.is_ascii_digit() || ch == '-'),
                "{}",
                c.name
            );
            assert!(CASES[..i].iter().all(|d| d.name != c.name), "{} twice", c.name);
            assert!(c.frames >= 1);
            let path = PathSpec::parse(&c.path_spec()).expect("every case's path spec parses");
            assert_eq!(path.len(), c.frames as usize, "{}", c.name);
            match c.scene {
                CaseScene::Generated(spec) => {
                    assert!(matches!(parse_spec(spec), Ok(SceneSpec::Generator(_))), "{spec}")
                }
                CaseScene::Model(file) => assert!(file.contains('/') && !file.starts_with('/'), "{file}"),
            }
        }
        assert!(CASES.iter().any(|c| c.quick) && CASES.iter().any(|c| !c.quick));
    }

    #[test]
    fn selection_by_name_quick_and_frames() {
        let all = select(None, false, None).expect("selecting all cases succeeds");
        assert_eq!(all, CASES);
        let quick = select(None, true, None).expect("selecting the quick cases succeeds");
        assert!(quick.iter().all(|c| c.quick && c.frames <= QUICK_MAX_FRAMES));
        assert_eq!(quick.len(), CASES.iter().filter(|c| c.quick).count());
        let names = [
            "terrain-flyover".to_string(),
            "city-street".into(),
            "terrain-flyover".into(),
        ];
        let some = select(Some(&names), false, Some(3)).expect("known case names select");
        assert_eq!(
            some.iter().map(|c| c.name).collect::<Vec<_>>(),
            ["terrain-flyover", "city-street"]
        );
        assert!(some.iter().all(|c| c.frames == 3));
        assert_eq!(some[0].path_spec(), "flyover:3");
    }

    #[test]
    fn unknown_names_list_the_valid_ones() {
        let e = select(Some(&["city-strete".to_string()]), false, None).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("city-strete") && msg.contains("city-street") && msg.contains("sponza-orbit"));
        assert!(!msg.contains('\n'));
        assert!(matches!(select(Some(&[]), false, None), Err(SuiteError::NoCases)));
    }
}
