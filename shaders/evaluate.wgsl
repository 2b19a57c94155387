// evaluate.wgsl — every network of a batch on the same points (host: src/gpu/evaluate.rs).
// outputs[k * Dims.sample_count + i] = network k at points[i]; same operation order as
// src/nn Mlp::forward.

@group(0) @binding(0) var<uniform> dims: Dims;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> points: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> outputs: array<f32>;

@compute @workgroup_size(64)
fn evaluate(@builtin(global_invocation_id) gid: vec3<u32>,
            @builtin(workgroup_id) wid: vec3<u32>,
            @builtin(num_workgroups) groups: vec3<u32>) {
    let k = wid.y;
    let pbase = k * dims.param_count;
    let last = dims.layer_count - 1u;
    // Two halves of one array: the previous layer's outputs and the current one's.
    var h: array<f32, 512>;
    for (var g = gid.x; g < dims.sample_count; g += groups.x * 64u) {
        let x = points[g];
        h[0] = x.x;
        h[1] = x.y;
        var prev = 0u;
        for (var l = 0u; l < dims.layer_count; l++) {
            let layer = dims.layers[l];
            let next = MAX_WIDTH - prev;
            let bias = pbase + layer.weight_offset + layer.inputs * layer.outputs;
            for (var i = 0u; i < layer.outputs; i++) {
                var z = params[bias + i];
                let row = pbase + layer.weight_offset + i * layer.inputs;
                for (var j = 0u; j < layer.inputs; j++) {
                    z = z + params[row + j] * h[prev + j];
                }
                if l != last {
                    z = activate(z, dims.activation);
                }
                h[next + i] = z;
            }
            prev = next;
        }
        outputs[k * dims.sample_count + g] = h[prev];
    }
}
