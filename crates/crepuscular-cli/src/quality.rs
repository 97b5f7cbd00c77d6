//! The quality table (docs/MODEL.md §4, rung 4): one measured technique × scene × backend
//! table, `docs/quality.toml`, from which every quality test takes its thresholds — each a
//! fixed margin from its own measurement ([`PSNR_MARGIN_DB`] below the PSNR,
//! [`FLIP_MARGIN`] above the FLIP), so no threshold drifts far below what a technique does.
//!
//! The tests measure at one configuration: 160×90, 1024² shadow maps, `reference` at 512 steps,
//! PSNR of the linear in-scattering (peak = the reference's maximum), FLIP mean of the
//! tone-mapped final images.
//!
//! Re-measuring (after a change that moves the figures on purpose): run the quality tests with
//! `CREPUSCULAR_QUALITY_MEASURE=DIR`; each row is then written into DIR (one file per row, so
//! parallel tests never share a file) instead of checked, and the ignored test
//! `write_quality_table` folds DIR into docs/quality.toml:
//!
//! ```sh
//! CREPUSCULAR_QUALITY_MEASURE=/tmp/q cargo test --workspace --release -- vs_reference
//! CREPUSCULAR_QUALITY_MEASURE=/tmp/q cargo test --release -p crepuscular-cli --test quality -- --ignored write_quality_table
//! ```

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// How far under its measured PSNR a row's threshold lies, dB.
pub const PSNR_MARGIN_DB: f64 = 2.0;
/// How far over its measured FLIP mean a row's threshold lies, as a fraction of the
/// measurement (FLIP is a mean error in [0, 1]: a relative margin, as dB are for PSNR).
pub const FLIP_MARGIN: f64 = 0.3;

/// The environment variable that switches the quality tests from checking to measuring.
pub const MEASURE_ENV: &str = "CREPUSCULAR_QUALITY_MEASURE";

/// One measured row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Row {
    /// The technique's name.
    pub technique: String,
    /// The scene (a built-in name, or a test's variant of one).
    pub scene: String,
    /// `cpu` or `gpu` (the adapter is in [`Table::adapter`]).
    pub backend: String,
    /// Measured PSNR of the in-scattering, dB.
    pub psnr_db: f64,
    /// Measured FLIP mean of the final image.
    pub flip: f64,
}

/// The table as docs/quality.toml holds it.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Table {
    /// When and on what it was measured.
    pub measured: String,
    /// The GPU adapter of the `gpu` rows.
    pub adapter: String,
    /// The rows, sorted by technique, scene and backend.
    pub rows: Vec<Row>,
}

/// docs/quality.toml in this repository.
pub fn table_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/quality.toml")
}

impl Table {
    /// Reads docs/quality.toml; the error names the file.
    pub fn load() -> Result<Table> {
        let path = table_path();
        let text = std::fs::read_to_string(&path).with_context(|| format!("{}", path.display()))?;
        let table: Table = toml::from_str(&text).with_context(|| format!("{}", path.display()))?;
        // A row whose figures are not finite and positive would pass (NaN) or fail everything.
        for r in &table.rows {
            if !(r.psnr_db.is_finite() && r.flip.is_finite() && r.flip >= 0.0) {
                bail!(
                    "{}: the row of {} on {} ({}) has psnr_db = {}, flip = {} (must be finite, flip >= 0)",
                    path.display(),
                    r.technique,
                    r.scene,
                    r.backend,
                    r.psnr_db,
                    r.flip
                );
            }
        }
        Ok(table)
    }

    /// The row of (technique, scene, backend).
    pub fn row(&self, technique: &str, scene: &str, backend: &str) -> Option<&Row> {
        self.rows.iter().find(|r| r.technique == technique && r.scene == scene && r.backend == backend)
    }
}

/// Checks a measurement against its row's thresholds (measured PSNR − [`PSNR_MARGIN_DB`],
/// measured FLIP × (1 + [`FLIP_MARGIN`])); the error names the row, the value and the bound.
/// With [`MEASURE_ENV`] set it records the measurement there instead and checks nothing.
pub fn check(technique: &str, scene: &str, backend: &str, psnr_db: f64, flip: f64) -> Result<()> {
    // Before recording too: a NaN row would pass every later measurement (no comparison with
    // NaN is true).
    if !psnr_db.is_finite() || !flip.is_finite() {
        bail!("{backend} {technique} on {scene}: PSNR {psnr_db}, FLIP {flip} (not finite)");
    }
    if let Some(dir) = std::env::var_os(MEASURE_ENV) {
        let row = Row { technique: technique.into(), scene: scene.into(), backend: backend.into(), psnr_db, flip };
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir).with_context(|| format!("{}", dir.display()))?;
        let file = dir.join(format!("{technique}--{scene}--{backend}.toml"));
        return crate::output::write_atomic(&file, toml::to_string(&row)?.as_bytes());
    }
    let table = Table::load()?;
    let Some(row) = table.row(technique, scene, backend) else {
        bail!(
            "{}: no row for {technique} on {scene} ({backend}): measure it ({MEASURE_ENV}, see crepuscular_cli::quality)",
            table_path().display()
        );
    };
    let (min_psnr, max_flip) = (row.psnr_db - PSNR_MARGIN_DB, row.flip * (1.0 + FLIP_MARGIN));
    if psnr_db < min_psnr {
        bail!("{backend} {technique} on {scene}: PSNR {psnr_db:.2} dB < {min_psnr:.2} (measured {:.2})", row.psnr_db);
    }
    if flip > max_flip {
        bail!("{backend} {technique} on {scene}: FLIP {flip:.4} > {max_flip:.4} (measured {:.4})", row.flip);
    }
    Ok(())
}

/// Folds the rows recorded in `dir` (by [`check`] under [`MEASURE_ENV`]) into docs/quality.toml:
/// a recorded row replaces the table's row of the same technique, scene and backend; the others
/// stay. Written atomically.
pub fn write_table(dir: &Path, adapter: &str, measured: &str) -> Result<Table> {
    let mut table = Table::load().unwrap_or_default();
    let mut recorded = 0;
    for entry in std::fs::read_dir(dir).with_context(|| format!("{}", dir.display()))? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "toml") {
            let text = std::fs::read_to_string(&path).with_context(|| format!("{}", path.display()))?;
            let mut row: Row = toml::from_str(&text).with_context(|| format!("{}", path.display()))?;
            // Readable figures: 0.01 dB and 10⁻⁴ of FLIP (a fraction of the margins).
            row.psnr_db = (row.psnr_db * 100.0).round() / 100.0;
            row.flip = (row.flip * 1e4).round() / 1e4;
            table.rows.retain(|r| !(r.technique == row.technique && r.scene == row.scene && r.backend == row.backend));
            table.rows.push(row);
            recorded += 1;
        }
    }
    if recorded == 0 {
        bail!("{}: no recorded rows", dir.display());
    }
    table.rows.sort_by(|a, b| (&a.technique, &a.scene, &a.backend).cmp(&(&b.technique, &b.scene, &b.backend)));
    table.measured = format!("{measured} ({recorded} rows re-measured)");
    table.adapter = adapter.into();
    let head = format!(
        "# The quality table (crates/crepuscular-cli/src/quality.rs): each technique at its defaults against\n\
         # `reference` (512 steps) at 160×90 with 1024² shadow maps; PSNR of the in-scattering (dB), FLIP mean\n\
         # of the final image. The quality tests' thresholds are each row's PSNR − {PSNR_MARGIN_DB} dB and FLIP × {}.\n\
         # Written by `write_quality_table` (see quality.rs); do not edit the figures by hand.\n\n",
        1.0 + FLIP_MARGIN
    );
    crate::output::write_atomic(&table_path(), format!("{head}{}", toml::to_string(&table)?).as_bytes())?;
    Ok(table)
}
