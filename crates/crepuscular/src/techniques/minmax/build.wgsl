// minmax pass `build` (cpu.rs build, level_offset): Chen, Baran, Durand & Jarosz 2011 §3.1, the
// 1D min-max mipmap of each row of the rectified shadow map. One workgroup per row: level 0 the
// host's rasterized depths (with the volume bias) or, where the map resamples the standard
// shadow map, the bounds of the standard texels each rectified texel covers (bounds.wgsl); then
// each coarser level the (min, max) of two children, a barrier between levels. Row r's nodes
// are tree[r·2W ..], level k from 2W − 2W/2^k on.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var depth_map: texture_2d<f32>;
@group(0) @binding(3) var<storage, read_write> tree: array<vec2<f32>>;
@group(0) @binding(4) var shadow_map: texture_2d_array<f32>;

fn band_value(i: u32) -> f32 {
    return 0.0;
}

fn level_offset(width: u32, level: u32) -> u32 {
    return 2u * width - ((2u * width) >> level);
}

@compute @workgroup_size(64)
fn build(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let row = wg.x;
    let w = params.width;
    let base = row * 2u * w;
    let host = (params.flags & FLAG_HOST_RASTER) != 0u && params.mode == RECT_PROJECTIVE;
    let light = lights.items[0];
    for (var c = li; c < w; c += 64u) {
        if host {
            let d = texel_depth(params, textureLoad(depth_map, vec2<i32>(i32(c), i32(row)), 0).r, c);
            tree[base + c] = vec2<f32>(d, d);
        } else {
            tree[base + c] = texel_bounds(params, light, c, row);
        }
    }
    let levels = params.tree_levels;
    for (var l = 1u; l <= levels; l++) {
        storageBarrier();
        workgroupBarrier();
        let below = base + level_offset(w, l - 1u);
        let at = base + level_offset(w, l);
        for (var i = li; i < (w >> l); i += 64u) {
            let a = tree[below + 2u * i];
            let b = tree[below + 2u * i + 1u];
            tree[at + i] = vec2<f32>(min(a.x, b.x), max(a.y, b.y));
        }
    }
}
