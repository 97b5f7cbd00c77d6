//! Output files, always written atomically, and reading images back.
//!
//! Every writer goes through [`write_atomic_with`]: the bytes go to a temporary file in the
//! destination's directory named `.<name>.tmp-<pid>`, which is fsynced and then renamed over the
//! destination. On any error the temporary is removed and an existing destination is left
//! untouched, so a reader never sees a half-written file.

use std::fs::{self, File, OpenOptions};
use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use crepuscular::Image;
use crepuscular::tonemap::srgb_eotf;
use image::{DynamicImage, ImageEncoder, ImageFormat, ImageReader, Rgba32FImage};

/// The temporary sibling of `path`: `<dir>/.<name>.tmp-<pid>`.
fn temp_path(path: &Path) -> Result<PathBuf> {
    let name = path.file_name().ok_or_else(|| anyhow!("{}: not a file path", path.display()))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp-{}", std::process::id()));
    Ok(path.with_file_name(tmp_name))
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, fsync, rename).
///
/// On error the temporary is removed and an existing file at `path` is left untouched.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |file| {
        file.write_all(bytes)?;
        Ok(())
    })
}

/// Writes `path` atomically with `f`, which receives the temporary file (opened for writing,
/// empty) and writes the whole contents; wrap it in a [`std::io::BufWriter`] for many small
/// writes. The file is then fsynced and renamed over `path`.
///
/// On any error — from `f`, the fsync or the rename — the temporary is removed and an existing
/// file at `path` is left untouched. Errors name `path`.
pub fn write_atomic_with(path: &Path, f: impl FnOnce(&mut File) -> Result<()>) -> Result<()> {
    let tmp = temp_path(path)?;
    let result = (|| -> Result<()> {
        let mut file = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&tmp)
            .with_context(|| format!("cannot create temporary file {}", tmp.display()))?;
        f(&mut file)?;
        file.flush()?;
        file.sync_all().with_context(|| format!("cannot sync {}", tmp.display()))?;
        drop(file);
        fs::rename(&tmp, path).with_context(|| format!("cannot rename {} to {}", tmp.display(), path.display()))?;
        Ok(())
    })();
    match result {
        Ok(()) => {
            sync_parent_dir(path);
            Ok(())
        }
        Err(err) => {
            let _ = fs::remove_file(&tmp);
            Err(err.context(format!("cannot write {}", path.display())))
        }
    }
}

/// Best effort: makes the rename durable by syncing the directory (Unix only; ignored elsewhere
/// and on failure, since the file itself is already complete).
fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
    #[cfg(not(unix))]
    let _ = path;
}

/// Writes tightly packed 8-bit RGB (`width * height * 3` bytes, row-major from the top left) as a
/// PNG, atomically.
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    let expected = width as usize * height as usize * 3;
    if rgb.len() != expected {
        bail!("cannot write {}: {}x{} RGB needs {expected} bytes, got {}", path.display(), width, height, rgb.len());
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .with_context(|| format!("cannot encode PNG for {}", path.display()))?;
    write_atomic(path, &png)
}

/// Writes a linear image as 32-bit float RGBA OpenEXR, atomically. Values are stored as they
/// are (no tone mapping, non-finite values included).
pub fn write_exr(path: &Path, img: &Image) -> Result<()> {
    let flat: Vec<f32> = img.pixels.iter().flatten().copied().collect();
    let buffer = Rgba32FImage::from_raw(img.width, img.height, flat).ok_or_else(|| {
        anyhow!("cannot write {}: {}x{} image has {} pixels", path.display(), img.width, img.height, img.pixels.len())
    })?;
    let mut cursor = Cursor::new(Vec::new());
    DynamicImage::ImageRgba32F(buffer)
        .write_to(&mut cursor, ImageFormat::OpenExr)
        .with_context(|| format!("cannot encode OpenEXR for {}", path.display()))?;
    write_atomic(path, &cursor.into_inner())
}

/// Reads an image into linear RGBA floats.
///
/// OpenEXR files are taken as linear radiance as stored (missing alpha reads as 1). Any other
/// format the `image` crate decodes (PNG in this build) is taken as sRGB-encoded: colour channels
/// are decoded with the sRGB EOTF, alpha is scaled linearly to `[0, 1]`. The format is
/// detected from the file contents, falling back to the extension. Errors name the file.
pub fn read_exr(path: &Path) -> Result<Image> {
    let reader = ImageReader::open(path)
        .with_context(|| format!("cannot open {}", path.display()))?
        .with_guessed_format()
        .with_context(|| format!("cannot read {}", path.display()))?;
    let format = reader.format();
    let decoded = reader.decode().with_context(|| format!("cannot decode image {}", path.display()))?;
    let linear_source = format == Some(ImageFormat::OpenExr)
        || matches!(decoded, DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_));
    let rgba = decoded.into_rgba32f();
    let (width, height) = rgba.dimensions();
    let pixels = rgba
        .pixels()
        .map(|p| {
            let [r, g, b, a] = p.0;
            if linear_source { [r, g, b, a] } else { [srgb_eotf(r), srgb_eotf(g), srgb_eotf(b), a] }
        })
        .collect();
    Ok(Image { width, height, pixels })
}

/// Writes `value` as pretty-printed JSON (with a trailing newline), atomically.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let mut bytes =
        serde_json::to_vec_pretty(value).with_context(|| format!("cannot serialise JSON for {}", path.display()))?;
    bytes.push(b'\n');
    write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh scratch directory under the system temp dir.
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "crepuscular-output-{name}-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporary() {
        let dir = scratch("replace");
        let path = dir.join("a.txt");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        assert_eq!(entries(&dir), vec!["a.txt".to_string()]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failed_write_keeps_old_file_and_removes_temporary() {
        let dir = scratch("fail");
        let path = dir.join("keep.json");
        write_atomic(&path, b"old").unwrap();
        let err = write_atomic_with(&path, |f| {
            f.write_all(b"partial")?;
            bail!("boom")
        })
        .unwrap_err();
        let msg = format!("{err:#}");
        assert!(msg.contains("keep.json") && msg.contains("boom"), "{msg}");
        assert_eq!(fs::read(&path).unwrap(), b"old");
        assert_eq!(entries(&dir), vec!["keep.json".to_string()]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_directory_is_an_error_naming_the_file() {
        let dir = scratch("missing");
        let path = dir.join("nope").join("x.png");
        let msg = format!("{:#}", write_atomic(&path, b"x").unwrap_err());
        assert!(msg.contains("x.png"), "{msg}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn exr_round_trip_is_exact() {
        let dir = scratch("exr");
        let path = dir.join("img.exr");
        let mut img = Image::new(3, 2);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = [i as f32 * 0.37, 1.0e4 + i as f32, 1.0e-6 * i as f32, 0.5];
        }
        write_exr(&path, &img).unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!(back, img);
        assert_eq!(entries(&dir), vec!["img.exr".to_string()]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn png_round_trip_decodes_srgb_to_linear() {
        let dir = scratch("png");
        let path = dir.join("img.png");
        let rgb = [0u8, 128, 255, 10, 20, 30];
        write_png_rgb8(&path, 2, 1, &rgb).unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (2, 1));
        for (i, &v) in rgb.iter().enumerate() {
            let got = back.pixels[i / 3][i % 3];
            let want = srgb_eotf(v as f32 / 255.0);
            assert!((got - want).abs() < 1e-6, "{i}: {got} vs {want}");
        }
        assert!((back.pixels[0][1] - 0.2158605).abs() < 1e-4);
        assert_eq!(back.pixels[0][3], 1.0);
        assert!(write_png_rgb8(&path, 2, 2, &rgb).is_err());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn read_errors_name_the_file() {
        let dir = scratch("readerr");
        let missing = dir.join("absent.exr");
        let msg = format!("{:#}", read_exr(&missing).unwrap_err());
        assert!(msg.contains("absent.exr"), "{msg}");
        let garbage = dir.join("garbage.exr");
        fs::write(&garbage, b"not an image").unwrap();
        let msg = format!("{:#}", read_exr(&garbage).unwrap_err());
        assert!(msg.contains("garbage.exr"), "{msg}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn json_is_pretty_with_trailing_newline() {
        let dir = scratch("json");
        let path = dir.join("m.json");
        write_json(&path, &serde_json::json!({"a": 1, "b": [1, 2]})).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.contains("\n  \"a\": 1"), "{text}");
        assert!(text.ends_with("}\n"));
        fs::remove_dir_all(&dir).unwrap();
    }
}
