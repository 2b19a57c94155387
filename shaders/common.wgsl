// common.wgsl — declarations shared by train.wgsl and evaluate.wgsl (prepended to each on the host).
// Every struct here is mirrored by a #[repr(C)] bytemuck struct of the same name in src/gpu/layout.rs.

// Hidden layers + output layer: src/nn MAX_HIDDEN_LAYERS + 1.
const MAX_LAYERS: u32 = 9u;
// Widest layer: src/nn MAX_WIDTH.
const MAX_WIDTH: u32 = 256u;
// Gradient lanes = workgroup size of gradient_adam: src/nn GRAD_LANES.
const GRAD_LANES: u32 = 64u;

// One weight layer. Parameters of network k start at k * Dims.param_count; within it,
// W[i][j] is at weight_offset + i * inputs + j and b[i] at weight_offset + inputs * outputs + i.
// unit_offset: first of this layer's outputs among a sample's stored units.
struct LayerInfo {
    inputs: u32,
    outputs: u32,
    weight_offset: u32,
    unit_offset: u32,
}

struct Dims {
    net_count: u32,
    param_count: u32,
    layer_count: u32,
    unit_count: u32,
    // Training: samples of the whole batch. Evaluation: points of this dispatch.
    sample_count: u32,
    // 0 tanh, 1 relu (src/nn Activation::shader_code).
    activation: u32,
    _pad0: u32,
    _pad1: u32,
    layers: array<LayerInfo, 9>,
}

// tanh as Eigen's rational approximation (generic_fast_tanh_float), operation for operation
// as src/nn tanh_f32, coefficients as exact hex floats: the built-in tanh differs from the
// CPU's in the last ulp, and full-batch Adam amplifies such differences.
fn tanh_f32(x_in: f32) -> f32 {
    let x = min(max(x_in, -0x1.f9f09ep+2f), 0x1.f9f09ep+2f);
    let x2 = x * x;
    var p = x2 * -0x1.3e4b8p-52f + 0x1.c266fcp-43f;
    p = x2 * p + -0x1.7a6ffep-34f;
    p = x2 * p + 0x1.b80082p-25f;
    p = x2 * p + 0x1.f28694p-17f;
    p = x2 * p + 0x1.4e1bdap-11f;
    p = x2 * p + 0x1.40b3b8p-8f;
    p = x * p;
    var q = x2 * 0x1.41a7bp-20f + 0x1.f12bacp-14f;
    q = x2 * q + 0x1.29540ap-9f;
    q = x2 * q + 0x1.40b3bap-8f;
    return select(p / q, x, abs(x) < 0x1.a36e2ep-12f);
}

fn activate(z: f32, activation: u32) -> f32 {
    if activation == 0u {
        return tanh_f32(z);
    }
    return max(z, 0.0);
}

// Derivative through the activation's output a (what backprop keeps).
fn activation_derivative(a: f32, activation: u32) -> f32 {
    if activation == 0u {
        return 1.0 - a * a;
    }
    return select(0.0, 1.0, a > 0.0);
}
