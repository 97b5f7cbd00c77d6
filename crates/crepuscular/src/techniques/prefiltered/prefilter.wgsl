// prefiltered pass `prefilter` (cpu.rs prefilter, texel_depth, texel_weight): Klehm et al. 2014
// §3.3, Listings 1–3. One thread per row × region × group of `bases_per_thread` bases walks its
// columns left to right, turning each depth into eq. 8's bases (fused, Listing 3) and keeping
// the weighted running mean Σwᵢ·B(zᵢ)/Σwᵢ (`mix`, Listing 2), stored in [0, 1] (Appendix A).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(3) var<storage, read> rows: array<f32>;
@group(0) @binding(4) var depth_map: texture_2d<f32>;
@group(0) @binding(5) var out_basis: texture_storage_2d_array<BASIS_FORMAT, write>;
@group(0) @binding(6) var out_cumw: texture_storage_2d_array<r32float, write>;

fn band_value(i: u32) -> f32 {
    return rows[i];
}

fn texel_weight(f: Frame, p: Params, row: u32, band: u32, channel: u32, col: u32) -> f32 {
    if (p.flags & FLAG_TRANSMITTANCE_WEIGHTS) == 0u {
        return 1.0;
    }
    let sigma = p.camera.w;
    let rr = rows[row * p.bands + band];
    var ta = 0.0;
    if col > 0u {
        ta = reference_distance(p, rr, row, f32(col));
    }
    let tb = reference_distance(p, rr, row, f32(col) + 1.0);
    if ta >= INF {
        return 0.0;
    }
    if p.local == 0u {
        return exp(-sigma * ta) * segment_transmittance1(sigma, tb - ta);
    }
    if tb >= INF {
        return 0.0;
    }
    let tm = 0.5 * (ta + tb);
    let dir = reference_dir(p, rr, row);
    let inc = light_incident(f, lights.items[0], spot_tex, p.camera.xyz + dir * tm);
    let ph = phase(f, dot(inc.dir, -dir));
    let c = inc.radiance * ph;
    var lum = dot(c, vec3<f32>(1.0 / 3.0));
    if p.channels == 3u {
        lum = c[channel];
    }
    return lum * exp(-sigma * tm) * (tb - ta);
}

const MAX_GROUP_LAYERS: u32 = 32u;

@compute @workgroup_size(64)
fn prefilter(@builtin(global_invocation_id) id: vec3<u32>) {
    let h = params.height;
    let regions = params.regions;
    let group_layers = params.bases_per_thread / 4u;
    let groups = params.bases / params.bases_per_thread;
    let channels = params.channels;
    let sets = params.bands * channels;
    let i = id.x + id.y * 65535u * 64u;
    if i >= h * regions * groups * sets {
        return;
    }
    let row = i % h;
    let region = (i / h) % regions;
    let group = (i / (h * regions)) % groups;
    let wset = i / (h * regions * groups);
    let band = wset / channels;
    let channel = wset % channels;
    let l0 = group * group_layers;
    let first_layer = wset * (params.bases / 4u);
    let cols = region_columns(params, region);
    var filt: array<vec4<f32>, MAX_GROUP_LAYERS>;
    for (var l = 0u; l < group_layers; l++) {
        filt[l] = vec4<f32>(0.0);
    }
    var sum = 0.0;
    for (var col = cols.x; col < cols.y; col++) {
        let stored = textureLoad(depth_map, vec2<i32>(i32(col), i32(row)), 0).r;
        let z = basis_z(texel_depth(params, stored, col));
        let wt = texel_weight(frame, params, row, band, channel, col);
        sum += wt;
        var fr = 1.0;
        if sum > 0.0 {
            fr = wt / sum;
        }
        if group == 0u {
            textureStore(out_cumw, vec2<i32>(i32(col), i32(row)), i32(wset), vec4<f32>(sum, 0.0, 0.0, 0.0));
        }
        // Eq. 8's bases of this group by rotation (cpu.rs basis_rotor): sin/cos of c_k·z for
        // k = 2·l0 … from one sin/cos of the first harmonic and one of the step 2π·z.
        var sc = vec2<f32>(sin(PI * f32(4u * l0 + 1u) * z), cos(PI * f32(4u * l0 + 1u) * z));
        let step = vec2<f32>(sin(2.0 * PI * z), cos(2.0 * PI * z));
        for (var l = 0u; l < group_layers; l++) {
            let sc2 = vec2<f32>(sc.x * step.y + sc.y * step.x, sc.y * step.y - sc.x * step.x);
            let b = vec4<f32>(sc, sc2);
            sc = vec2<f32>(sc2.x * step.y + sc2.y * step.x, sc2.y * step.y - sc2.x * step.x);
            filt[l] += (b - filt[l]) * fr;
            textureStore(out_basis, vec2<i32>(i32(col), i32(row)), i32(first_layer + l0 + l), filt[l] * 0.5 + 0.5);
        }
    }
}
