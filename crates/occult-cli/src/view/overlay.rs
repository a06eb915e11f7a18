//! Text over the frame: Noto Sans Regular (the font the plots embed), rasterized with
//! ab_glyph once per character and size and cached, drawn on a darkened panel.

use std::collections::HashMap;

use ab_glyph::{Font, FontRef, PxScale, ScaleFont};
use anyhow::{Context, Result};

/// A character's coverage, rasterized once.
struct Glyph {
    /// Coverage 0..=255, `width × height`, row-major.
    coverage: Vec<u8>,
    width: usize,
    height: usize,
    /// Offset of the bitmap's top-left from the pen position on the baseline, pixels.
    left: i32,
    top: i32,
    /// Pen advance, pixels.
    advance: f32,
}

/// Draws lines of text into `0x00RRGGBB` pixel buffers.
pub struct Text {
    font: FontRef<'static>,
    scale: PxScale,
    glyphs: HashMap<char, Glyph>,
}

/// Pixels between the panel's edge and its text.
const PAD: i32 = 6;
/// Pixels between a panel's columns.
const COLUMN_GAP: i32 = 16;

impl Text {
    /// Text of `px` pixels per em.
    ///
    /// # Errors
    /// The embedded font failing to parse (a broken build).
    pub fn new(px: f32) -> Result<Self> {
        let font = FontRef::try_from_slice(ttf_noto_sans::REGULAR).context("the embedded font Noto Sans")?;
        Ok(Self {
            font,
            scale: PxScale::from(px),
            glyphs: HashMap::new(),
        })
    }

    /// Height of a line, pixels.
    pub fn line_height(&self) -> i32 {
        let f = self.font.as_scaled(self.scale);
        (f.ascent() - f.descent() + f.line_gap()).ceil() as i32
    }

    fn glyph(&mut self, c: char) -> &Glyph {
        let (font, scale) = (&self.font, self.scale);
        self.glyphs.entry(c).or_insert_with(|| {
            let scaled = font.as_scaled(scale);
            let id = font.glyph_id(c);
            let advance = scaled.h_advance(id);
            let glyph = id.with_scale_and_position(scale, ab_glyph::point(0.0, 0.0));
            match font.outline_glyph(glyph) {
                Some(outlined) => {
                    let b = outlined.px_bounds();
                    let (width, height) = (b.width() as usize, b.height() as usize);
                    let mut coverage = vec![0u8; width * height];
                    outlined.draw(|x, y, c| {
                        if let Some(v) = coverage.get_mut(y as usize * width + x as usize) {
                            *v = (c.clamp(0.0, 1.0) * 255.0) as u8;
                        }
                    });
                    Glyph {
                        coverage,
                        width,
                        height,
                        left: b.min.x as i32,
                        top: b.min.y as i32,
                        advance,
                    }
                }
                None => Glyph {
                    coverage: Vec::new(),
                    width: 0,
                    height: 0,
                    left: 0,
                    top: 0,
                    advance,
                },
            }
        })
    }

    /// Width of `line`, pixels.
    pub fn width(&mut self, line: &str) -> i32 {
        line.chars().map(|c| self.glyph(c).advance).sum::<f32>().ceil() as i32
    }

    /// Draws `lines` on a darkened panel whose top-left corner is at (`x`, `y`) in a
    /// `width`-pixel-wide buffer; `right` aligns the panel's right edge at `x` instead. Each
    /// line is drawn in its own color (`0x00RRGGBB`). A tab starts a second column, aligned
    /// across the lines.
    pub fn panel(&mut self, pixels: &mut [u32], width: usize, x: i32, y: i32, right: bool, lines: &[(String, u32)]) {
        if lines.is_empty() || width == 0 {
            return;
        }
        let height = (pixels.len() / width) as i32;
        let line_height = self.line_height();
        let first_column = lines
            .iter()
            .filter_map(|(l, _)| l.split_once('\t'))
            .map(|(a, _)| self.width(a) + COLUMN_GAP)
            .max()
            .unwrap_or(0);
        let text_width = lines
            .iter()
            .map(|(l, _)| match l.split_once('\t') {
                Some((_, b)) => first_column + self.width(b),
                None => self.width(l),
            })
            .max()
            .unwrap_or(0);
        let panel_w = text_width + 2 * PAD;
        let panel_h = line_height * lines.len() as i32 + 2 * PAD;
        let x0 = if right { x - panel_w } else { x };
        for py in y.max(0)..(y + panel_h).min(height) {
            for px in x0.max(0)..(x0 + panel_w).min(width as i32) {
                let p = &mut pixels[py as usize * width + px as usize];
                // Darken to a third: the frame stays visible behind the text.
                *p = (*p >> 2) & 0x003f_3f3f;
            }
        }
        let ascent = self.font.as_scaled(self.scale).ascent().round() as i32;
        for (i, (line, color)) in lines.iter().enumerate() {
            let baseline = y + PAD + ascent + i as i32 * line_height;
            let mut pen = (x0 + PAD) as f32;
            for c in line.chars() {
                if c == '\t' {
                    pen = (x0 + PAD + first_column) as f32;
                    continue;
                }
                let g = self.glyph(c);
                let gx = pen.round() as i32 + g.left;
                let gy = baseline + g.top;
                blit(pixels, width, height, g, gx, gy, *color);
                pen += g.advance;
            }
        }
    }
}

fn blit(pixels: &mut [u32], width: usize, height: i32, g: &Glyph, gx: i32, gy: i32, color: u32) {
    for row in 0..g.height {
        let y = gy + row as i32;
        if y < 0 || y >= height {
            continue;
        }
        for col in 0..g.width {
            let x = gx + col as i32;
            let a = u32::from(g.coverage[row * g.width + col]);
            if x < 0 || x >= width as i32 || a == 0 {
                continue;
            }
            let p = &mut pixels[y as usize * width + x as usize];
            *p = blend(*p, color, a);
        }
    }
}

/// `over` on `under` with coverage `a` in 0..=255.
fn blend(under: u32, over: u32, a: u32) -> u32 {
    let channel = |shift: u32| {
        let u = (under >> shift) & 0xff;
        let o = (over >> shift) & 0xff;
        ((o * a + u * (255 - a)) / 255) << shift
    };
    channel(16) | channel(8) | channel(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_marks_pixels_inside_the_buffer_only() {
        let mut text = Text::new(14.0).expect("the embedded font parses");
        let (w, h) = (120usize, 40usize);
        let mut pixels = vec![0x0080_8080u32; w * h];
        text.panel(&mut pixels, w, 0, 0, false, &[("Hello, occult".into(), 0x00ff_ffff)]);
        assert!(pixels.contains(&0x0020_2020), "the panel darkens");
        assert!(pixels.iter().any(|&p| p > 0x0080_8080), "some text is drawn");
        text.panel(&mut pixels, w, -500, -500, true, &[("off screen".into(), 0x00ff_ffff)]);
        text.panel(&mut pixels, w, 0, 0, false, &[]);
    }

    #[test]
    fn blending_ends() {
        assert_eq!(blend(0x0010_2030, 0x00ff_ffff, 0), 0x0010_2030);
        assert_eq!(blend(0x0010_2030, 0x00ff_ffff, 255), 0x00ff_ffff);
    }
}
