//! Geometry builders and mesh import.
//!
//! Every builder returns world-space triangles ([`Geometry`]) with per-vertex albedo. The
//! procedural primitives are unit-sized and centred so that a [`Transform`] places them:
//!
//! | builder | shape before the transform | normals |
//! | --- | --- | --- |
//! | [`plane`] | 1 × 1 square in XZ at y = 0, normal +Y (one quad; culling is off) | flat |
//! | [`cuboid`] | unit cube centred at the origin (the scene-file kind `box`) | flat |
//! | [`sphere`] | UV sphere of radius 0.5, 24 × 16 segments | smooth |
//! | [`cylinder`] | radius 0.5, height 1 along Y, centred, 24 segments, capped | smooth sides, flat caps |
//!
//! [`load_mesh`] imports glTF 2.0 (`.gltf` / `.glb`) and Wavefront OBJ (`.obj`) files.

use crate::file::SceneError;
use crate::scene::{Geometry, Vertex};
use glam::{Mat3, Mat4, Vec3};
use std::f32::consts::PI;
use std::path::Path;

/// Most triangles one imported mesh file may hold; more is an error naming the file and the
/// count (a guard against runaway memory use).
pub const MAX_MESH_TRIANGLES: usize = 5_000_000;

/// Largest mesh file (and glTF buffer file) read, bytes: 1 GiB. Larger is an error naming the
/// file and its size, before anything is read.
pub const MAX_MESH_FILE_BYTES: u64 = 1 << 30;

/// Longest glTF `data:` buffer URI accepted, bytes of URI text (64 MiB, ≈ 48 MiB of data).
pub const MAX_DATA_URI_BYTES: usize = 64 << 20;

/// Albedo used when neither the scene object nor the mesh's material gives one: linear grey 0.7.
pub const DEFAULT_ALBEDO: Vec3 = Vec3::splat(0.7);

/// Placement of an object: scale, then rotate (Euler angles in degrees about X, then Y, then Z,
/// i.e. `R = Rz·Ry·Rx`), then translate. Default: identity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Translation, world units (metres). Default 0.
    pub translate: Vec3,
    /// Rotation angles about the X, Y and Z axes, degrees, applied X first, then Y, then Z.
    /// Default 0.
    pub rotate_degrees: Vec3,
    /// Scale per axis, applied first (in the object's own frame). Default 1.
    pub scale: Vec3,
}

impl Default for Transform {
    fn default() -> Self {
        Self { translate: Vec3::ZERO, rotate_degrees: Vec3::ZERO, scale: Vec3::ONE }
    }
}

impl Transform {
    /// A pure translation.
    pub fn at(translate: Vec3) -> Self {
        Self { translate, ..Self::default() }
    }
    /// Translation and per-axis scale, no rotation.
    pub fn at_scaled(translate: Vec3, scale: Vec3) -> Self {
        Self { translate, scale, ..Self::default() }
    }
    /// Returns this transform with the given rotation (degrees, X then Y then Z).
    pub fn rotated(mut self, rotate_degrees: Vec3) -> Self {
        self.rotate_degrees = rotate_degrees;
        self
    }
    /// The rotation part, `Rz·Ry·Rx`.
    pub fn rotation(&self) -> Mat3 {
        let r = self.rotate_degrees * (PI / 180.0);
        Mat3::from_rotation_z(r.z) * Mat3::from_rotation_y(r.y) * Mat3::from_rotation_x(r.x)
    }
    /// Object → world matrix `T·R·S`.
    pub fn matrix(&self) -> Mat4 {
        Mat4::from_translation(self.translate) * Mat4::from_mat3(self.rotation()) * Mat4::from_scale(self.scale)
    }
}

/// Maps object-space points and normals to world space with one affine matrix, keeping
/// normals outward under mirroring and finite under degenerate (zero) scales.
struct Placer {
    m: Mat4,
    normal_m: Mat3,
    /// True when the matrix mirrors (negative determinant): triangle winding is flipped so
    /// that front faces stay counter-clockwise around their normals.
    flip: bool,
}

impl Placer {
    fn new(m: Mat4) -> Self {
        let m3 = Mat3::from_mat4(m);
        let det = m3.determinant();
        // Cofactor matrix = det·M⁻ᵀ; it exists for singular matrices too. Multiplying by the
        // determinant's sign gives the direction of M⁻ᵀ·n.
        let cof = Mat3::from_cols(m3.y_axis.cross(m3.z_axis), m3.z_axis.cross(m3.x_axis), m3.x_axis.cross(m3.y_axis));
        let s = if det < 0.0 { -1.0 } else { 1.0 };
        Self { m, normal_m: cof * s, flip: det < 0.0 }
    }
    fn point(&self, p: Vec3) -> Vec3 {
        self.m.transform_point3(p)
    }
    fn normal(&self, n: Vec3) -> Vec3 {
        let w = self.normal_m * n;
        let l = w.length();
        if l > 1e-30 && l.is_finite() { w / l } else { n.normalize_or(Vec3::Y) }
    }
}

/// Accumulates world-space triangles.
struct Builder<'a> {
    g: Geometry,
    placer: &'a Placer,
    albedo: [f32; 3],
}

impl<'a> Builder<'a> {
    fn new(placer: &'a Placer, albedo: Vec3) -> Self {
        Self { g: Geometry::default(), placer, albedo: albedo.to_array() }
    }
    /// Adds an object-space vertex; returns its index.
    fn vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        let i = self.g.vertices.len() as u32;
        self.g.vertices.push(Vertex {
            position: self.placer.point(p).to_array(),
            normal: self.placer.normal(n).to_array(),
            albedo: self.albedo,
        });
        i
    }
    fn tri(&mut self, a: u32, b: u32, c: u32) {
        if self.placer.flip {
            self.g.indices.extend_from_slice(&[a, c, b]);
        } else {
            self.g.indices.extend_from_slice(&[a, b, c]);
        }
    }
    /// A flat quad with corners in counter-clockwise order around `n`.
    fn quad(&mut self, corners: [Vec3; 4], n: Vec3) {
        let i = corners.map(|p| self.vertex(p, n));
        self.tri(i[0], i[1], i[2]);
        self.tri(i[0], i[2], i[3]);
    }
}

/// A 1 × 1 square in the XZ plane at y = 0, centred at the origin, normal +Y, placed by
/// `transform` (scale it to make a ground). One quad, two triangles; the host renderer does
/// not cull back faces, so it is visible and shadows from both sides.
pub fn plane(transform: &Transform, albedo: Vec3) -> Geometry {
    let placer = Placer::new(transform.matrix());
    let mut b = Builder::new(&placer, albedo);
    let h = 0.5;
    b.quad([Vec3::new(-h, 0.0, -h), Vec3::new(-h, 0.0, h), Vec3::new(h, 0.0, h), Vec3::new(h, 0.0, -h)], Vec3::Y);
    b.g
}

/// A unit cube centred at the origin (12 triangles, flat normals), placed by `transform`.
/// This is the scene-file object kind `box` (`box` is a Rust keyword).
pub fn cuboid(transform: &Transform, albedo: Vec3) -> Geometry {
    let placer = Placer::new(transform.matrix());
    let mut b = Builder::new(&placer, albedo);
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            // Two tangents u, v with u × v = n.
            let mut u = Vec3::ZERO;
            u[(axis + 1) % 3] = 1.0;
            let mut v = Vec3::ZERO;
            v[(axis + 2) % 3] = sign;
            let c = n * 0.5;
            let (u, v) = (u * 0.5, v * 0.5);
            b.quad([c - u - v, c + u - v, c + u + v, c - u + v], n);
        }
    }
    b.g
}

/// A UV sphere of radius 0.5 centred at the origin with smooth normals, 24 segments around
/// and 16 from pole to pole, placed by `transform`.
pub fn sphere(transform: &Transform, albedo: Vec3) -> Geometry {
    sphere_segments(transform, albedo, 24, 16)
}

/// A UV sphere like [`sphere`] with `around` (≥ 3) segments about Y and `rings` (≥ 2) from pole
/// to pole.
pub fn sphere_segments(transform: &Transform, albedo: Vec3, around: u32, rings: u32) -> Geometry {
    let (around, rings) = (around.max(3), rings.max(2));
    let placer = Placer::new(transform.matrix());
    let mut b = Builder::new(&placer, albedo);
    for j in 0..=rings {
        let theta = PI * j as f32 / rings as f32;
        for i in 0..=around {
            let phi = 2.0 * PI * i as f32 / around as f32;
            let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), -theta.sin() * phi.sin());
            b.vertex(n * 0.5, n);
        }
    }
    let row = around + 1;
    for j in 0..rings {
        for i in 0..around {
            let a = j * row + i;
            let c = a + row;
            if j != 0 {
                b.tri(a, c, a + 1);
            }
            if j != rings - 1 {
                b.tri(a + 1, c, c + 1);
            }
        }
    }
    b.g
}

/// A capped cylinder of radius 0.5 and height 1 along Y, centred at the origin, 24 segments,
/// placed by `transform` (columns, trunks). Sides have smooth normals, caps flat ones.
pub fn cylinder(transform: &Transform, albedo: Vec3) -> Geometry {
    cylinder_segments(transform, albedo, 24)
}

/// A cylinder like [`cylinder`] with `segments` (≥ 3) around its axis.
pub fn cylinder_segments(transform: &Transform, albedo: Vec3, segments: u32) -> Geometry {
    let segments = segments.max(3);
    let placer = Placer::new(transform.matrix());
    let mut b = Builder::new(&placer, albedo);
    let ring = |i: u32| {
        let phi = 2.0 * PI * (i % segments) as f32 / segments as f32;
        Vec3::new(phi.cos(), 0.0, -phi.sin())
    };
    // Sides.
    let base = b.g.vertices.len() as u32;
    for i in 0..=segments {
        let d = ring(i);
        b.vertex(d * 0.5 - Vec3::Y * 0.5, d);
        b.vertex(d * 0.5 + Vec3::Y * 0.5, d);
    }
    for i in 0..segments {
        let a = base + 2 * i;
        b.tri(a, a + 2, a + 3);
        b.tri(a, a + 3, a + 1);
    }
    // Caps.
    for (y, n) in [(0.5f32, Vec3::Y), (-0.5, Vec3::NEG_Y)] {
        let c = b.vertex(Vec3::new(0.0, y, 0.0), n);
        let first = b.g.vertices.len() as u32;
        for i in 0..segments {
            b.vertex(ring(i) * 0.5 + Vec3::Y * y, n);
        }
        for i in 0..segments {
            let (p, q) = (first + i, first + (i + 1) % segments);
            if y > 0.0 { b.tri(c, p, q) } else { b.tri(c, q, p) }
        }
    }
    b.g
}

/// A single triangle with the given world-space corners, a flat normal from their winding
/// (counter-clockwise front) and the given albedo. Degenerate triangles get normal +Y.
pub fn triangle(a: Vec3, b: Vec3, c: Vec3, albedo: Vec3) -> Geometry {
    let n = (b - a).cross(c - a).normalize_or(Vec3::Y).to_array();
    let albedo = albedo.to_array();
    Geometry {
        vertices: [a, b, c].map(|p| Vertex { position: p.to_array(), normal: n, albedo }).to_vec(),
        indices: vec![0, 1, 2],
    }
}

/// A flat world-space quad (two triangles) with corners in order around its boundary.
pub fn quad(corners: [Vec3; 4], albedo: Vec3) -> Geometry {
    let [a, b, c, d] = corners;
    let n = (c - a).cross(d - b).normalize_or(Vec3::Y).to_array();
    let albedo = albedo.to_array();
    Geometry {
        vertices: corners.map(|p| Vertex { position: p.to_array(), normal: n, albedo }).to_vec(),
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

// ---------------------------------------------------------------------------------------------
// Import.

fn mesh_err(path: &Path, message: impl std::fmt::Display) -> SceneError {
    SceneError::Mesh { file: path.display().to_string(), message: message.to_string() }
}

/// Collects imported triangles, checks them and places them in the world.
struct Importer<'p> {
    path: &'p Path,
    g: Geometry,
    dropped: usize,
    /// Triangles seen so far (kept or dropped), for the size limit.
    seen: usize,
}

impl<'p> Importer<'p> {
    fn new(path: &'p Path) -> Self {
        Self { path, g: Geometry::default(), dropped: 0, seen: 0 }
    }

    fn count(&mut self, triangles: usize) -> Result<(), SceneError> {
        self.seen = self.seen.saturating_add(triangles);
        if self.seen > MAX_MESH_TRIANGLES {
            return Err(mesh_err(
                self.path,
                format!("{} triangles or more, more than the limit of {MAX_MESH_TRIANGLES}", self.seen),
            ));
        }
        Ok(())
    }

    /// Adds one primitive: object-space `positions`, optional `normals` (same length),
    /// triangle-list `indices`, placed by `m`.
    fn add(
        &mut self,
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
        indices: &[u32],
        m: Mat4,
        albedo: Vec3,
    ) -> Result<(), SceneError> {
        let tris = indices.len() / 3;
        self.count(tris)?;
        let placer = Placer::new(m);
        let albedo = albedo.to_array();
        let world: Vec<Vec3> = positions.iter().map(|&p| placer.point(p)).collect();
        for (i, (p, w)) in positions.iter().zip(&world).enumerate() {
            if !p.is_finite() || !w.is_finite() {
                return Err(mesh_err(self.path, format!("vertex {i} has a non-finite position {p}")));
            }
        }
        if let Some(ns) = normals {
            if ns.len() != positions.len() {
                return Err(mesh_err(self.path, format!("{} normals for {} positions", ns.len(), positions.len())));
            }
            if let Some((i, n)) = ns.iter().enumerate().find(|(_, n)| !n.is_finite()) {
                return Err(mesh_err(self.path, format!("vertex {i} has a non-finite normal {n}")));
            }
        }
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
            return Err(mesh_err(self.path, format!("index {bad} out of range for {} vertices", positions.len())));
        }
        let area2 = |t: &[u32]| {
            let (a, b, c) = (world[t[0] as usize], world[t[1] as usize], world[t[2] as usize]);
            (b - a).cross(c - a)
        };
        match normals {
            Some(ns) => {
                let base = self.g.vertices.len() as u32;
                self.g.vertices.extend(world.iter().zip(ns).map(|(p, &n)| Vertex {
                    position: p.to_array(),
                    normal: placer.normal(n).to_array(),
                    albedo,
                }));
                for t in indices.chunks_exact(3) {
                    let c = area2(t);
                    if c.length_squared() <= 0.0 || c.is_nan() {
                        self.dropped += 1;
                        continue;
                    }
                    let (a, b, c) = (t[0] + base, t[1] + base, t[2] + base);
                    if placer.flip {
                        self.g.indices.extend_from_slice(&[a, c, b]);
                    } else {
                        self.g.indices.extend_from_slice(&[a, b, c]);
                    }
                }
            }
            None => {
                // Flat normals: three vertices of their own per triangle.
                for t in indices.chunks_exact(3) {
                    let mut c = area2(t);
                    if c.length_squared() <= 0.0 || c.is_nan() {
                        self.dropped += 1;
                        continue;
                    }
                    let mut order = [t[0], t[1], t[2]];
                    if placer.flip {
                        order.swap(1, 2);
                        c = -c;
                    }
                    let n = c.normalize_or(Vec3::Y).to_array();
                    let base = self.g.vertices.len() as u32;
                    for i in order {
                        self.g.vertices.push(Vertex { position: world[i as usize].to_array(), normal: n, albedo });
                    }
                    self.g.indices.extend_from_slice(&[base, base + 1, base + 2]);
                }
            }
        }
        Ok(())
    }

    fn finish(self) -> Geometry {
        if self.dropped > 0 {
            log::warn!("{}: dropped {} zero-area triangles", self.path.display(), self.dropped);
        }
        self.g
    }
}

/// Imports a triangle mesh from a glTF 2.0 (`.gltf` with embedded or relative buffers, `.glb`)
/// or Wavefront OBJ (`.obj`) file, placed by `transform` (applied after the file's own node
/// transforms).
///
/// - glTF: walks the default scene (else the first one; else every mesh once) applying node
///   transforms; reads positions and normals of triangle primitives (strips and fans are
///   converted; points and lines are skipped); computes flat normals where a primitive has
///   none. Albedo: `albedo` if given, else the material's base colour factor (linear RGB).
///   Images are not loaded. Buffer URIs must be relative paths without `..` (or `data:` URIs).
/// - OBJ: faces are triangulated; normals are used when every vertex has one, else flat
///   normals are computed. Albedo: `albedo` if given, else the MTL diffuse colour if the
///   material library loads (only from the OBJ's directory or below), else [`DEFAULT_ALBEDO`].
///
/// Errors (naming the file): unreadable or malformed files, indices out of range, non-finite
/// positions or normals, more than [`MAX_MESH_TRIANGLES`] triangles, an unknown extension.
/// Zero-area triangles are dropped and counted in a `log::warn!`. Never panics.
pub fn load_mesh(path: &Path, transform: &Transform, albedo: Option<Vec3>) -> Result<Geometry, SceneError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    let run = || match ext.as_deref() {
        Some("gltf") | Some("glb") => load_gltf(path, transform, albedo),
        Some("obj") => load_obj(path, transform, albedo),
        _ => Err(mesh_err(path, "unknown mesh format (expected .gltf, .glb or .obj)")),
    };
    // The importers check what they read, but a malformed file must never take the process
    // down: turn any panic inside a third-party parser into an error.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)) {
        Ok(r) => r,
        Err(_) => Err(mesh_err(path, "malformed mesh file (the importer failed)")),
    }
}

fn load_obj(path: &Path, transform: &Transform, albedo: Option<Vec3>) -> Result<Geometry, SceneError> {
    check_file_size(path, path)?;
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let file = std::fs::File::open(path).map_err(|e| mesh_err(path, e))?;
    let mut reader = std::io::BufReader::new(file);
    let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    // Material libraries load only from the OBJ's directory or below (no absolute paths, no
    // `..`); a library that fails to load leaves the default albedo.
    let load_mtl = |p: &Path| {
        if !is_safe_relative(&p.to_string_lossy()) {
            log::warn!("{}: ignoring material library {:?} outside the mesh's directory", path.display(), p);
            return Err(tobj::LoadError::OpenFileFailed);
        }
        tobj::load_mtl(base.join(p))
    };
    let (models, materials) = tobj::load_obj_buf(&mut reader, &options, load_mtl).map_err(|e| mesh_err(path, e))?;
    let materials = materials.unwrap_or_default();
    let total: usize = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    let mut imp = Importer::new(path);
    if total > MAX_MESH_TRIANGLES {
        return Err(mesh_err(path, format!("{total} triangles, more than the limit of {MAX_MESH_TRIANGLES}")));
    }
    let m = transform.matrix();
    for model in &models {
        let mesh = &model.mesh;
        if mesh.positions.len() % 3 != 0 || mesh.indices.len() % 3 != 0 {
            return Err(mesh_err(path, format!("malformed data in object `{}`", model.name)));
        }
        let positions: Vec<Vec3> = mesh.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let normals: Vec<Vec3> = mesh.normals.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let normals = (!normals.is_empty() && normals.len() == positions.len()).then_some(normals.as_slice());
        let a = albedo
            .or_else(|| {
                mesh.material_id
                    .and_then(|i| materials.get(i))
                    .and_then(|mat| mat.diffuse)
                    .map(Vec3::from)
                    .filter(|c| c.is_finite())
                    .map(|c| c.clamp(Vec3::ZERO, Vec3::ONE))
            })
            .unwrap_or(DEFAULT_ALBEDO);
        imp.add(&positions, normals, &mesh.indices, m, a)?;
    }
    Ok(imp.finish())
}

/// True for a relative path that stays inside its base directory: not empty, not absolute (no
/// leading `/` or `\`, no drive letter or URI scheme), no `..` component (either separator).
pub(crate) fn is_safe_relative(p: &str) -> bool {
    !p.trim().is_empty()
        && !p.starts_with(['/', '\\'])
        && !p.contains(':')
        && !Path::new(p).is_absolute()
        && !p.split(['/', '\\']).any(|c| c.trim() == "..")
}

/// Decodes `%XX` escapes (the glTF importer decodes them before opening a URI).
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = b.get(i + 1..i + 3).and_then(|h| std::str::from_utf8(h).ok());
        match (b[i], hex.and_then(|h| u8::from_str_radix(h, 16).ok())) {
            (b'%', Some(v)) => {
                out.push(v);
                i += 3;
            }
            (c, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Rejects buffer URIs that would read outside the glTF file's directory (absolute paths, `..`,
/// schemes, symbolic links leading out), external buffers over [`MAX_MESH_FILE_BYTES`] and
/// `data:` URIs over [`MAX_DATA_URI_BYTES`].
fn check_gltf_uri(path: &Path, uri: &str) -> Result<(), SceneError> {
    if uri.starts_with("data:") {
        if uri.len() > MAX_DATA_URI_BYTES {
            return Err(mesh_err(
                path,
                format!("a data: buffer uri of {} bytes, more than the limit of {MAX_DATA_URI_BYTES}", uri.len()),
            ));
        }
        return Ok(());
    }
    let bad = !is_safe_relative(uri) || !is_safe_relative(&percent_decode(uri));
    if bad {
        return Err(mesh_err(path, format!("buffer uri {uri:?} must be a relative path inside the mesh's directory")));
    }
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let target = base.join(percent_decode(uri));
    if let (Ok(b), Ok(t)) = (base.canonicalize(), target.canonicalize())
        && !t.starts_with(&b)
    {
        return Err(mesh_err(
            path,
            format!("buffer uri {uri:?} leads outside the mesh's directory (a symbolic link?)"),
        ));
    }
    check_file_size(path, &target)
}

/// [`MAX_MESH_FILE_BYTES`] for `file` (a missing file is left to the reader's own error).
fn check_file_size(path: &Path, file: &Path) -> Result<(), SceneError> {
    match std::fs::metadata(file) {
        Ok(m) if m.len() > MAX_MESH_FILE_BYTES => Err(mesh_err(
            path,
            format!("{} is {} bytes, more than the limit of {MAX_MESH_FILE_BYTES}", file.display(), m.len()),
        )),
        _ => Ok(()),
    }
}

fn load_gltf(path: &Path, transform: &Transform, albedo: Option<Vec3>) -> Result<Geometry, SceneError> {
    check_file_size(path, path)?;
    let bytes = std::fs::read(path).map_err(|e| mesh_err(path, e))?;
    let gltf = gltf::Gltf::from_slice(&bytes).map_err(|e| mesh_err(path, e))?;
    drop(bytes);
    for buffer in gltf.document.buffers() {
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            check_gltf_uri(path, uri)?;
        }
    }
    let base = path.parent().unwrap_or(Path::new("."));
    let doc = &gltf.document;
    let buffers = gltf::import_buffers(doc, Some(base), gltf.blob.clone()).map_err(|e| mesh_err(path, e))?;

    let mut imp = Importer::new(path);
    let root = transform.matrix();
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    match scene {
        Some(scene) => {
            for node in scene.nodes() {
                walk_node(&mut imp, &buffers, node, root, albedo, 0)?;
            }
        }
        None => {
            for mesh in doc.meshes() {
                add_gltf_mesh(&mut imp, &buffers, mesh, root, albedo)?;
            }
        }
    }
    Ok(imp.finish())
}

/// Deepest node hierarchy accepted (guards against cyclic or absurd files).
const MAX_NODE_DEPTH: usize = 64;

fn walk_node(
    imp: &mut Importer,
    buffers: &[gltf::buffer::Data],
    node: gltf::Node,
    parent: Mat4,
    albedo: Option<Vec3>,
    depth: usize,
) -> Result<(), SceneError> {
    if depth > MAX_NODE_DEPTH {
        return Err(mesh_err(imp.path, format!("node hierarchy deeper than {MAX_NODE_DEPTH} (a cycle?)")));
    }
    let local = Mat4::from_cols_array_2d(&node.transform().matrix());
    if !local.is_finite() {
        return Err(mesh_err(imp.path, format!("node {} has a non-finite transform", node.index())));
    }
    let m = parent * local;
    if let Some(mesh) = node.mesh() {
        add_gltf_mesh(imp, buffers, mesh, m, albedo)?;
    }
    for child in node.children() {
        walk_node(imp, buffers, child, m, albedo, depth + 1)?;
    }
    Ok(())
}

fn add_gltf_mesh(
    imp: &mut Importer,
    buffers: &[gltf::buffer::Data],
    mesh: gltf::Mesh,
    m: Mat4,
    albedo: Option<Vec3>,
) -> Result<(), SceneError> {
    use gltf::accessor::{DataType, Dimensions};
    use gltf::mesh::Mode;
    let path = imp.path;
    for prim in mesh.primitives() {
        let mode = prim.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            continue;
        }
        let what = |s: &str| format!("mesh {} primitive {}: {s}", mesh.index(), prim.index());
        let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
            return Err(mesh_err(path, what("no POSITION attribute")));
        };
        if pos_acc.data_type() != DataType::F32 || pos_acc.dimensions() != Dimensions::Vec3 {
            return Err(mesh_err(path, what("POSITION is not a float vec3")));
        }
        if pos_acc.count() == 0 {
            continue;
        }
        let normal_acc = prim.get(&gltf::Semantic::Normals);
        if let Some(n) = &normal_acc
            && (n.data_type() != DataType::F32 || n.dimensions() != Dimensions::Vec3)
        {
            return Err(mesh_err(path, what("NORMAL is not a float vec3")));
        }
        let index_count = match prim.indices() {
            Some(acc) => {
                if !matches!(acc.data_type(), DataType::U8 | DataType::U16 | DataType::U32)
                    || acc.dimensions() != Dimensions::Scalar
                {
                    return Err(mesh_err(path, what("indices are not unsigned integer scalars")));
                }
                acc.count()
            }
            None => pos_acc.count(),
        };
        // Triangle count before reading anything, for the size limit.
        let tris = match mode {
            Mode::Triangles => index_count / 3,
            _ => index_count.saturating_sub(2),
        };
        if imp.seen.saturating_add(tris) > MAX_MESH_TRIANGLES {
            return Err(mesh_err(
                path,
                format!("{} triangles or more, more than the limit of {MAX_MESH_TRIANGLES}", imp.seen + tris),
            ));
        }
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| d.0.as_slice()));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| mesh_err(path, what("POSITION data missing or out of its buffer")))?
            .map(Vec3::from)
            .collect();
        let normals: Option<Vec<Vec3>> = match normal_acc {
            Some(acc) if acc.count() > 0 => Some(
                reader
                    .read_normals()
                    .ok_or_else(|| mesh_err(path, what("NORMAL data missing or out of its buffer")))?
                    .map(Vec3::from)
                    .collect(),
            ),
            _ => None,
        };
        let raw: Vec<u32> = match prim.indices() {
            Some(acc) if acc.count() == 0 => Vec::new(),
            Some(_) => reader
                .read_indices()
                .ok_or_else(|| mesh_err(path, what("index data missing or out of its buffer")))?
                .into_u32()
                .collect(),
            None => (0..positions.len() as u32).collect(),
        };
        let indices: Vec<u32> =
            match mode {
                Mode::Triangles => raw[..raw.len() / 3 * 3].to_vec(),
                Mode::TriangleStrip => (0..raw.len().saturating_sub(2))
                    .flat_map(|i| {
                        if i % 2 == 0 { [raw[i], raw[i + 1], raw[i + 2]] } else { [raw[i + 1], raw[i], raw[i + 2]] }
                    })
                    .collect(),
                _ => (1..raw.len().saturating_sub(1)).flat_map(|i| [raw[0], raw[i], raw[i + 1]]).collect(),
            };
        let a = albedo.unwrap_or_else(|| {
            let material = prim.material();
            if material.index().is_none() {
                return DEFAULT_ALBEDO;
            }
            let c = material.pbr_metallic_roughness().base_color_factor();
            let c = Vec3::new(c[0], c[1], c[2]);
            if c.is_finite() { c.clamp(Vec3::ZERO, Vec3::ONE) } else { DEFAULT_ALBEDO }
        });
        imp.add(&positions, normals.as_deref(), &indices, m, a)?;
    }
    Ok(())
}
