//! Tests of the CPU rasterizer: coverage, the top-left rule, depth, near clipping,
//! barycentrics and shadow maps; and of the rectified shadow map of `prefiltered` (depth
//! clamped instead of clipped), CPU and GPU.

use crepuscular::techniques::prefiltered::raster::{RasterRegion, RectifiedRaster};
use crepuscular::{Camera, Light, ShadowFilter, ShadowProjection};
use crepuscular_scene::builtin::builtin;
use crepuscular_scene::host::hardware_depth_clamp;
use crepuscular_scene::raster::{
    DepthBuffer, motion_vectors, rasterize, rasterize_depth_only, rasterize_rectified, render_shadow_map,
};
use crepuscular_scene::{Geometry, GpuHost, Vertex};
use glam::{DVec3, Mat4, Vec3};

fn vertex(p: Vec3) -> Vertex {
    Vertex { position: p.to_array(), normal: [0.0, 1.0, 0.0], albedo: [0.5; 3] }
}

fn geometry(tris: &[[Vec3; 3]]) -> Geometry {
    let mut g = Geometry::default();
    for t in tris {
        let base = g.vertices.len() as u32;
        g.vertices.extend(t.iter().map(|&p| vertex(p)));
        g.indices.extend([base, base + 1, base + 2]);
    }
    g
}

/// With the identity matrix clip = NDC: the NDC point of screen position (sx, sy).
fn ndc(sx: f32, sy: f32, w: u32, h: u32, z: f32) -> Vec3 {
    Vec3::new(2.0 * sx / w as f32 - 1.0, 1.0 - 2.0 * sy / h as f32, z)
}

fn screen_tri(s: [(f32, f32); 3], w: u32, h: u32, z: f32) -> [Vec3; 3] {
    s.map(|(x, y)| ndc(x, y, w, h, z))
}

fn covered_count(buf: &DepthBuffer) -> usize {
    buf.triangle.iter().filter(|&&t| t != u32::MAX).count()
}

/// Deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

#[test]
fn right_triangle_covers_exactly_the_expected_pixels() {
    let (w, h) = (64, 64);
    for winding in [[0, 1, 2], [0, 2, 1]] {
        let s = [(0.0, 0.0), (64.0, 0.0), (0.0, 64.0)];
        let tri = screen_tri(winding.map(|i| s[i]), w, h, 0.5);
        let buf = rasterize(&geometry(&[tri]), Mat4::IDENTITY, w, h);
        // Centres with x + y + 1 < 64 are inside; those on the hypotenuse (a right edge)
        // are not: x + y ≤ 62.
        for y in 0..h {
            for x in 0..w {
                assert_eq!(buf.covered(x, y), x + y <= 62, "pixel {x},{y} winding {winding:?}");
            }
        }
        assert_eq!(covered_count(&buf), 63 * 64 / 2);
        assert!(buf.depth.iter().all(|&d| d == 0.5 || d == 1.0));
    }
}

#[test]
fn pixel_aligned_square_follows_top_left_rule() {
    // A square with corners on pixel centres: the top and left edges are in, the bottom
    // and right edges out, so exactly 4×4 pixels starting at (2, 3).
    let (w, h) = (16, 16);
    let (x0, y0, x1, y1) = (2.5, 3.5, 6.5, 7.5);
    for flip in [false, true] {
        let mut a = screen_tri([(x0, y0), (x1, y0), (x1, y1)], w, h, 0.25);
        let mut b = screen_tri([(x0, y0), (x1, y1), (x0, y1)], w, h, 0.25);
        if flip {
            a.swap(1, 2);
            b.swap(0, 1);
        }
        let buf = rasterize(&geometry(&[a, b]), Mat4::IDENTITY, w, h);
        for y in 0..h {
            for x in 0..w {
                let inside = (2..6).contains(&x) && (3..7).contains(&y);
                assert_eq!(buf.covered(x, y), inside, "pixel {x},{y}");
            }
        }
    }
}

#[test]
fn general_triangle_matches_point_in_triangle_away_from_edges() {
    let (w, h) = (320, 180);
    let s = [(13.3, 20.7), (301.9, 61.2), (97.1, 171.4)];
    let buf = rasterize(&geometry(&[screen_tri(s, w, h, 0.3)]), Mat4::IDENTITY, w, h);
    let area = 0.5 * ((s[1].0 - s[0].0) * (s[2].1 - s[0].1) - (s[1].1 - s[0].1) * (s[2].0 - s[0].0)).abs();
    let perimeter: f32 = (0..3)
        .map(|i| {
            let (a, b) = (s[i], s[(i + 1) % 3]);
            ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt()
        })
        .sum();
    let n = covered_count(&buf) as f32;
    assert!((n - area).abs() < perimeter, "covered {n}, area {area}");
    // Signed distances (pixels) to the three edges.
    let dist = |px: f32, py: f32| -> f32 {
        (0..3)
            .map(|i| {
                let (a, b) = (s[i], s[(i + 1) % 3]);
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                (dx * (py - a.1) - dy * (px - a.0)) / (dx * dx + dy * dy).sqrt()
            })
            .fold(f32::MAX, f32::min)
    };
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let d = dist(x as f32 + 0.5, y as f32 + 0.5);
            if d.abs() > 0.01 {
                assert_eq!(buf.covered(x, y), d > 0.0, "pixel {x},{y}");
                checked += 1;
            }
        }
    }
    assert!(checked > w * h * 9 / 10);
}

/// A jittered grid mesh larger than the screen, with vertices on pixel centres and
/// pixel corners, exactly horizontal and vertical edges, and random windings.
fn jittered_mesh(w: u32, h: u32, seed: u64) -> Vec<[Vec3; 3]> {
    let mut rng = Lcg(seed);
    let (nx, ny) = (11, 7);
    let mut pts = vec![(0.0f32, 0.0f32); (nx + 1) * (ny + 1)];
    for j in 0..=ny {
        for i in 0..=nx {
            let mut x = -20.0 + i as f32 * (w as f32 + 40.0) / nx as f32;
            let mut y = -20.0 + j as f32 * (h as f32 + 40.0) / ny as f32;
            if i > 0 && i < nx && j > 0 && j < ny {
                match (i + j) % 4 {
                    0 => {
                        x = (x + 9.0 * (rng.next() - 0.5)).floor() + 0.5;
                        y = (y + 9.0 * (rng.next() - 0.5)).floor() + 0.5;
                    }
                    1 => {
                        x = (x + 9.0 * (rng.next() - 0.5)).floor();
                        y = (y + 9.0 * (rng.next() - 0.5)).floor();
                    }
                    2 => {} // regular: horizontal / vertical neighbours
                    _ => {
                        x += 9.0 * (rng.next() - 0.5);
                        y += 9.0 * (rng.next() - 0.5);
                    }
                }
            }
            pts[j * (nx + 1) + i] = (x, y);
        }
    }
    let mut tris = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let p = |a: usize, b: usize| pts[(j + b) * (nx + 1) + i + a];
            let (p00, p10, p01, p11) = (p(0, 0), p(1, 0), p(0, 1), p(1, 1));
            let pair =
                if (i + j) % 2 == 0 { [[p00, p10, p11], [p00, p11, p01]] } else { [[p00, p10, p01], [p10, p11, p01]] };
            for mut t in pair {
                if rng.next() < 0.5 {
                    t.swap(1, 2);
                }
                tris.push(screen_tri(t, w, h, 0.5));
            }
        }
    }
    tris
}

#[test]
fn shared_edges_are_drawn_exactly_once() {
    let (w, h) = (320, 180);
    // A quad split in two along its diagonal.
    let quad = [
        screen_tri([(40.3, 20.1), (250.7, 35.5), (270.2, 160.9)], w, h, 0.5),
        screen_tri([(40.3, 20.1), (270.2, 160.9), (30.6, 150.25)], w, h, 0.5),
    ];
    let mut count = vec![0u32; (w * h) as usize];
    for t in &quad {
        let buf = rasterize(&geometry(&[*t]), Mat4::IDENTITY, w, h);
        for (c, &id) in count.iter_mut().zip(&buf.triangle) {
            *c += (id != u32::MAX) as u32;
        }
    }
    assert!(count.iter().all(|&c| c <= 1), "a pixel was drawn twice");
    let both = rasterize(&geometry(&quad), Mat4::IDENTITY, w, h);
    assert_eq!(count.iter().sum::<u32>() as usize, covered_count(&both));
    // No holes: every pixel inside the quad's outline (rows between its left and right
    // edges, well inside) is covered.
    for y in 40..140 {
        for x in 60..230 {
            assert_eq!(count[(y * w + x) as usize], 1, "hole at {x},{y}");
        }
    }

    // A whole-screen mesh with many shared edges of every orientation.
    for seed in [1, 2, 3] {
        let mesh = jittered_mesh(w, h, seed);
        let mut count = vec![0u32; (w * h) as usize];
        for t in &mesh {
            let buf = rasterize(&geometry(&[*t]), Mat4::IDENTITY, w, h);
            for (c, &id) in count.iter_mut().zip(&buf.triangle) {
                *c += (id != u32::MAX) as u32;
            }
        }
        let doubles = count.iter().filter(|&&c| c > 1).count();
        let holes = count.iter().filter(|&&c| c == 0).count();
        assert_eq!((doubles, holes), (0, 0), "seed {seed}");
        // Drawn together, every pixel belongs to exactly one triangle.
        let buf = rasterize(&geometry(&mesh), Mat4::IDENTITY, w, h);
        assert_eq!(covered_count(&buf), (w * h) as usize);
    }
}

fn camera_basis(cam: &Camera) -> (DVec3, DVec3, DVec3) {
    let f = cam.forward().as_dvec3();
    let r = f.cross(cam.up.as_dvec3()).normalize();
    let u = r.cross(f);
    (f, r, u)
}

/// Direction (unnormalised, unit length along the view axis) of the ray through the centre
/// of pixel (x, y).
fn pixel_ray(cam: &Camera, w: u32, h: u32, x: u32, y: u32) -> DVec3 {
    let (f, r, u) = camera_basis(cam);
    let ty = ((cam.fov_y_degrees as f64).to_radians() * 0.5).tan();
    let tx = ty * w as f64 / h as f64;
    let nx = (x as f64 + 0.5) / w as f64 * 2.0 - 1.0;
    let ny = 1.0 - (y as f64 + 0.5) / h as f64 * 2.0;
    f + r * (nx * tx) + u * (ny * ty)
}

/// [0, 1] depth of a point at view distance `d` (`Mat4::perspective_rh`).
fn ndc_depth(d: f64, near: f64, far: f64) -> f64 {
    far * (d - near) / (d * (far - near))
}

#[test]
fn depth_of_a_plane_matches_the_analytic_depth() {
    let (w, h) = (320, 180);
    let cam = Camera {
        position: Vec3::new(0.0, 0.0, 0.0),
        look_at: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        fov_y_degrees: 60.0,
        near: 0.1,
        far: 100.0,
    };
    let vp = cam.view_projection(w as f32 / h as f32);
    // A fronto-parallel plane at view distance 7.
    let d = 7.0;
    let big = 100.0;
    let plane = [
        [Vec3::new(-big, -big, -d), Vec3::new(big, -big, -d), Vec3::new(big, big, -d)],
        [Vec3::new(-big, -big, -d), Vec3::new(big, big, -d), Vec3::new(-big, big, -d)],
    ];
    let buf = rasterize(&geometry(&plane), vp, w, h);
    let expect = ndc_depth(d as f64, 0.1, 100.0);
    assert_eq!(covered_count(&buf), (w * h) as usize);
    for &z in &buf.depth {
        assert!((z as f64 - expect).abs() < 2e-6, "{z} vs {expect}");
    }
    let lin = crepuscular::model::linear_depth(buf.depth[0], cam.near, cam.far);
    assert!((lin - d).abs() < 1e-3 * d, "linear depth {lin}");

    // A tilted plane: depth at every pixel centre from the ray-plane intersection, and the
    // barycentrics reproduce the intersection point (perspective-correct interpolation).
    let n = DVec3::new(0.3, 0.5, 1.0).normalize();
    let p0 = DVec3::new(0.0, 0.0, -6.0);
    let (a, b) = (n.cross(DVec3::X).normalize(), n.cross(DVec3::X).normalize().cross(n));
    let s = 40.0;
    let corner = |i: f64, j: f64| (p0 + a * (i * s) + b * (j * s)).as_vec3();
    let tilted = [
        [corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0)],
        [corner(-1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)],
    ];
    let g = geometry(&tilted);
    let buf = rasterize(&g, vp, w, h);
    let depth_only = rasterize_depth_only(&g, vp, w, h);
    assert_eq!(buf.depth, depth_only);
    let (fwd, _, _) = camera_basis(&cam);
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let ray = pixel_ray(&cam, w, h, x, y);
            let t = n.dot(p0) / n.dot(ray);
            let hit = ray * t;
            let view_dist = hit.dot(fwd);
            if !(t > 0.0 && view_dist > 0.1 && view_dist < 100.0) {
                assert!(!buf.covered(x, y));
                continue;
            }
            let i = buf.index(x, y);
            assert_ne!(buf.triangle[i], u32::MAX, "pixel {x},{y}");
            let expect = ndc_depth(view_dist, 0.1, 100.0);
            assert!((buf.depth[i] as f64 - expect).abs() < 1e-5, "pixel {x},{y}: {} vs {expect}", buf.depth[i]);
            let bc = buf.bary[i];
            assert!((bc.iter().sum::<f32>() - 1.0).abs() < 1e-5, "bary {bc:?}");
            assert!(bc.iter().all(|&b| b > -1e-4 && b < 1.0 + 1e-4), "bary {bc:?}");
            let tri = buf.triangle[i] as usize;
            let p: DVec3 = (0..3)
                .map(|k| Vec3::from(g.vertices[g.indices[3 * tri + k] as usize].position).as_dvec3() * bc[k] as f64)
                .sum();
            assert!((p - hit).length() < 1e-3 * (1.0 + t), "pixel {x},{y}: {p} vs {hit}");
            checked += 1;
        }
    }
    assert!(checked > 1000);
}

#[test]
fn ground_plane_behind_the_camera_is_clipped_without_artifacts() {
    let (w, h) = (320, 180);
    let cam = Camera {
        position: Vec3::new(0.0, 1.7, 0.0),
        look_at: Vec3::new(0.3, 1.2, -10.0),
        up: Vec3::Y,
        fov_y_degrees: 70.0,
        near: 0.1,
        far: 1000.0,
    };
    let vp = cam.view_projection(w as f32 / h as f32);
    let e = 500.0;
    // Corners behind the camera: every triangle crosses the near plane.
    let ground = [
        [Vec3::new(-e, 0.0, -e), Vec3::new(e, 0.0, e), Vec3::new(e, 0.0, -e)],
        [Vec3::new(-e, 0.0, -e), Vec3::new(-e, 0.0, e), Vec3::new(e, 0.0, e)],
    ];
    let g = geometry(&ground);
    // Attribute: albedo = (x, z, 1) per vertex, interpolated with the barycentrics.
    let mut g2 = g.clone();
    for v in &mut g2.vertices {
        v.albedo = [v.position[0], v.position[2], 1.0];
    }
    let buf = rasterize(&g2, vp, w, h);
    assert_eq!(buf.depth, rasterize_depth_only(&g, vp, w, h));
    let (fwd, _, _) = camera_basis(&cam);
    let eye = cam.position.as_dvec3();
    let mut below = 0;
    for y in 0..h {
        for x in 0..w {
            let ray = pixel_ray(&cam, w, h, x, y);
            let i = buf.index(x, y);
            if ray.y >= 0.0 {
                assert!(!buf.covered(x, y), "sky pixel {x},{y} covered");
                continue;
            }
            let t = -eye.y / ray.y;
            let hit = eye + ray * t;
            let extent = hit.x.abs().max(hit.z.abs());
            if extent > 510.0 {
                assert!(!buf.covered(x, y), "pixel {x},{y} beyond the plane covered");
            } else if extent < 490.0 {
                below += 1;
                assert!(buf.covered(x, y), "hole below the horizon at {x},{y}");
                let expect = ndc_depth((hit - eye).dot(fwd), 0.1, 1000.0);
                assert!((buf.depth[i] as f64 - expect).abs() < 1e-5, "pixel {x},{y}");
                let tri = buf.triangle[i] as usize;
                let bc = buf.bary[i];
                assert!((bc.iter().sum::<f32>() - 1.0).abs() < 1e-5, "bary {bc:?}");
                let attr: [f64; 3] = std::array::from_fn(|c| {
                    (0..3).map(|k| g2.vertices[g2.indices[3 * tri + k] as usize].albedo[c] as f64 * bc[k] as f64).sum()
                });
                let tol = 1e-3 * (1.0 + t * t);
                assert!(
                    (attr[0] - hit.x).abs() < tol && (attr[1] - hit.z).abs() < tol,
                    "pixel {x},{y}: {attr:?} vs {hit}"
                );
                assert!((attr[2] - 1.0).abs() < 1e-5);
            }
        }
    }
    assert!(below > (w * h / 3) as usize, "{below}");
}

#[test]
fn far_plane_clips() {
    let (w, h) = (64, 64);
    // z ∈ [0, w]: a triangle beyond the far plane is not drawn, one crossing it is cut.
    let beyond = [Vec3::new(-1.0, -1.0, 1.5), Vec3::new(1.0, -1.0, 1.5), Vec3::new(0.0, 1.0, 1.5)];
    assert_eq!(covered_count(&rasterize(&geometry(&[beyond]), Mat4::IDENTITY, w, h)), 0);
    // Depth 0.5 on the left edge, 1.5 on the right: the left half is drawn.
    let crossing = [
        [Vec3::new(-1.0, -1.0, 0.5), Vec3::new(1.0, -1.0, 1.5), Vec3::new(1.0, 1.0, 1.5)],
        [Vec3::new(-1.0, -1.0, 0.5), Vec3::new(1.0, 1.0, 1.5), Vec3::new(-1.0, 1.0, 0.5)],
    ];
    let buf = rasterize(&geometry(&crossing), Mat4::IDENTITY, w, h);
    for y in 0..h {
        for x in 0..w {
            assert_eq!(buf.covered(x, y), x < 32, "pixel {x},{y}");
        }
    }
    assert!(buf.depth.iter().all(|&d| (0.0..=1.0).contains(&d)));
}

#[test]
fn depth_test_is_less_in_primitive_order() {
    let (w, h) = (32, 32);
    let full = |z: f32| {
        [
            [Vec3::new(-1.0, -1.0, z), Vec3::new(3.0, -1.0, z), Vec3::new(-1.0, 3.0, z)],
            [Vec3::new(1.0, 1.0, z), Vec3::new(-3.0, 1.0, z), Vec3::new(1.0, -3.0, z)],
        ]
    };
    let mut tris = Vec::new();
    tris.extend(full(0.6));
    tris.extend(full(0.3));
    tris.extend(full(0.3)); // equal depth: LESS keeps the first
    tris.extend(full(0.8));
    let buf = rasterize(&geometry(&tris), Mat4::IDENTITY, w, h);
    assert!(buf.depth.iter().all(|&d| d == 0.3));
    assert!(buf.triangle.iter().all(|&t| t == 2 || t == 3));
}

#[test]
fn degenerate_and_invalid_triangles_are_skipped() {
    let (w, h) = (64, 64);
    let mut g = geometry(&[
        [Vec3::ZERO, Vec3::new(0.5, 0.5, 0.5), Vec3::new(1.0, 1.0, 0.5)], // collinear
        [Vec3::new(0.1, 0.1, 0.5); 3],                                    // a point
        [Vec3::new(f32::NAN, 0.0, 0.5), Vec3::new(1.0, 0.0, 0.5), Vec3::new(0.0, 1.0, 0.5)],
        [Vec3::new(f32::INFINITY, 0.0, 0.5), Vec3::new(1.0, 0.0, 0.5), Vec3::new(0.0, 1.0, 0.5)],
        [Vec3::new(-1.0, 0.0, -0.5), Vec3::new(1.0, 0.0, -0.5), Vec3::new(0.0, 1.0, -0.5)], // behind
    ]);
    g.indices.extend([0, 1, 99]); // out of range
    g.indices.extend([0, 1]); // incomplete
    let buf = rasterize(&g, Mat4::IDENTITY, w, h);
    assert_eq!(covered_count(&buf), 0);
    assert!(buf.depth.iter().all(|&d| d == 1.0));
    assert!(rasterize_depth_only(&g, Mat4::IDENTITY, w, h).iter().all(|&d| d == 1.0));
    // A NaN matrix, an empty image.
    let nan = Mat4::from_cols_array(&[f32::NAN; 16]);
    assert_eq!(covered_count(&rasterize(&g, nan, w, h)), 0);
    assert!(rasterize(&g, Mat4::IDENTITY, 0, 10).depth.is_empty());
}

fn room(min: Vec3, max: Vec3) -> Geometry {
    let c = |i: usize| {
        Vec3::new(
            if i & 1 == 0 { min.x } else { max.x },
            if i & 2 == 0 { min.y } else { max.y },
            if i & 4 == 0 { min.z } else { max.z },
        )
    };
    let faces = [[0, 2, 6, 4], [1, 3, 7, 5], [0, 1, 5, 4], [2, 3, 7, 6], [0, 1, 3, 2], [4, 5, 7, 6]];
    let mut tris = Vec::new();
    for f in faces {
        tris.push([c(f[0]), c(f[1]), c(f[2])]);
        tris.push([c(f[0]), c(f[2]), c(f[3])]);
    }
    geometry(&tris)
}

#[test]
fn point_light_shadow_map_has_six_layers() {
    // Light at the origin; walls at x = +2, x = −3, and ±3 on y and z.
    let g = room(Vec3::new(-3.0, -3.0, -3.0), Vec3::new(2.0, 3.0, 3.0));
    let light = Light::Point { position: Vec3::ZERO, color: Vec3::ONE, intensity: 1.0 };
    let size = 64;
    let proj = ShadowProjection::fit(&light, &Camera::default(), 1.0, g.bounds(), size);
    assert_eq!(proj.layers, 6);
    let map = render_shadow_map(&g, &proj);
    let n = (size * size) as usize;
    assert_eq!(map.depth.len(), 6 * n);
    assert!(map.depth.iter().all(|&d| d < 1.0), "the room surrounds the light");
    for layer in 0..6u32 {
        for y in 0..size {
            for x in 0..size {
                let lin = proj.linear(map.texel(layer, x, y));
                let ok = match layer {
                    0 => (lin - 2.0).abs() < 2e-3,
                    1 => (lin - 3.0).abs() < 3e-3,
                    _ => lin > 2.0 - 2e-3 && lin < 3.0 + 3e-3,
                };
                assert!(ok, "layer {layer} texel {x},{y}: {lin}");
            }
        }
    }
    // Lookups through the map agree: a point just in front of a wall is lit, one behind a
    // wall (outside the room) in shadow.
    assert_eq!(map.visibility(Vec3::ZERO, Vec3::new(1.9, 0.2, 0.1), 0.02, ShadowFilter::Nearest), 1.0);
    assert_eq!(map.visibility(Vec3::ZERO, Vec3::new(2.5, 0.2, 0.1), 0.02, ShadowFilter::Nearest), 0.0);
    assert_eq!(map.visibility(Vec3::ZERO, Vec3::new(0.1, -0.3, -3.5), 0.02, ShadowFilter::Nearest), 0.0);

    // A spot light has one layer.
    let spot = Light::Spot {
        position: Vec3::ZERO,
        direction: Vec3::NEG_Z,
        outer_angle_degrees: 30.0,
        inner_angle_degrees: 20.0,
        color: Vec3::ONE,
        intensity: 1.0,
        texture: None,
    };
    let proj = ShadowProjection::fit(&spot, &Camera::default(), 1.0, g.bounds(), size);
    let map = render_shadow_map(&g, &proj);
    assert_eq!(map.depth.len(), n);
    assert!(map.depth.iter().all(|&d| (proj.linear(d) - 3.0).abs() < 3e-3));
}

/// About 50k triangles: a wavy terrain of 200×120 quads plus scattered small boxes.
fn big_scene() -> Geometry {
    let mut tris = Vec::new();
    let (nx, nz) = (200, 120);
    let height = |x: f32, z: f32| 0.3 * (0.7 * x).sin() * (0.5 * z).cos();
    for j in 0..nz {
        for i in 0..nx {
            let p = |a: usize, b: usize| {
                let x = -50.0 + (i + a) as f32 * 100.0 / nx as f32;
                let z = -60.0 + (j + b) as f32 * 60.0 / nz as f32;
                Vec3::new(x, height(x, z), z)
            };
            tris.push([p(0, 0), p(1, 0), p(1, 1)]);
            tris.push([p(0, 0), p(1, 1), p(0, 1)]);
        }
    }
    let mut rng = Lcg(7);
    let mut g = geometry(&tris);
    while g.triangle_count() < 50_000 {
        let c = Vec3::new(rng.next() * 60.0 - 30.0, rng.next() * 4.0, -rng.next() * 50.0);
        let s = 0.2 + rng.next();
        g.append(&room(c - Vec3::splat(s), c + Vec3::splat(s)));
    }
    g
}

#[test]
fn timing_50k_triangles() {
    let g = big_scene();
    let cam = Camera {
        position: Vec3::new(0.0, 3.0, 8.0),
        look_at: Vec3::new(0.0, 0.0, -20.0),
        up: Vec3::Y,
        fov_y_degrees: 60.0,
        near: 0.1,
        far: 200.0,
    };
    let vp = cam.view_projection(1920.0 / 1080.0);
    let _ = rasterize(&g, vp, 1920, 1080); // warm up the thread pool
    let t = std::time::Instant::now();
    let buf = rasterize(&g, vp, 1920, 1080);
    let full = t.elapsed();
    let t = std::time::Instant::now();
    let depth = rasterize_depth_only(&g, vp, 1920, 1080);
    let depth_only = t.elapsed();
    assert_eq!(buf.depth, depth);
    let light = Light::Point { position: Vec3::new(0.0, 6.0, -20.0), color: Vec3::ONE, intensity: 1.0 };
    let proj = ShadowProjection::fit(&light, &cam, 16.0 / 9.0, g.bounds(), 4096);
    let mut one = proj.clone();
    one.layers = 1;
    let t = std::time::Instant::now();
    let map = render_shadow_map(&g, &one);
    let shadow = t.elapsed();
    assert_eq!(map.depth.len(), 4096 * 4096);
    println!(
        "{} triangles: rasterize 1920×1080 {full:?}, depth only {depth_only:?}, one 4096² shadow layer {shadow:?}; covered {}",
        g.triangle_count(),
        covered_count(&buf)
    );
}

// ---------------------------------------------------------------------------------------------
// The rectified shadow map of `prefiltered`: regions as viewports, depth clamped, not clipped.

/// Texels (in a request's row-major layout) of region `r`.
fn region_texels(req: &RectifiedRaster, r: usize) -> impl Iterator<Item = (u32, u32)> + '_ {
    let [c0, c1] = req.regions[r].columns;
    (0..req.height).flat_map(move |y| (c0..c1).map(move |x| (x, y)))
}

/// A camera's world → clip matrix (`Mat4::perspective_rh`, vertical field of view in degrees).
fn perspective(eye: Vec3, target: Vec3, fov_y: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    Mat4::perspective_rh(fov_y.to_radians(), aspect, near, far) * Mat4::look_at_rh(eye, target, Vec3::Y)
}

/// Two regions of a 96×64 map over the colonnade: the scene camera with a near plane far in
/// front of it (much of the scene has z/w < 0) and a close far plane, and a view from above.
fn colonnade_request() -> (Geometry, RectifiedRaster) {
    let scene = builtin("colonnade").unwrap();
    let cam = &scene.camera;
    let (w, h, split) = (96, 64, 40);
    let a = perspective(cam.position, cam.look_at, 60.0, split as f32 / h as f32, 6.0, 25.0);
    let b = perspective(Vec3::new(2.0, 24.0, 22.0), Vec3::ZERO, 50.0, (w - split) as f32 / h as f32, 8.0, 60.0);
    let request = RectifiedRaster {
        width: w,
        height: h,
        regions: vec![
            RasterRegion { view_proj: a, columns: [0, split] },
            RasterRegion { view_proj: b, columns: [split, w] },
        ],
    };
    (scene.geometry, request)
}

/// Fraction of texels where `a` and `b` differ by at most `tol`, and the largest difference.
fn agreement(a: &[f32], b: &[f32], tol: f32) -> (f64, f32) {
    assert_eq!(a.len(), b.len());
    let ok = a.iter().zip(b).filter(|(x, y)| (*x - *y).abs() <= tol).count();
    let max = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max);
    (ok as f64 / a.len() as f64, max)
}

#[test]
fn rectified_regions_are_viewports_with_clamped_depth() {
    let (g, req) = colonnade_request();
    let map = rasterize_rectified(&g, &req);
    assert_eq!(map.len(), (req.width * req.height) as usize);
    assert!(map.iter().all(|d| (0.0..=1.0).contains(d)));
    let idx = |x: u32, y: u32| (y * req.width + x) as usize;
    for (r, region) in req.regions.iter().enumerate() {
        let [c0, c1] = region.columns;
        let rw = c1 - c0;
        // Each region is its own viewport: where the clipped raster of that viewport has a
        // depth strictly inside (0, 1), the clamped one has the same depth (the nearest
        // surface there is not clipped); where it is 0 or uncovered the clamped one may be
        // 0 instead (something in front of the near plane).
        let clipped = rasterize_depth_only(&g, region.view_proj, rw, req.height);
        let (mut same, mut inside, mut clamped_near) = (0, 0, 0);
        let mut worst = 0.0f32;
        for (x, y) in region_texels(&req, r) {
            let c = clipped[(y * rw + x - c0) as usize];
            let d = map[idx(x, y)];
            if c > 0.0 && c < 1.0 {
                inside += 1;
                // Up to rounding: the clipped raster's depth plane moves with the snapping of
                // the vertices it cuts at the near plane (~1e-4 here, with near = 6).
                same += ((c - d).abs() <= 5e-4 || d == 0.0) as usize;
                if d != 0.0 {
                    worst = worst.max((c - d).abs());
                }
            }
            clamped_near += (d == 0.0 && c != 0.0) as usize;
        }
        println!(
            "region {r}: {inside} texels inside (0, 1), {clamped_near} clamped to 0 that clipping loses, largest difference {worst}"
        );
        assert!(inside > 500, "region {r}: {inside}");
        assert!(same as f64 >= 0.99 * inside as f64, "region {r}: {same} of {inside}");
        if r == 0 {
            assert!(clamped_near > 100, "region 0 has geometry in front of its near plane: {clamped_near}");
        }
    }
    // An empty region or an empty request draws nothing.
    let one = RectifiedRaster {
        regions: vec![RasterRegion { view_proj: req.regions[0].view_proj, columns: [0, req.width] }],
        ..req.clone()
    };
    let with_empty = RectifiedRaster {
        regions: vec![one.regions[0], RasterRegion { view_proj: req.regions[1].view_proj, columns: [7, 7] }],
        ..req.clone()
    };
    assert_eq!(rasterize_rectified(&g, &one), rasterize_rectified(&g, &with_empty));
    let none = RectifiedRaster { regions: vec![], ..req.clone() };
    assert!(rasterize_rectified(&g, &none).iter().all(|&d| d == 1.0));
}

#[test]
fn rectified_gpu_matches_cpu_on_the_colonnade() {
    let Some(gpu) = crepuscular::gpu::test_gpu("rectified_gpu_matches_cpu_on_the_colonnade") else { return };
    let (g, req) = colonnade_request();
    let host = GpuHost::new(&gpu, &g).unwrap();
    let cpu = rasterize_rectified(&g, &req);
    let tex = host.render_rectified(&gpu, &req).unwrap();
    assert_eq!((tex.width(), tex.height(), tex.format()), (req.width, req.height, wgpu::TextureFormat::Depth32Float));
    assert!(tex.usage().contains(
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::RENDER_ATTACHMENT
    ));
    let gpu_map = gpu.read_texture_f32(&tex, 0).unwrap();
    let (frac, max) = agreement(&gpu_map, &cpu, 1e-4);
    let path = if hardware_depth_clamp(&gpu) { "unclipped_depth" } else { "shader clamp" };
    println!("GPU ({path}) vs CPU: {:.3}% of texels within 1e-4, largest difference {max}", 100.0 * frac);
    assert!(frac >= 0.99, "{frac}");
    // Both regions drew something, and region 0 has texels clamped to 0.
    for r in 0..2 {
        assert!(region_texels(&req, r).any(|(x, y)| gpu_map[(y * req.width + x) as usize] < 1.0), "region {r}");
    }
    assert!(region_texels(&req, 0).filter(|&(x, y)| gpu_map[(y * req.width + x) as usize] == 0.0).count() > 100);
    // Region columns outside the map are refused.
    let bad = RectifiedRaster {
        regions: vec![RasterRegion { view_proj: Mat4::IDENTITY, columns: [10, req.width + 1] }],
        ..req.clone()
    };
    assert!(matches!(host.render_rectified(&gpu, &bad), Err(crepuscular::Error::Invalid { .. })));
}

/// Two regions of a 64×32 map: region 0 with the identity matrix (clip = NDC) over a quad at
/// z = −0.5, one at z = 1.5 and a strip whose depth runs from −0.5 to 1.5 across the region;
/// region 1 a perspective camera at (10, 0, 5) looking down −z (near 1, far 10) over a quad
/// between the eye and the near plane, one beyond the far plane and a ground plane at y = −0.5
/// that runs from behind the eye past the far plane. Each region's objects lie outside the
/// other's view. Returns the geometry, the request and the expected depth per texel (`None`
/// within a texel of an edge).
fn near_far_request() -> (Geometry, RectifiedRaster, Vec<Option<f32>>) {
    let quad = |x0: f32, x1: f32, y0: f32, y1: f32, z0: f32, z1: f32| {
        // Depth z0 on the left edge, z1 on the right.
        let p = |x: f32, y: f32| Vec3::new(x, y, z0 + (z1 - z0) * (x - x0) / (x1 - x0));
        [[p(x0, y0), p(x1, y0), p(x1, y1)], [p(x0, y0), p(x1, y1), p(x0, y1)]]
    };
    let zquad = |x0: f32, x1: f32, y0: f32, y1: f32, z: f32| {
        let p = |x: f32, y: f32| Vec3::new(x, y, z);
        [[p(x0, y0), p(x1, y0), p(x1, y1)], [p(x0, y0), p(x1, y1), p(x0, y1)]]
    };
    let mut tris = Vec::new();
    tris.extend(quad(-0.75, -0.25, 0.25, 0.75, -0.5, -0.5)); // in front of the near plane
    tris.extend(quad(0.25, 0.75, 0.25, 0.75, 1.5, 1.5)); // beyond the far plane
    tris.extend(quad(-1.5, 1.5, -0.75, -0.25, -1.0, 2.0)); // z = 0.5 + x
    let (ex, ez) = (10.0, 5.0);
    tris.extend(zquad(ex - 0.3, ex - 0.1, -0.1, 0.1, ez - 0.5)); // view distance 0.5 < near
    tris.extend(zquad(ex + 2.0, ex + 6.0, -2.0, 2.0, ez - 20.0)); // view distance 20 > far
    let ground = |x: f32, z: f32| Vec3::new(x, -0.5, z);
    tris.push([ground(ex - 100.0, ez + 0.5), ground(ex + 100.0, ez + 0.5), ground(ex + 100.0, ez - 30.0)]);
    tris.push([ground(ex - 100.0, ez + 0.5), ground(ex + 100.0, ez - 30.0), ground(ex - 100.0, ez - 30.0)]);
    let (w, h) = (64u32, 32u32);
    let view = perspective(Vec3::new(ex, 0.0, ez), Vec3::new(ex, 0.0, 0.0), 90.0, 1.0, 1.0, 10.0);
    let req = RectifiedRaster {
        width: w,
        height: h,
        regions: vec![
            RasterRegion { view_proj: Mat4::IDENTITY, columns: [0, 32] },
            RasterRegion { view_proj: view, columns: [32, 64] },
        ],
    };
    let margin = 0.6 / 16.0; // NDC: 0.6 texel of a 32-texel region
    let inside = |v: f32, lo: f32, hi: f32| v > lo + margin && v < hi - margin;
    let near_edge = |v: f32, e: f32| (v - e).abs() <= margin;
    let mut expect = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let nx = ((x % 32) as f32 + 0.5) / 16.0 - 1.0;
            let ny = 1.0 - (y as f32 + 0.5) / 16.0;
            let e = if x < 32 {
                if inside(nx, -0.75, -0.25) && inside(ny, 0.25, 0.75) {
                    Some(0.0)
                } else if inside(ny, -0.75, -0.25) {
                    Some((0.5 + nx).clamp(0.0, 1.0))
                } else if [-0.75, -0.25, 0.25, 0.75].iter().any(|&e| near_edge(nx, e) || near_edge(ny, e)) {
                    None
                } else {
                    Some(1.0) // nothing, or the quad beyond the far plane
                }
            } else if inside(nx, -0.6, -0.2) && inside(ny, -0.2, 0.2) {
                Some(0.0)
            } else if [-0.6, -0.2].iter().any(|&e| near_edge(nx, e)) && ny.abs() < 0.2 + margin
                || near_edge(ny, 0.2) && nx > -0.6 - margin && nx < -0.2 + margin
            {
                None
            } else if ny < 0.0 {
                // The ground, at view distance d: perspective_rh's depth, clamped.
                let d = 0.5 / -ny as f64;
                Some((10.0 * (d - 1.0) / (9.0 * d)).clamp(0.0, 1.0) as f32)
            } else {
                Some(1.0)
            };
            expect.push(e);
        }
    }
    (geometry(&tris), req, expect)
}

/// Checks a rectified map of [`near_far_request`] against its expected depths: exactly 0
/// where clamped to 0, within `tol` elsewhere in region 0 (clip w = 1, so the depth is exact
/// up to rounding), within `tol_ground` elsewhere in region 1: there the ground crosses the eye
/// plane, so its clipped vertices at the guard band have |z/w| ~ 10³, and their sub-pixel
/// snapping moves the interpolated depth by ~10⁻⁴ (as on the GPU: depth clamping keeps
/// these vertices where near clipping would have cut them away).
fn check_near_far(what: &str, map: &[f32], expect: &[Option<f32>], tol: f32, tol_ground: f32) {
    let (mut checked, mut zeros, mut ramp) = (0, 0, 0);
    let mut worst = [0.0f32; 2];
    for (i, (&d, e)) in map.iter().zip(expect).enumerate() {
        let Some(e) = *e else { continue };
        let region = (i % 64 >= 32) as usize;
        let tol = if e == 0.0 {
            0.0
        } else if region == 0 {
            tol
        } else {
            tol_ground
        };
        assert!((d - e).abs() <= tol, "{what}: texel {},{}: {d} vs {e}", i % 64, i / 64);
        worst[region] = worst[region].max((d - e).abs());
        checked += 1;
        zeros += (e == 0.0) as usize;
        ramp += (e > 0.0 && e < 1.0) as usize;
    }
    println!("{what}: {checked} texels checked, {zeros} clamped to 0, {ramp} inside (0, 1); largest error {worst:?}");
    assert!(checked > 1500 && zeros > 200 && ramp > 300, "{what}: {checked} {zeros} {ramp}");
}

#[test]
fn rectified_depth_is_clamped_not_clipped_on_the_cpu() {
    let (g, req, expect) = near_far_request();
    let map = rasterize_rectified(&g, &req);
    check_near_far("CPU", &map, &expect, 1e-6, 1e-3);
    // The ordinary (clipping) raster of each region drops what is in front of the near plane:
    // it has no zeros where the clamped one has them.
    for (r, region) in req.regions.iter().enumerate() {
        let clipped = rasterize_depth_only(&g, region.view_proj, 32, 32);
        let mut dropped = 0;
        for (x, y) in region_texels(&req, r) {
            if expect[(y * req.width + x) as usize] == Some(0.0) {
                assert!(clipped[(y * 32 + x - 32 * r as u32) as usize] > 0.0, "region {r} texel {x},{y}");
                dropped += 1;
            }
        }
        assert!(dropped > 50, "region {r}: {dropped}");
    }
}

#[test]
fn rectified_depth_is_clamped_not_clipped_on_the_gpu() {
    let Some(gpu) = crepuscular::gpu::test_gpu("rectified_depth_is_clamped_not_clipped_on_the_gpu") else { return };
    let (g, req, expect) = near_far_request();
    let host = GpuHost::new(&gpu, &g).unwrap();
    let cpu = rasterize_rectified(&g, &req);
    let mut paths = vec![true];
    if hardware_depth_clamp(&gpu) {
        paths.insert(0, false);
    } else {
        println!("the device has no DEPTH_CLIP_CONTROL: only the shader-clamp path runs");
    }
    for shader_clamp in paths {
        let what = if shader_clamp { "GPU shader clamp" } else { "GPU unclipped_depth" };
        let tex = host.render_rectified_with(&gpu, &req, shader_clamp).unwrap();
        let map = gpu.read_texture_f32(&tex, 0).unwrap();
        check_near_far(what, &map, &expect, 1e-5, 1e-3);
        let (frac, max) = agreement(&map, &cpu, 1e-4);
        println!("{what} vs CPU: {:.3}% of texels within 1e-4, largest difference {max}", 100.0 * frac);
        assert!(frac >= 0.99, "{what}: {frac}");
    }
}

#[test]
fn rectified_shader_clamp_matches_unclipped_depth() {
    let Some(gpu) = crepuscular::gpu::test_gpu("rectified_shader_clamp_matches_unclipped_depth") else { return };
    if !hardware_depth_clamp(&gpu) {
        println!("SKIPPED rectified_shader_clamp_matches_unclipped_depth: the device has no DEPTH_CLIP_CONTROL");
        return;
    }
    let (g, req) = colonnade_request();
    let host = GpuHost::new(&gpu, &g).unwrap();
    let unclipped = gpu.read_texture_f32(&host.render_rectified_with(&gpu, &req, false).unwrap(), 0).unwrap();
    let shader = gpu.read_texture_f32(&host.render_rectified_with(&gpu, &req, true).unwrap(), 0).unwrap();
    assert_eq!(unclipped, gpu.read_texture_f32(&host.render_rectified(&gpu, &req).unwrap(), 0).unwrap());
    let (frac, max) = agreement(&shader, &unclipped, 1e-4);
    println!(
        "ran unclipped_depth and shader clamp: {:.3}% of texels within 1e-4, largest difference {max}",
        100.0 * frac
    );
    assert!(frac >= 0.999, "{frac}");
}

/// A camera at the origin looking down −Z (60° vertical field of view).
fn head_on_camera() -> Camera {
    Camera { position: Vec3::ZERO, look_at: Vec3::new(0.0, 0.0, -1.0), ..Camera::default() }
}

#[test]
fn motion_vectors_of_a_sliding_face_are_its_exact_screen_shift() {
    // A square facing the camera at distance z moves by d parallel to the image: every point of
    // it moves on the screen by d·(H/2)/(tan(fov/2)·z) pixels (the pinhole's x = f·X/Z).
    let (w, h) = (96u32, 54u32);
    let cam = head_on_camera();
    let vp = cam.view_projection(w as f32 / h as f32);
    let z = 5.0f32;
    let (a, b, c, e) =
        (Vec3::new(-1.0, -1.0, -z), Vec3::new(1.0, -1.0, -z), Vec3::new(1.0, 1.0, -z), Vec3::new(-1.0, 1.0, -z));
    let g = geometry(&[[a, b, c], [a, c, e]]);
    let d = Vec3::new(0.3, -0.2, 0.0);
    let previous: Vec<[f32; 3]> = g.vertices.iter().map(|v| (Vec3::from(v.position) - d).to_array()).collect();
    let buf = rasterize(&g, vp, w, h);
    let mv = motion_vectors(&buf, &g, &previous, vp);
    let f = (h as f32 * 0.5) / 30f32.to_radians().tan();
    // Now minus then, UV units, y down.
    let expect = [d.x * f / z / w as f32, -d.y * f / z / h as f32];
    let mut drawn = 0;
    for (i, m) in mv.iter().enumerate() {
        if buf.triangle[i] == u32::MAX {
            assert_eq!(*m, [0.0, 0.0], "pixel {i}: nothing drawn, no motion");
            continue;
        }
        drawn += 1;
        // The rasterizer snaps vertices to 1/256 pixel, and the barycentrics (so the point
        // moved back) are the snapped triangle's: up to 1/256 pixel off.
        let off = [(m[0] - expect[0]) * w as f32, (m[1] - expect[1]) * h as f32];
        assert!(off[0].abs() < 1.0 / 256.0 && off[1].abs() < 1.0 / 256.0, "pixel {i}: {m:?} vs {expect:?}");
    }
    assert!(drawn > 200, "the square covers {drawn} pixels");
}

#[test]
fn motion_vectors_of_a_static_scene_are_the_cameras_reprojection() {
    // The geometry stays, the camera moves: each drawn pixel's vector is where its depth
    // buffer's world point was through the previous camera (the closed form the temporal stage
    // uses without motion vectors).
    let scene = builtin("colonnade").unwrap();
    let (w, h) = (96u32, 54u32);
    let aspect = w as f32 / h as f32;
    let before = scene.camera.clone();
    let mut after = before.clone();
    after.position += Vec3::new(0.4, 0.1, -0.3);
    let (vp0, vp1) = (before.view_projection(aspect), after.view_projection(aspect));
    let g = &scene.geometry;
    let positions: Vec<[f32; 3]> = g.vertices.iter().map(|v| v.position).collect();
    let buf = rasterize(g, vp1, w, h);
    let mv = motion_vectors(&buf, g, &positions, vp0);
    let inv = vp1.inverse();
    let mut worst = 0.0f32;
    let mut drawn = 0;
    for (i, m) in mv.iter().enumerate() {
        if buf.triangle[i] == u32::MAX {
            continue;
        }
        drawn += 1;
        let (x, y) = ((i as u32 % w) as f32 + 0.5, (i as u32 / w) as f32 + 0.5);
        let ndc = Vec3::new(2.0 * x / w as f32 - 1.0, 1.0 - 2.0 * y / h as f32, buf.depth[i]);
        let p = inv.project_point3(ndc);
        let then = vp0.project_point3(p);
        let expect = [x / w as f32 - (then.x * 0.5 + 0.5), y / h as f32 - (0.5 - then.y * 0.5)];
        // In pixels.
        worst = worst.max(((m[0] - expect[0]) * w as f32).abs()).max(((m[1] - expect[1]) * h as f32).abs());
    }
    eprintln!("{drawn} drawn pixels; worst difference {worst:.2e} px");
    assert!(drawn > (w * h / 2) as usize, "the colonnade covers {drawn} pixels");
    // Measured: 2.2e-3 px (the depth buffer's f32 rounding and the 1/256-pixel vertex snap).
    assert!(worst < 0.01, "motion vectors and the depth buffer's reprojection differ by {worst} px");
}
