//! Collects the doc comment of every field of every technique's settings struct
//! (`pub struct <Technique>Settings` under `crates/crepuscular/src/techniques/`) into a table
//! the viewer shows as tooltips, so each setting's tooltip is its documentation (meaning, unit,
//! default, cost) and a technique added later gets its tooltips without viewer changes.
//! Writes `$OUT_DIR/setting_docs.rs`: `const GENERATED_SETTING_DOCS: &[(&str, &str, &str)]`
//! of (technique, field, doc). Without the library's sources (a packaged crate) the table is
//! empty and the viewer shows no tooltips.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// `BruteForce` → `brute-force`.
fn kebab(camel: &str) -> String {
    let mut s = String::new();
    for (i, c) in camel.chars().enumerate() {
        if c.is_ascii_uppercase() {
            if i > 0 {
                s.push('-');
            }
            s.push(c.to_ascii_lowercase());
        } else {
            s.push(c);
        }
    }
    s
}

/// (technique, field, doc) of every documented field of every `pub struct XSettings {` in `text`.
fn settings_docs(text: &str) -> Vec<(String, String, String)> {
    let mut out = Vec::new();
    let mut technique: Option<String> = None;
    let mut doc: Vec<String> = Vec::new();
    for line in text.lines() {
        let t = line.trim();
        if let Some(rest) = t.strip_prefix("pub struct ")
            && let Some(name) = rest.strip_suffix(" {").and_then(|n| n.strip_suffix("Settings"))
            && !name.is_empty()
            && !name.contains(['<', ' '])
        {
            technique = Some(kebab(name));
            doc.clear();
            continue;
        }
        let Some(tech) = &technique else { continue };
        if line.starts_with('}') {
            technique = None;
            continue;
        }
        if let Some(d) = t.strip_prefix("///") {
            doc.push(d.strip_prefix(' ').unwrap_or(d).to_string());
        } else if t.starts_with("#[") {
            // Attributes between a doc comment and its field.
        } else if let Some(rest) = t.strip_prefix("pub ")
            && let Some((field, _)) = rest.split_once(':')
            && field.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            // Paragraphs stay apart; lines within one are joined.
            let mut text = String::new();
            for l in &doc {
                if l.is_empty() {
                    text.push_str("\n\n");
                } else {
                    if !text.is_empty() && !text.ends_with('\n') {
                        text.push(' ');
                    }
                    text.push_str(l);
                }
            }
            if !text.is_empty() {
                out.push((tech.clone(), field.to_string(), text.trim().to_string()));
            }
            doc.clear();
        } else {
            doc.clear();
        }
    }
    out
}

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let techniques = root.join("../crepuscular/src/techniques");
    println!("cargo:rerun-if-changed={}", techniques.display());
    let mut files = Vec::new();
    rust_files(&techniques, &mut files);
    let mut table = String::from("const GENERATED_SETTING_DOCS: &[(&str, &str, &str)] = &[\n");
    for f in &files {
        println!("cargo:rerun-if-changed={}", f.display());
        let text = std::fs::read_to_string(f).unwrap_or_default();
        for (t, k, d) in settings_docs(&text) {
            let _ = writeln!(table, "    ({t:?}, {k:?}, {d:?}),");
        }
    }
    table.push_str("];\n");
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("setting_docs.rs");
    std::fs::write(&out, table).unwrap_or_else(|e| panic!("writing {}: {e}", out.display()));
}
