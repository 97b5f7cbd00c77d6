//! The report's plots (SVG and PNG, plotters) and every file `bench` writes.

use super::*;

pub(super) const COLORS: [plotters::style::RGBColor; 8] = [
    plotters::style::RGBColor(31, 119, 180),
    plotters::style::RGBColor(255, 127, 14),
    plotters::style::RGBColor(44, 160, 44),
    plotters::style::RGBColor(214, 39, 40),
    plotters::style::RGBColor(148, 103, 189),
    plotters::style::RGBColor(140, 86, 75),
    plotters::style::RGBColor(227, 119, 194),
    plotters::style::RGBColor(127, 127, 127),
];

type Curves = Vec<(String, Vec<(f64, f64)>)>;

/// Size of every plot, pixels (SVG user units and PNG pixels).
pub(super) const PLOT_SIZE: (u32, u32) = (900, 560);

/// Writes a plot as SVG at `path` and as PNG beside it (same stem). Nothing is written when no
/// curve has a finite point.
pub(super) fn line_plot(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    log_x: bool,
    curves: &Curves,
) -> Result<bool> {
    let mut svg = String::new();
    {
        let root = plotters::prelude::SVGBackend::with_string(&mut svg, PLOT_SIZE);
        if !draw_plot(root, title, x_desc, y_desc, log_x, curves)? {
            return Ok(false);
        }
    }
    crate::output::write_atomic(path, svg.as_bytes())?;
    let mut png = pixel_plot::RgbBackend::new(PLOT_SIZE);
    draw_plot(&mut png, title, x_desc, y_desc, log_x, curves)?;
    crate::output::write_png_rgb8(&path.with_extension("png"), PLOT_SIZE.0, PLOT_SIZE.1, &png.rgb)?;
    Ok(true)
}

/// Draws the plot on any plotters backend; false when there is nothing to draw.
pub(super) fn draw_plot<DB: plotters::prelude::DrawingBackend>(
    backend: DB,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    log_x: bool,
    curves: &Curves,
) -> Result<bool> {
    use plotters::prelude::*;
    let pts: Vec<(f64, f64)> =
        curves.iter().flat_map(|c| c.1.iter().copied()).filter(|p| p.0.is_finite() && p.1.is_finite()).collect();
    if pts.is_empty() {
        return Ok(false);
    }
    let (mut x0, mut x1) = pts.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (mut y0, mut y1) = pts.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    if log_x {
        x0 = (x0 * 0.8).max(1e-6);
        x1 = (x1 * 1.25).max(x0 * 10.0);
    } else {
        let pad = ((x1 - x0) * 0.05).max(1e-3);
        (x0, x1) = (x0 - pad, x1 + pad);
    }
    let pad = ((y1 - y0) * 0.08).max(1e-3);
    (y0, y1) = (y0 - pad, y1 + pad);
    let root = backend.into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut b = ChartBuilder::on(&root);
    b.caption(title, ("sans-serif", 16)).margin(12).x_label_area_size(44).y_label_area_size(64);
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart.configure_mesh().x_desc(x_desc).y_desc(y_desc).draw().map_err(|e| anyhow::anyhow!("{e:?}"))?;
            for (i, (name, c)) in curves.iter().enumerate() {
                let col = COLORS[i % COLORS.len()];
                let mut c = c.clone();
                c.sort_by(|a, b| a.0.total_cmp(&b.0));
                chart
                    .draw_series(LineSeries::new(c.clone(), col.stroke_width(2)))
                    .map_err(|e| anyhow::anyhow!("{e:?}"))?
                    .label(name.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], col.stroke_width(2)));
                chart
                    .draw_series(c.iter().map(|&p| Circle::new(p, 3, col.filled())))
                    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
            }
            chart
                .configure_series_labels()
                // 17 px: plotters sizes the legend box from its estimate of the font (≈ 0.46 em
                // per character), which at this size matches the PNG's 8-pixel glyphs.
                .label_font(("sans-serif", 17))
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK)
                .draw()
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }};
    }
    if log_x {
        draw!(b.build_cartesian_2d((x0..x1).log_scale(), y0..y1).map_err(|e| anyhow::anyhow!("{e:?}"))?);
    } else {
        draw!(b.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| anyhow::anyhow!("{e:?}"))?);
    }
    root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    Ok(true)
}

/// A plotters backend that draws into an 8-bit RGB buffer with the 8×8 bitmap font of the
/// contact sheet (`font8x8`, public domain), so PNG plots need no TrueType font: plotters'
/// own bitmap backend needs one (`ttf` or `ab_glyph` plus a font file), and enabling those
/// features would make the SVG plots depend on a font being found too.
mod pixel_plot {
    use plotters_backend::text_anchor::{HPos, VPos};
    use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingBackend, DrawingErrorKind};

    /// The buffer, white-initialised; `rgb` is tightly packed, row-major from the top left.
    pub struct RgbBackend {
        pub size: (u32, u32),
        pub rgb: Vec<u8>,
    }

    impl RgbBackend {
        pub fn new(size: (u32, u32)) -> Self {
            RgbBackend { size, rgb: vec![255; size.0 as usize * size.1 as usize * 3] }
        }
    }

    /// Font pixels per glyph pixel for a plotters font size (px): 12–17 px → 1, 18+ → 2.
    fn scale(size: f64) -> i32 {
        ((size / 12.0).floor() as i32).clamp(1, 4)
    }

    #[derive(Debug)]
    pub struct Never;
    impl std::fmt::Display for Never {
        fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("unreachable")
        }
    }
    impl std::error::Error for Never {}

    impl DrawingBackend for &mut RgbBackend {
        type ErrorType = Never;

        fn get_size(&self) -> (u32, u32) {
            self.size
        }

        fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Never>> {
            Ok(())
        }

        fn present(&mut self) -> Result<(), DrawingErrorKind<Never>> {
            Ok(())
        }

        fn draw_pixel(&mut self, (x, y): BackendCoord, c: BackendColor) -> Result<(), DrawingErrorKind<Never>> {
            let (w, h) = self.size;
            if x < 0 || y < 0 || x >= w as i32 || y >= h as i32 || c.alpha <= 0.0 {
                return Ok(());
            }
            let i = (y as usize * w as usize + x as usize) * 3;
            let a = c.alpha.min(1.0);
            for (k, v) in [c.rgb.0, c.rgb.1, c.rgb.2].into_iter().enumerate() {
                let old = self.rgb[i + k] as f64;
                self.rgb[i + k] = (old + (v as f64 - old) * a).round() as u8;
            }
            Ok(())
        }

        fn estimate_text_size<S: BackendTextStyle>(
            &self,
            text: &str,
            style: &S,
        ) -> Result<(u32, u32), DrawingErrorKind<Never>> {
            let s = scale(style.size()) as u32;
            Ok((text.chars().count() as u32 * 8 * s, 8 * s))
        }

        fn draw_text<S: BackendTextStyle>(
            &mut self,
            text: &str,
            style: &S,
            pos: BackendCoord,
        ) -> Result<(), DrawingErrorKind<Never>> {
            use font8x8::UnicodeFonts;
            let color = style.color();
            let s = scale(style.size());
            let (w, h) = (text.chars().count() as i32 * 8 * s, 8 * s);
            let dx = match style.anchor().h_pos {
                HPos::Left => 0,
                HPos::Right => -w,
                HPos::Center => -w / 2,
            };
            let dy = match style.anchor().v_pos {
                VPos::Top => 0,
                VPos::Center => -h / 2,
                VPos::Bottom => -h,
            };
            let trans = style.transform();
            for (n, ch) in text.chars().enumerate() {
                let ch = match ch {
                    '—' | '–' | '−' => '-',
                    c => c,
                };
                let glyph = font8x8::BASIC_FONTS
                    .get(ch)
                    .or_else(|| font8x8::LATIN_FONTS.get(ch))
                    .or_else(|| font8x8::GREEK_FONTS.get(ch))
                    .or_else(|| font8x8::BASIC_FONTS.get('?'))
                    .unwrap_or([0; 8]);
                for (row, bits) in glyph.iter().enumerate() {
                    for col in 0..8 {
                        if bits >> col & 1 == 1 {
                            for sy in 0..s {
                                for sx in 0..s {
                                    let x = n as i32 * 8 * s + col * s + sx + dx;
                                    let y = row as i32 * s + sy + dy;
                                    let (x, y) = trans.transform(x, y);
                                    self.draw_pixel((pos.0 + x, pos.1 + y), color)?;
                                }
                            }
                        }
                    }
                }
            }
            Ok(())
        }
    }
}

/// Writes bench.json, bench.md and the plots into `dir`; returns the paths written.
pub fn write(r: &BenchReport, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create the output directory", dir.display()))?;
    let mut written = Vec::new();
    let p = dir.join("bench.json");
    crate::output::write_json(&p, r)?;
    written.push(p);
    let p = dir.join("bench.md");
    crate::output::write_atomic(&p, markdown(r).as_bytes())?;
    written.push(p);
    let dev = format!("{} · {}", r.adapter.name, r.date);
    // Time vs quality: one plot per scene and size, each series a curve over its swept setting.
    if r.plan.reference_steps > 0 {
        for scene in &r.plan.scenes {
            for &(w, h) in &r.plan.sizes {
                let mut curves: Curves = Vec::new();
                for x in r.records.iter().filter(|x| &x.scene == scene && x.size == [w, h]) {
                    let Some(q) = x.psnr_db else { continue };
                    let pt = (x.total_ms[0].max(1e-4), q);
                    match curves.iter_mut().find(|c| c.0 == x.series) {
                        Some(c) => c.1.push(pt),
                        None => curves.push((x.series.clone(), vec![pt])),
                    }
                }
                let name: String =
                    scene.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
                let p = dir.join(format!("time_vs_quality_{name}_{w}x{h}.svg"));
                if line_plot(
                    &p,
                    &format!("time vs quality — {name} {w}×{h} — {dev}"),
                    "technique time per frame, ms (median)",
                    "PSNR vs reference, dB",
                    true,
                    &curves,
                )? {
                    written.push(p.with_extension("png"));
                    written.push(p);
                }
            }
        }
    }
    // Time per scene: scene independence, one curve per configuration.
    if r.plan.scenes.len() > 1 {
        let size = r.plan.sizes[0];
        let mut curves: Curves = Vec::new();
        for x in r.records.iter().filter(|x| x.size == [size.0, size.1]) {
            let i = r.plan.scenes.iter().position(|s| load_name_matches(s, &x.scene)).unwrap_or(0) as f64;
            match curves.iter_mut().find(|c| c.0 == x.label) {
                Some(c) => c.1.push((i, x.total_ms[0])),
                None => curves.push((x.label.clone(), vec![(i, x.total_ms[0])])),
            }
        }
        let p = dir.join("time_per_scene.svg");
        if line_plot(
            &p,
            &format!("time per scene ({}) — {}×{} — {dev}", r.plan.scenes.join(", "), size.0, size.1),
            "scene (index in the list above)",
            "technique time per frame, ms (median)",
            false,
            &curves,
        )? {
            written.push(p.with_extension("png"));
            written.push(p);
        }
    }
    // Time vs a swept setting: one plot per scene, size and setting, each series a curve.
    let mut keys: Vec<&str> = Vec::new();
    for v in &r.plan.variants {
        if let Some((k, _)) = &v.sweep
            && !keys.contains(&k.as_str())
        {
            keys.push(k);
        }
    }
    for key in keys {
        for scene in &r.plan.scenes {
            for &(w, h) in &r.plan.sizes {
                let mut curves: Curves = Vec::new();
                for x in r.records.iter().filter(|x| load_name_matches(scene, &x.scene) && x.size == [w, h]) {
                    let Some((k, v)) = &x.sweep else { continue };
                    if k != key {
                        continue;
                    }
                    let pt = (*v, x.total_ms[0]);
                    match curves.iter_mut().find(|c| c.0 == x.series) {
                        Some(c) => c.1.push(pt),
                        None => curves.push((x.series.clone(), vec![pt])),
                    }
                }
                if curves.iter().map(|c| c.1.len()).sum::<usize>() < 2 {
                    continue;
                }
                let name: String =
                    scene.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
                let p = dir.join(format!("time_vs_{key}_{name}_{w}x{h}.svg"));
                if line_plot(
                    &p,
                    &format!("time vs {key} — {name} {w}×{h} — {dev}"),
                    key,
                    "technique time per frame, ms (median)",
                    false,
                    &curves,
                )? {
                    written.push(p.with_extension("png"));
                    written.push(p);
                }
            }
        }
    }
    // Time and quality vs the number of lights (the `lights` preset): one curve per technique.
    if r.plan.scenes.iter().all(|s| light_count(s).is_some()) && r.plan.scenes.len() > 1 {
        for (what, file, quality) in [
            ("technique time per frame, ms (median)", "time_vs_lights", false),
            ("PSNR vs reference, dB", "psnr_vs_lights", true),
        ] {
            let mut curves: Curves = Vec::new();
            for x in &r.records {
                let Some(n) = light_count(&x.scene) else { continue };
                let y = if quality { x.psnr_db } else { Some(x.total_ms[0]) };
                let Some(y) = y.filter(|y| y.is_finite()) else { continue };
                match curves.iter_mut().find(|c| c.0 == x.series) {
                    Some(c) => c.1.push((n as f64, y)),
                    None => curves.push((x.series.clone(), vec![(n as f64, y)])),
                }
            }
            let p = dir.join(format!("{file}.svg"));
            let (w, h) = r.plan.sizes[0];
            if line_plot(
                &p,
                &format!("{what} vs lights — {LIGHTS_SCENE} {w}×{h} — {dev}"),
                "lights",
                what,
                false,
                &curves,
            )? {
                written.push(p.with_extension("png"));
                written.push(p);
            }
        }
    }
    // Time vs resolution.
    if r.plan.sizes.len() > 1 {
        let mut curves: Curves = Vec::new();
        for x in r.records.iter().filter(|x| x.scene == r.records[0].scene) {
            let mp = x.size[0] as f64 * x.size[1] as f64 / 1e6;
            match curves.iter_mut().find(|c| c.0 == x.label) {
                Some(c) => c.1.push((mp, x.total_ms[0])),
                None => curves.push((x.label.clone(), vec![(mp, x.total_ms[0])])),
            }
        }
        let p = dir.join("time_vs_resolution.svg");
        if line_plot(
            &p,
            &format!("time vs resolution — {} — {dev}", r.records.first().map(|x| x.scene.as_str()).unwrap_or("")),
            "megapixels",
            "technique time per frame, ms (median)",
            false,
            &curves,
        )? {
            written.push(p.with_extension("png"));
            written.push(p);
        }
    }
    Ok(written)
}
