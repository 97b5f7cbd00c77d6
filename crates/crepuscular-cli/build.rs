//! Collects the doc comment of every field of every technique's settings struct
//! (`pub struct <Technique>Settings` under `crates/crepuscular/src/techniques/`) into a table
//! the viewer shows as tooltips, so each setting's tooltip is its documentation (meaning, unit,
//! default, cost) and a technique added later gets its tooltips without viewer changes.
//! The settings every marching technique shares (`MarchSettings`, `StepPolicy` in march.rs,
//! flattened into the techniques' settings) are read there and listed under each technique that
//! flattens them, by their keys (a `#[serde(rename = "…")]` names the key).
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

/// The documented fields of every `pub struct <name> {` in `text` whose name `accept` takes:
/// (struct name, key, type, doc). The key is the field's name, or its `#[serde(rename = "…")]`.
fn struct_docs(text: &str, accept: impl Fn(&str) -> bool) -> Vec<(String, String, String, String)> {
    let mut out = Vec::new();
    let mut current: Option<String> = None;
    let mut doc: Vec<String> = Vec::new();
    let mut rename: Option<String> = None;
    for line in text.lines() {
        let t = line.trim();
        if let Some(rest) = t.strip_prefix("pub struct ")
            && let Some(name) = rest.strip_suffix(" {")
            && !name.contains(['<', ' '])
            && accept(name)
        {
            current = Some(name.to_string());
            doc.clear();
            continue;
        }
        let Some(name) = &current else { continue };
        if line.starts_with('}') {
            current = None;
            continue;
        }
        if let Some(d) = t.strip_prefix("///") {
            doc.push(d.strip_prefix(' ').unwrap_or(d).to_string());
        } else if let Some(attr) = t.strip_prefix("#[serde(rename = \"") {
            rename = attr.split('"').next().map(str::to_string);
        } else if t.starts_with("#[") {
            // Other attributes between a doc comment and its field.
        } else if let Some(rest) = t.strip_prefix("pub ")
            && let Some((field, ty)) = rest.split_once(':')
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
            let key = rename.take().unwrap_or_else(|| field.to_string());
            let ty = ty.trim().trim_end_matches(',').to_string();
            if !text.is_empty() {
                out.push((name.clone(), key, ty, text.trim().to_string()));
            }
            doc.clear();
        } else {
            doc.clear();
            rename = None;
        }
    }
    out
}

/// (technique, key, doc) of every documented field of every `pub struct XSettings {` in `text`;
/// a field of a `shared` type (flattened) stands for that type's fields.
fn settings_docs(text: &str, shared: &[(String, String, String, String)]) -> Vec<(String, String, String)> {
    let mut out = Vec::new();
    let settings = |n: &str| n.strip_suffix("Settings").is_some_and(|t| !t.is_empty());
    for (name, key, ty, doc) in struct_docs(text, settings) {
        let technique = kebab(name.strip_suffix("Settings").expect("accepted above"));
        let flattened: Vec<_> = shared.iter().filter(|s| s.0 == ty).collect();
        if flattened.is_empty() {
            out.push((technique, key, doc));
        } else {
            out.extend(flattened.into_iter().map(|s| (technique.clone(), s.1.clone(), s.3.clone())));
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
    let march = root.join("../crepuscular/src/march.rs");
    println!("cargo:rerun-if-changed={}", march.display());
    let march_text = std::fs::read_to_string(&march).unwrap_or_default();
    let shared = struct_docs(&march_text, |n| n == "MarchSettings" || n == "StepPolicy");
    let mut table = String::from("const GENERATED_SETTING_DOCS: &[(&str, &str, &str)] = &[\n");
    for f in &files {
        println!("cargo:rerun-if-changed={}", f.display());
        let text = std::fs::read_to_string(f).unwrap_or_default();
        for (t, k, d) in settings_docs(&text, &shared) {
            let _ = writeln!(table, "    ({t:?}, {k:?}, {d:?}),");
        }
    }
    table.push_str("];\n");
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("setting_docs.rs");
    std::fs::write(&out, table).unwrap_or_else(|e| panic!("writing {}: {e}", out.display()));
}
