// minmax pass `traverse` (cpu.rs traverse): per pixel, `shade` (walk.wgsl). Pixels of the
// epipole disc are the `epipole` pass's (epipole.wgsl). The walks' counts are reduced per workgroup and added to
// `counters`: rays, nodes, most nodes of one ray, lit nodes, shadowed nodes, rays over budget,
// mixed texels.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;
@group(0) @binding(3) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(4) var spot_tex: texture_2d_array<f32>;
@group(0) @binding(5) var out_tex: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var<storage, read> tree: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>, 7>;

var<workgroup> wg_counts: array<atomic<u32>, 7>;

@compute @workgroup_size(8, 8)
fn traverse(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    if li < 7u {
        atomicStore(&wg_counts[li], 0u);
    }
    workgroupBarrier();
    let px = id.xy;
    if px.x < frame.width && px.y < frame.height && !in_epipole_disc(params, px) {
        let dir = pixel_ray(frame, px);
        let s = view_distance(frame, textureLoad(depth_tex, vec2<i32>(px), 0).r, dir);
        let r = shade(frame, params, dir, s);
        textureStore(out_tex, vec2<i32>(px), vec4<f32>(r.l, 1.0));
        atomicAdd(&wg_counts[0], 1u);
        atomicAdd(&wg_counts[1], r.walk.nodes);
        atomicMax(&wg_counts[2], r.walk.nodes);
        atomicAdd(&wg_counts[3], r.walk.lit);
        atomicAdd(&wg_counts[4], r.walk.shadowed);
        atomicAdd(&wg_counts[5], r.walk.over_budget);
        atomicAdd(&wg_counts[6], r.walk.mixed);
    }
    workgroupBarrier();
    if li < 7u {
        let v = atomicLoad(&wg_counts[li]);
        if li == 2u {
            atomicMax(&counters[2], v);
        } else if v > 0u {
            atomicAdd(&counters[li], v);
        }
    }
}
