//! `crepuscular compare`: `reference` and each technique on the same inputs, side by side — one
//! contact sheet (final image, in-scattering, FLIP error map with a colour bar, each row
//! captioned with time, ray-marched samples, PSNR and FLIP) plus `report.md` / `report.json`.

use crate::bench::{self, BenchPlan, BenchReport, Kept, Variant};
use crate::metrics::flip_heatmap;
use anyhow::{Context, Result, bail};
use crepuscular::gpu::GpuContext;
use crepuscular::tonemap::ToneMap;
use std::path::{Path, PathBuf};

/// An 8-bit RGB canvas.
pub struct Canvas {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Packed RGB, row-major from the top left.
    pub rgb: Vec<u8>,
}

impl Canvas {
    /// A canvas filled with `bg`.
    pub fn new(width: u32, height: u32, bg: [u8; 3]) -> Self {
        Canvas { width, height, rgb: bg.repeat(width as usize * height as usize) }
    }

    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = (y as usize * self.width as usize + x as usize) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Pastes `rgb` (w×h), scaled to `tw` wide (box filter when shrinking), at (x, y).
    pub fn paste_scaled(&mut self, x: u32, y: u32, w: u32, h: u32, rgb: &[u8], tw: u32) -> u32 {
        let th = ((h as u64 * tw as u64) / w.max(1) as u64).max(1) as u32;
        for ty in 0..th {
            for tx in 0..tw {
                let (x0, x1) = (tx * w / tw, ((tx + 1) * w / tw).max(tx * w / tw + 1).min(w));
                let (y0, y1) = (ty * h / th, ((ty + 1) * h / th).max(ty * h / th + 1).min(h));
                let mut acc = [0u32; 3];
                let mut n = 0;
                for sy in y0..y1 {
                    for sx in x0..x1 {
                        let i = (sy as usize * w as usize + sx as usize) * 3;
                        for c in 0..3 {
                            acc[c] += rgb[i + c] as u32;
                        }
                        n += 1;
                    }
                }
                let n = n.max(1);
                self.put((x + tx) as i64, (y + ty) as i64, acc.map(|a| (a / n) as u8));
            }
        }
        th
    }

    /// Draws `text` with the 8×8 bitmap font at `scale` pixels per font pixel.
    pub fn text(&mut self, x: u32, y: u32, text: &str, scale: u32, color: [u8; 3]) {
        use font8x8::UnicodeFonts;
        let mut cx = x as i64;
        for ch in text.chars() {
            let glyph = font8x8::BASIC_FONTS
                .get(ch)
                .or_else(|| font8x8::LATIN_FONTS.get(ch))
                .or_else(|| font8x8::GREEK_FONTS.get(ch))
                .or_else(|| font8x8::BASIC_FONTS.get('?'))
                .unwrap_or([0; 8]);
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits >> col & 1 == 1 {
                        for sy in 0..scale {
                            for sx in 0..scale {
                                self.put(
                                    cx + (col * scale + sx) as i64,
                                    y as i64 + (row as u32 * scale + sy) as i64,
                                    color,
                                );
                            }
                        }
                    }
                }
            }
            cx += 8 * scale as i64;
        }
    }
}

/// Width in pixels of `text` at `scale`.
pub fn text_width(text: &str, scale: u32) -> u32 {
    text.chars().count() as u32 * 8 * scale
}

/// The FLIP magma colour bar, `w` × `h`, 0 on the left to 1 on the right.
fn colour_bar(w: u32, h: u32) -> Vec<u8> {
    let ramp: Vec<f32> = (0..w).map(|i| i as f32 / (w - 1).max(1) as f32).collect();
    let img = nv_flip::FlipImageFloat::with_data(w, 1, &ramp);
    let row = img.apply_color_lut(&nv_flip::magma_lut()).to_vec();
    row.repeat(h as usize)
}

/// Builds the contact sheet from the reference's and the rows' images.
pub fn contact_sheet(report: &BenchReport, kept: &[Kept], exposure: f32) -> Result<Canvas> {
    let reference = kept.iter().find(|k| k.label == "reference").context("no reference images")?;
    let (w, h) = (reference.size[0], reference.size[1]);
    let tone = ToneMap::new(exposure);
    let tile_w = w.min(480);
    let tile_h = ((h as u64 * tile_w as u64) / w as u64).max(1) as u32;
    let (margin, cap) = (12u32, 40u32);
    let sheet_w = margin + 3 * (tile_w + margin);
    let rows = kept.len() as u32;
    let header = 64u32;
    let footer = 48u32;
    let sheet_h = header + rows * (cap + tile_h + margin) + footer;
    let mut c = Canvas::new(sheet_w, sheet_h, [24, 24, 28]);
    let white = [235, 235, 235];
    let grey = [170, 170, 175];
    c.text(margin, 8, &format!("{} {}x{}", report.plan.scenes.join(","), w, h), 2, white);
    let dev = format!("{} - {} - {}", report.adapter.name, report.adapter.backend, report.date);
    c.text(margin, 28, &dev, 1, grey);
    for (i, title) in
        ["final (tone-mapped)", "in-scattering (tone-mapped)", "FLIP error vs reference"].iter().enumerate()
    {
        c.text(margin + i as u32 * (tile_w + margin), header - 14, title, 1, grey);
    }
    let mut y = header;
    for k in kept {
        let caption = if k.label == "reference" {
            let steps = report.plan.reference_steps;
            format!("reference ({steps} steps/px, CPU f64) - {:.0} ms", k.ms)
        } else {
            let r = report.records.iter().find(|r| r.label == k.label && r.size == k.size);
            match r {
                Some(r) => format!(
                    "{} - {:.1} ms - {:.2}M samples - PSNR {} dB - FLIP {}",
                    k.label,
                    r.total_ms[0],
                    r.raymarched_samples as f64 / 1e6,
                    r.psnr_db.map(|p| format!("{p:.1}")).unwrap_or_else(|| "-".into()),
                    r.flip_mean.map(|f| format!("{f:.4}")).unwrap_or_else(|| "-".into()),
                ),
                None => k.label.clone(),
            }
        };
        c.text(margin, y + 14, &caption, if text_width(&caption, 2) + margin < sheet_w { 2 } else { 1 }, white);
        y += cap;
        let fin = tone.to_rgb8(&k.final_radiance);
        c.paste_scaled(margin, y, w, h, &fin, tile_w);
        let ins = tone.to_rgb8(&k.inscatter);
        c.paste_scaled(margin + tile_w + margin, y, w, h, &ins, tile_w);
        if k.label != "reference" {
            let (hw, hh, heat) = flip_heatmap(&reference.final_radiance, &k.final_radiance, &tone)?;
            c.paste_scaled(margin + 2 * (tile_w + margin), y, hw, hh, &heat, tile_w);
        }
        y += tile_h + margin;
    }
    // The colour bar of the error maps.
    let bx = margin + 2 * (tile_w + margin);
    let bar = colour_bar(tile_w, 12);
    c.paste_scaled(bx, y + 4, tile_w, 12, &bar, tile_w);
    c.text(bx, y + 22, "0", 1, grey);
    c.text(bx + tile_w - 8, y + 22, "1", 1, grey);
    c.text(bx + tile_w / 2 - text_width("FLIP", 1) / 2, y + 22, "FLIP", 1, grey);
    Ok(c)
}

/// What `compare` needs.
pub struct CompareArgs {
    /// Scene name or file.
    pub scene: String,
    /// Techniques at their scene/default settings.
    pub techniques: Vec<String>,
    /// Image size (None: the scene's).
    pub size: Option<(u32, u32)>,
    /// Reference steps.
    pub reference_steps: u32,
    /// Timed frames.
    pub repeat: u32,
    /// Output directory.
    pub output: PathBuf,
}

/// Runs `compare` and writes sheet.png, report.md, report.json; returns the paths.
pub fn run(
    a: &CompareArgs,
    gpu: Option<&GpuContext>,
    command: &str,
    progress: &dyn Fn(&str),
    reference_progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Vec<PathBuf>> {
    if a.techniques.is_empty() {
        bail!("--techniques: give at least one technique");
    }
    let scene = crate::render::load_scene(&a.scene)?;
    let size = a.size.unwrap_or((scene.render.width, scene.render.height));
    let plan = BenchPlan {
        name: "compare".into(),
        description: format!("`reference` and {} on the same inputs", a.techniques.join(", ")),
        scenes: vec![a.scene.clone()],
        sizes: vec![size],
        variants: a.techniques.iter().map(|t| Variant::new(t, &[], t, None)).collect(),
        repeat: a.repeat.max(1),
        warmup: 1,
        reference_steps: a.reference_steps,
        shadow_filter: None,
    };
    if a.reference_steps < 2 || a.reference_steps % 2 != 0 {
        bail!("--reference-steps {}: must be even and ≥ 2", a.reference_steps);
    }
    let (report, kept) = bench::run(&plan, gpu, command, progress, reference_progress, true)?;
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("{}: cannot create the output directory", a.output.display()))?;
    let sheet = contact_sheet(&report, &kept, scene.render.exposure)?;
    let mut written = Vec::new();
    let p = a.output.join("sheet.png");
    crate::output::write_png_rgb8(&p, sheet.width, sheet.height, &sheet.rgb)?;
    written.push(p);
    let p = a.output.join("report.md");
    let md = bench::markdown(&report).replacen("# bench: compare", &format!("# compare: {}", scene.name), 1);
    crate::output::write_atomic(&p, format!("{md}\n![contact sheet](sheet.png)\n").as_bytes())?;
    written.push(p);
    let p = a.output.join("report.json");
    crate::output::write_json(&p, &report)?;
    written.push(p);
    Ok(written)
}

/// Checks that `dir` can be written before any long work starts.
pub fn check_output_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create the output directory", dir.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_draws_glyph_pixels_and_unknown_characters_do_not_panic() {
        let mut c = Canvas::new(64, 16, [0; 3]);
        c.text(0, 0, "A×→", 1, [255; 3]);
        let lit = c.rgb.chunks(3).filter(|p| p[0] == 255).count();
        assert!(lit > 10, "{lit}");
        // Off-canvas text is clipped, not a panic.
        c.text(60, 12, "WWWW", 3, [255; 3]);
    }

    #[test]
    fn paste_scaled_box_filters_when_shrinking() {
        let mut c = Canvas::new(2, 1, [0; 3]);
        let src = [255u8, 255, 255, 0, 0, 0, 255, 255, 255, 0, 0, 0];
        let th = c.paste_scaled(0, 0, 4, 1, &src, 2);
        assert_eq!(th, 1);
        assert_eq!(&c.rgb[..3], &[127, 127, 127]);
    }

    #[test]
    fn colour_bar_runs_dark_to_bright() {
        let b = colour_bar(32, 2);
        let lum = |i: usize| b[i * 3] as u32 + b[i * 3 + 1] as u32 + b[i * 3 + 2] as u32;
        assert!(lum(0) < lum(31));
        assert_eq!(b.len(), 32 * 2 * 3);
    }
}
