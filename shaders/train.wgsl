// train.wgsl — full-batch Adam for every network of a batch at once (host: src/gpu/train.rs).
// The CPU reference (src/nn/train.rs) is the specification: same layout, same operation order.
//
// Per epoch the host records two dispatches:
//   forward_backward  one thread per sample of the batch: forward pass, loss gradient
//                     2(y − t)/n, backward pass; stores each layer's outputs and deltas.
//   gradient_adam     one thread per (parameter, network): lane t of GRAD_LANES sums samples
//                     t, t + 64, … in order, a fixed binary tree adds the lanes, then Adam.
//                     No atomics, no data-dependent order: the same bytes every run.
// and, every loss_every epochs only, loss_reduce (one workgroup per network).
//
// Unit storage (acts, deltas): network k owns [nets[k].act_offset, + sample_count * unit_count);
// unit u of its sample s sits at act_offset + u * sample_count + s (unit-major, so the
// gradient threads of a workgroup read consecutive samples).

struct NetInfo {
    sample_offset: u32,
    sample_count: u32,
    act_offset: u32,
    // 2 / sample_count, computed on the host.
    grad_scale: f32,
}

struct Sample {
    x: f32,
    y: f32,
    target_value: f32,
    net: u32,
}

struct Step {
    learning_rate: f32,
    // 1 / (1 − β₁ᵗ) and 1 / (1 − β₂ᵗ), computed on the host in f64.
    correction1: f32,
    correction2: f32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> dims: Dims;
@group(0) @binding(1) var<storage, read> nets: array<NetInfo>;
@group(0) @binding(2) var<storage, read> samples: array<Sample>;
@group(0) @binding(3) var<storage, read_write> params: array<f32>;
// Adam moments: m of parameter p of network k at k * param_count + p, v at
// (net_count + k) * param_count + p.
@group(0) @binding(4) var<storage, read_write> moments: array<f32>;
@group(0) @binding(5) var<storage, read_write> acts: array<f32>;
@group(0) @binding(6) var<storage, read_write> deltas: array<f32>;
@group(0) @binding(7) var<storage, read_write> sq_err: array<f32>;
@group(0) @binding(8) var<storage, read_write> losses: array<f32>;
@group(1) @binding(0) var<uniform> step: Step;

// Adam (Kingma & Ba 2015) constants as exact hex floats: the bits of src/nn ADAM_*.
const BETA1: f32 = 0x1.ccccccp-1f;           // 0.9
const ONE_MINUS_BETA1: f32 = 0x1.99999ap-4f; // 0.1
const BETA2: f32 = 0x1.ff7ceep-1f;           // 0.999
const ONE_MINUS_BETA2: f32 = 0x1.0624dep-10f; // 0.001
const EPSILON: f32 = 0x1.5798eep-27f;        // 1e-8

@compute @workgroup_size(64)
fn forward_backward(@builtin(global_invocation_id) gid: vec3<u32>,
                    @builtin(num_workgroups) groups: vec3<u32>) {
    let stride = groups.x * 64u;
    for (var g = gid.x; g < dims.sample_count; g += stride) {
        let sample = samples[g];
        let net = nets[sample.net];
        let n = net.sample_count;
        let s = g - net.sample_offset;
        let pbase = sample.net * dims.param_count;
        let abase = net.act_offset;
        let last = dims.layer_count - 1u;
        // Forward: z = b[i] + Σ_j W[i][j]·a[j], j ascending.
        for (var l = 0u; l < dims.layer_count; l++) {
            let layer = dims.layers[l];
            let prev_unit = dims.layers[max(l, 1u) - 1u].unit_offset;
            let bias = pbase + layer.weight_offset + layer.inputs * layer.outputs;
            for (var i = 0u; i < layer.outputs; i++) {
                var z = params[bias + i];
                let row = pbase + layer.weight_offset + i * layer.inputs;
                for (var j = 0u; j < layer.inputs; j++) {
                    var a: f32;
                    if l == 0u {
                        a = select(sample.y, sample.x, j == 0u);
                    } else {
                        a = acts[abase + (prev_unit + j) * n + s];
                    }
                    z = z + params[row + j] * a;
                }
                if l != last {
                    z = activate(z, dims.activation);
                }
                acts[abase + (layer.unit_offset + i) * n + s] = z;
            }
        }
        let out_unit = dims.layers[last].unit_offset;
        let err = acts[abase + out_unit * n + s] - sample.target_value;
        sq_err[g] = err * err;
        deltas[abase + out_unit * n + s] = err * net.grad_scale;
        // Backward: δ_prev[j] = (Σ_i W[i][j]·δ[i], i ascending) · f'(a_prev[j]).
        for (var l = last; l > 0u; l--) {
            let layer = dims.layers[l];
            let prev_unit = dims.layers[l - 1u].unit_offset;
            for (var j = 0u; j < layer.inputs; j++) {
                var b = 0.0;
                for (var i = 0u; i < layer.outputs; i++) {
                    let w = params[pbase + layer.weight_offset + i * layer.inputs + j];
                    b = b + w * deltas[abase + (layer.unit_offset + i) * n + s];
                }
                let at = abase + (prev_unit + j) * n + s;
                deltas[at] = b * activation_derivative(acts[at], dims.activation);
            }
        }
    }
}

// One thread per (parameter, network): x = parameter (grid-stride), y = network.
@compute @workgroup_size(64)
fn gradient_adam(@builtin(global_invocation_id) gid: vec3<u32>,
                 @builtin(num_workgroups) groups: vec3<u32>) {
    let k = gid.y;
    let net = nets[k];
    let n = net.sample_count;
    let abase = net.act_offset;
    for (var p = gid.x; p < dims.param_count; p += groups.x * 64u) {
        // Which layer, and weight (i, j) or bias i.
        var l = 0u;
        var layer = dims.layers[0];
        for (var q = 0u; q < dims.layer_count; q++) {
            layer = dims.layers[q];
            l = q;
            if p < layer.weight_offset + layer.inputs * layer.outputs + layer.outputs {
                break;
            }
        }
        let local = p - layer.weight_offset;
        let weights = layer.inputs * layer.outputs;
        let is_bias = local >= weights;
        let i = select(local / layer.inputs, local - weights, is_bias);
        let j = local % layer.inputs;
        let prev_unit = dims.layers[max(l, 1u) - 1u].unit_offset;
        let delta_row = abase + (layer.unit_offset + i) * n;
        let act_row = abase + (prev_unit + j) * n;
        // Lane t sums samples t, t + 64, … in ascending order.
        var lanes: array<f32, 64>;
        for (var t = 0u; t < GRAD_LANES; t++) {
            var acc = 0.0;
            for (var s = t; s < n; s += GRAD_LANES) {
                let d = deltas[delta_row + s];
                if is_bias {
                    acc = acc + d;
                } else {
                    var a: f32;
                    if l == 0u {
                        let sample = samples[net.sample_offset + s];
                        a = select(sample.y, sample.x, j == 0u);
                    } else {
                        a = acts[act_row + s];
                    }
                    acc = acc + d * a;
                }
            }
            lanes[t] = acc;
        }
        // Fixed binary tree: lane t += lane t + half, half = 32, 16, … 1.
        for (var half = GRAD_LANES / 2u; half > 0u; half = half / 2u) {
            for (var t = 0u; t < half; t++) {
                lanes[t] = lanes[t] + lanes[t + half];
            }
        }
        let g = lanes[0];
        let at = k * dims.param_count + p;
        let vt = (dims.net_count + k) * dims.param_count + p;
        let m = BETA1 * moments[at] + ONE_MINUS_BETA1 * g;
        let v = BETA2 * moments[vt] + ONE_MINUS_BETA2 * (g * g);
        moments[at] = m;
        moments[vt] = v;
        let m_hat = m * step.correction1;
        let v_hat = v * step.correction2;
        params[at] = params[at] - step.learning_rate * m_hat / (sqrt(v_hat) + EPSILON);
    }
}

var<workgroup> partial: array<f32, 256>;

// losses[k] = mean squared error of network k at the last forward pass.
@compute @workgroup_size(256)
fn loss_reduce(@builtin(local_invocation_id) lid: vec3<u32>,
               @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) groups: vec3<u32>) {
    let t = lid.x;
    for (var k = wid.x; k < dims.net_count; k += groups.x) {
        let net = nets[k];
        var acc = 0.0;
        for (var s = t; s < net.sample_count; s += 256u) {
            acc = acc + sq_err[net.sample_offset + s];
        }
        partial[t] = acc;
        workgroupBarrier();
        for (var half = 128u; half > 0u; half = half / 2u) {
            if t < half {
                partial[t] = partial[t] + partial[t + half];
            }
            workgroupBarrier();
        }
        if t == 0u {
            losses[k] = partial[0] / f32(net.sample_count);
        }
        workgroupBarrier();
    }
}
