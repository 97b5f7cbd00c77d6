// Copies layers of one of Bevy's shadow-map textures (Depth32Float, reversed-Z) into the
// plugin's shadow array (R32Float): the library reads every light's map from one array, and
// Bevy keeps directional cascades and spot maps in one texture, point-light cubes in another,
// at different sizes (docs/BEVY.md "Shadow maps"). Depth copies between textures of different
// sizes are not allowed by WebGPU, hence this pass. The value is copied bit for bit.

struct Job {
    src_layer: u32,
    dst_layer: u32,
    size: u32,
    _pad: u32,
}

@group(0) @binding(0) var src: texture_depth_2d_array;
@group(0) @binding(1) var dst: texture_storage_2d_array<r32float, write>;
@group(0) @binding(2) var<storage, read> jobs: array<Job>;

@compute @workgroup_size(8, 8, 1)
fn copy_layers(@builtin(global_invocation_id) id: vec3<u32>) {
    let job = jobs[id.z];
    if id.x >= job.size || id.y >= job.size {
        return;
    }
    let d = textureLoad(src, vec2<u32>(id.xy), job.src_layer, 0);
    textureStore(dst, vec2<u32>(id.xy), job.dst_layer, vec4<f32>(d, 0.0, 0.0, 1.0));
}
