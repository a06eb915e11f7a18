//! Files out (PNG, JSON, CSV) and the number formats of the text output.

/// `println!` that returns an error instead of panicking when stdout is closed (`| head`).
/// Under `mpirun`, rank 0 alone prints.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if $crate::ranks::is_root() {
            writeln!(std::io::stdout().lock(), $($arg)*)?;
        }
    }};
}

/// `print!` that returns an error instead of panicking when stdout is closed.
macro_rules! say_raw {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if $crate::ranks::is_root() {
            write!(std::io::stdout().lock(), $($arg)*)?;
        }
    }};
}

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use occult_raster::Frame;
use occult_render::FrameStats;
use serde::Serialize;

/// Checks, before any long work, that `path` can be created: its directory exists and it is
/// not a directory itself.
///
/// # Errors
/// A missing parent directory or a path that is a directory.
pub fn check_output(path: &Path) -> Result<()> {
    if path.is_dir() {
        bail!("cannot write '{}': it is a directory", path.display());
    }
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !parent.is_dir() {
        bail!(
            "cannot write '{}': directory '{}' does not exist",
            path.display(),
            parent.display()
        );
    }
    Ok(())
}

/// Checks every path of `paths` with [`check_output`], and that no two name the same file (one
/// output would overwrite the other).
///
/// # Errors
/// As [`check_output`]; two paths naming one file.
pub fn check_outputs<'a>(paths: impl IntoIterator<Item = &'a Option<PathBuf>>) -> Result<()> {
    // Under `mpirun` every rank checks, and all end alike when one path is bad.
    crate::ranks::agree(check_each_output(paths))
}

fn check_each_output<'a>(paths: impl IntoIterator<Item = &'a Option<PathBuf>>) -> Result<()> {
    let mut seen: Vec<(PathBuf, &Path)> = Vec::new();
    for p in paths.into_iter().flatten() {
        check_output(p)?;
        let file = std::path::absolute(p).unwrap_or_else(|_| p.clone());
        if let Some((_, first)) = seen.iter().find(|(f, _)| *f == file) {
            bail!("'{}' and '{}' name the same output file", first.display(), p.display());
        }
        seen.push((file, p));
    }
    Ok(())
}

/// Writes the frame's color (after shading) as PNG.
///
/// # Errors
/// I/O and encoding errors, naming the file.
pub fn write_color_png(frame: &Frame, path: &Path) -> Result<()> {
    if !crate::ranks::is_root() {
        return Ok(());
    }
    frame
        .color_image()
        .save_with_format(path, image::ImageFormat::Png)
        .with_context(|| format!("cannot write '{}'", path.display()))
}

/// Writes the frame's depth visualisation as PNG.
///
/// # Errors
/// I/O and encoding errors, naming the file.
pub fn write_depth_png(frame: &Frame, path: &Path) -> Result<()> {
    if !crate::ranks::is_root() {
        return Ok(());
    }
    frame
        .depth_image()
        .save_with_format(path, image::ImageFormat::Png)
        .with_context(|| format!("cannot write '{}'", path.display()))
}

/// Writes `value` as pretty JSON.
///
/// # Errors
/// I/O errors, naming the file.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    if !crate::ranks::is_root() {
        return Ok(());
    }
    let mut text = serde_json::to_string_pretty(value).context("cannot serialize the report")?;
    text.push('\n');
    std::fs::write(path, text).with_context(|| format!("cannot write '{}'", path.display()))
}

/// Writes a CSV file from a header and rows of already formatted fields.
///
/// # Errors
/// I/O errors, naming the file.
pub fn write_csv(path: &Path, header: &[&str], rows: &[Vec<String>]) -> Result<()> {
    if !crate::ranks::is_root() {
        return Ok(());
    }
    let mut text = header.join(",");
    text.push('\n');
    for row in rows {
        let fields: Vec<String> = row.iter().map(|f| csv_field(f)).collect();
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    std::fs::write(path, text).with_context(|| format!("cannot write '{}'", path.display()))
}

/// Quotes a CSV field when it needs it.
fn csv_field(f: &str) -> String {
    if f.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", f.replace('"', "\"\""))
    } else {
        f.to_string()
    }
}

/// One parameter of a catalogue (`occult algos`, `occult scenes`), as JSON.
#[derive(Serialize)]
pub struct ParamOut {
    name: &'static str,
    default: &'static str,
    meaning: &'static str,
}

impl ParamOut {
    /// A parameter `name` with its default value and what it means.
    pub fn new(name: &'static str, default: &'static str, meaning: &'static str) -> Self {
        Self { name, default, meaning }
    }
}

/// The parameters as lines `    name=default  meaning`, the meanings aligned; each line ends
/// with a newline.
pub fn param_lines(params: &[ParamOut]) -> String {
    let width = params
        .iter()
        .map(|p| p.name.len() + p.default.len() + 1)
        .max()
        .unwrap_or(0);
    params
        .iter()
        .map(|p| format!("    {:<width$}  {}\n", format!("{}={}", p.name, p.default), p.meaning))
        .collect()
}

/// An optional number as a CSV field (empty when absent).
pub fn opt_field<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or_else(String::new, |v| format!("{v}"))
}

/// A phase's name as it serializes (`depth_structure`).
pub fn phase_name(p: &impl Serialize) -> String {
    match serde_json::to_value(p) {
        Ok(serde_json::Value::String(s)) => s,
        _ => "other".to_string(),
    }
}

/// Frame statistics as text lines: nonzero counters, then the phases.
pub fn stats_text(s: &FrameStats) -> String {
    let mut out = String::new();
    for (name, v) in s.fixed_counters() {
        if v > 0 || name.starts_with("triangles") {
            let name = name.replace('_', " ");
            let _ = writeln!(out, "  {name:<22} {}", count(v as f64));
        }
    }
    for &(name, v) in &s.counters.0 {
        let _ = writeln!(out, "  {name:<22} {}", count(v as f64));
    }
    let phases: Vec<String> = s.phases_ms().iter().map(|(p, ms)| format!("{p} {ms:.2}")).collect();
    let _ = writeln!(
        out,
        "  {:<22} {:.2} ms ({})",
        "frame time",
        s.total.as_secs_f64() * 1e3,
        phases.join(", ")
    );
    out
}

/// A count with thousands separators (`1,234,567`); fractional counts keep one decimal below
/// 100.
pub fn count(v: f64) -> String {
    if !v.is_finite() {
        return "-".into();
    }
    if v.fract() != 0.0 && v.abs() < 100.0 {
        return format!("{v:.1}");
    }
    let digits = format!("{:.0}", v.abs());
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    if v < 0.0 {
        out.insert(0, '-');
    }
    out
}

/// Bytes in binary units (`12.3 MiB`).
pub fn bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", UNITS[unit])
    }
}

/// Milliseconds with precision that suits the magnitude.
pub fn millis(ms: f64) -> String {
    if ms >= 100.0 {
        format!("{ms:.0}")
    } else if ms >= 10.0 {
        format!("{ms:.1}")
    } else if ms >= 0.1 {
        format!("{ms:.2}")
    } else {
        format!("{ms:.3}")
    }
}

/// A plain text table: left-aligned first column, right-aligned others.
pub fn table(header: &[&str], rows: &[Vec<String>]) -> String {
    let cols = header.len();
    let mut widths: Vec<usize> = header.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: &mut dyn Iterator<Item = &str>| {
        let mut s = String::new();
        for (i, cell) in cells.enumerate().take(cols) {
            let pad = widths[i].saturating_sub(cell.chars().count());
            if i == 0 {
                s.push_str(cell);
                s.push_str(&" ".repeat(pad));
            } else {
                s.push_str("  ");
                s.push_str(&" ".repeat(pad));
                s.push_str(cell);
            }
        }
        s.trim_end().to_string()
    };
    let mut out = line(&mut header.iter().copied());
    out.push('\n');
    for row in rows {
        out.push_str(&line(&mut row.iter().map(String::as_str)));
        out.push('\n');
    }
    out
}

/// `names` sorted and comma-separated without repeats, or `they have none` when empty: the
/// tail of a message listing what a name could have been.
pub fn names_or_none(names: &[&str]) -> String {
    let mut names = names.to_vec();
    names.sort_unstable();
    names.dedup();
    if names.is_empty() {
        "they have none".to_string()
    } else {
        format!("known: {}", names.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_formats() {
        assert_eq!(count(1234567.0), "1,234,567");
        assert_eq!(count(999.0), "999");
        assert_eq!(count(12.5), "12.5");
        assert_eq!(count(0.0), "0");
        assert_eq!(bytes(512), "512 B");
        assert_eq!(bytes(3 << 20), "3.0 MiB");
        assert_eq!(millis(0.1234), "0.12");
        assert_eq!(millis(123.4), "123");
    }

    #[test]
    fn tables_align() {
        let t = table(&["a", "bb"], &[vec!["long".into(), "1".into()]]);
        assert_eq!(t, "a     bb\nlong   1\n");
    }

    #[test]
    fn csv_quotes_when_needed() {
        assert_eq!(csv_field("city:blocks=8"), "city:blocks=8");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"x\""), "\"say \"\"x\"\"\"");
    }

    #[test]
    fn output_checks() {
        assert!(check_output(Path::new("/no/such/dir/x.png")).is_err());
        assert!(check_output(Path::new("/")).is_err());
        assert!(check_output(Path::new("x.png")).is_ok());
    }
}
