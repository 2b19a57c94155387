//! WGSL generated per architecture: `gradient_adam_rows`, the gradient reduction and Adam step of `shaders/train.wgsl` with one workgroup per weight row, for lavapipe and other SIMD-on-CPU adapters.
//!
//! The generic `gradient_adam` runs one thread per parameter; on lavapipe each thread's
//! 64 gradient lanes live in a dynamically indexed private array and every term costs two
//! gathers. Here workgroup (row i of layer l, network k) has 64 threads, thread t being lane
//! t: it sums δ_i(s)·a_j(s) for all inputs j of the row (and δ_i(s) for the bias) over samples
//! s = t, t + 64, … in ascending order, in registers (the row width is a constant of the
//! generated text), then the workgroup adds the lanes in the same binary tree
//! (lane t += lane t + half, half = 32, 16, … 1) and threads 0..=inputs apply Adam.
//! Same f32 operations in the same order as `gradient_adam` and the CPU reference.

use std::fmt::Write;

use crate::nn::{layer_spans, unit_offsets, Activation, LayerSpan, GRAD_LANES};

/// Widest layer input the row kernel holds in registers and workgroup memory
/// ((inputs + 1) · 64 floats of workgroup memory: 16 KiB at 63 inputs).
pub const MAX_ROW_INPUTS: usize = 63;

/// The `gradient_adam_rows` entry point for these layer sizes and the number of rows
/// (workgroups per network) to dispatch, or `None` when a layer is too wide.
/// Appended to `TRAIN_WGSL` by the host; dispatch `(rows, networks, 1)`.
pub fn gradient_rows_source(layer_sizes: &[usize]) -> Option<(String, u32)> {
    let spans = layer_spans(layer_sizes);
    let params: usize = spans.last().map(|s| s.bias_offset + s.outputs)?;
    let widest = spans.iter().map(|s| s.inputs).max()?;
    if widest > MAX_ROW_INPUTS || GRAD_LANES != 64 || layer_sizes.first() != Some(&2) {
        return None;
    }
    let unit_offset = unit_offsets(&spans);
    let units: usize = spans.iter().map(|span| span.outputs).sum();
    let mut w = String::new();
    // `writeln!` into a String cannot fail.
    let mut line = |text: String| {
        let _ = writeln!(w, "{text}");
    };
    gradient_rows_header(&mut line, widest);
    for (l, span) in spans.iter().enumerate() {
        let first_row = unit_offset[l];
        let cond = if l == 0 {
            format!("    if row < {}u {{", first_row + span.outputs)
        } else {
            format!("    }} else if row < {}u {{", first_row + span.outputs)
        };
        line(cond);
        line(format!("        let i = row - {first_row}u;"));
        row_lane_sums(&mut line, l, span, &unit_offset);
        row_tree_reduce(&mut line, span.inputs);
        row_adam(&mut line, span, params);
    }
    line("    }".into());
    line("}".into());
    Some((w, units as u32))
}

/// The workgroup memory of the lanes' row sums and the kernel's signature and common lets.
fn gradient_rows_header(line: &mut dyn FnMut(String), widest: usize) {
    line(format!(
        "var<workgroup> row_lanes: array<f32, {}>;",
        (widest + 1) * 64
    ));
    line("@compute @workgroup_size(64)".into());
    line("fn gradient_adam_rows(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {".into());
    line("    let t = lid.x;".into());
    line("    let k = gid.y;".into());
    line("    let net = nets[k];".into());
    line("    let n = net.sample_count;".into());
    line("    let abase = net.act_offset;".into());
    line("    let row = wid.x;".into());
}

/// Lane t's sums g0 … g{inputs} of δ_i(s)·a_j(s) (and δ_i(s)) over its samples of a row of
/// layer `l`, stored into the lanes' workgroup memory.
fn row_lane_sums(line: &mut dyn FnMut(String), l: usize, span: &LayerSpan, unit_offset: &[usize]) {
    let inputs = span.inputs;
    line("        let delta_row = abase + row * n;".into());
    for j in 0..=inputs {
        line(format!("        var g{j} = 0.0;"));
    }
    line("        for (var s = t; s < n; s += 64u) {".into());
    line("            let d = deltas[delta_row + s];".into());
    if l == 0 {
        line("            let sample = samples[net.sample_offset + s];".into());
        for j in 0..inputs {
            let a = if j == 0 { "sample.x" } else { "sample.y" };
            line(format!("            g{j} = g{j} + d * {a};"));
        }
    } else {
        for j in 0..inputs {
            line(format!(
                "            g{j} = g{j} + d * acts[abase + {}u * n + s];",
                unit_offset[l - 1] + j
            ));
        }
    }
    line(format!("            g{inputs} = g{inputs} + d;"));
    line("        }".into());
    for j in 0..=inputs {
        line(format!("        row_lanes[{}u + t] = g{j};", j * 64));
    }
}

/// The 64 lanes of each of the row's `inputs + 1` sums added in the binary tree
/// (lane t += lane t + half, half = 32, 16, … 1).
fn row_tree_reduce(line: &mut dyn FnMut(String), inputs: usize) {
    line("        workgroupBarrier();".into());
    line("        for (var half = 32u; half > 0u; half = half / 2u) {".into());
    line("            if t < half {".into());
    for j in 0..=inputs {
        line(format!(
            "                row_lanes[{o}u + t] = row_lanes[{o}u + t] + row_lanes[{o}u + t + half];",
            o = j * 64
        ));
    }
    line("            }".into());
    line("            workgroupBarrier();".into());
    line("        }".into());
}

/// Threads 0..=inputs apply Adam to the row's weights and bias.
fn row_adam(line: &mut dyn FnMut(String), span: &LayerSpan, params: usize) {
    let inputs = span.inputs;
    line(format!("        if t <= {inputs}u {{"));
    line("            let g = row_lanes[t * 64u];".into());
    line(format!(
        "            let p = select({w}u + i * {inputs}u + t, {b}u + i, t == {inputs}u);",
        w = span.weight_offset,
        b = span.bias_offset
    ));
    line(format!("            let at = k * {params}u + p;"));
    line(format!(
        "            let vt = (dims.net_count + k) * {params}u + p;"
    ));
    line("            let m = BETA1 * moments[at] + ONE_MINUS_BETA1 * g;".into());
    line("            let v = BETA2 * moments[vt] + ONE_MINUS_BETA2 * (g * g);".into());
    line("            moments[at] = m;".into());
    line("            moments[vt] = v;".into());
    line("            let m_hat = m * step.correction1;".into());
    line("            let v_hat = v * step.correction2;".into());
    line("            params[at] = params[at] - step.learning_rate * m_hat / (sqrt(v_hat) + EPSILON);".into());
    line("        }".into());
}

/// Widest layer the row forward kernel holds in registers.
pub const MAX_FORWARD_WIDTH: usize = 64;

/// The `forward_backward_rows` entry point for these layer sizes, or `None` when a layer is
/// wider than [`MAX_FORWARD_WIDTH`] or the output is not a single unit.
///
/// `forward_backward` of `shaders/train.wgsl` with the layer loop unrolled: each layer loads
/// its inputs (or, backwards, its deltas) once into registers, then loops over its outputs
/// (inputs) with the inner sum unrolled, so a term costs one weight load instead of a weight
/// and an activation load. Same operations in the same order: z = b[i] + Σ_j W[i][j]·a[j],
/// j ascending; δ_prev[j] = (0 + Σ_i W[i][j]·δ[i], i ascending) · f'(a_prev[j]).
/// Fully unrolling the output loop as well was measured 2.5× slower on lavapipe.
pub fn forward_rows_source(layer_sizes: &[usize], activation: Activation) -> Option<String> {
    let spans = layer_spans(layer_sizes);
    let params: usize = spans.last().map(|s| s.bias_offset + s.outputs)?;
    let widest = layer_sizes.iter().copied().max()?;
    if widest > MAX_FORWARD_WIDTH
        || layer_sizes.first() != Some(&2)
        || layer_sizes.last() != Some(&1)
    {
        return None;
    }
    let last = spans.len() - 1;
    let unit_offset = unit_offsets(&spans);
    let mut w = String::new();
    let mut line = |text: String| {
        let _ = writeln!(w, "{text}");
    };
    forward_rows_header(&mut line, params);
    for (l, span) in spans.iter().enumerate() {
        forward_layer(&mut line, l, span, l == last, &unit_offset, activation);
    }
    line("        let err = y - sample.target_value;".into());
    line("        sq_err[g] = err * err;".into());
    line("        let dout = err * net.grad_scale;".into());
    line(format!(
        "        deltas[ab + {}u * n] = dout;",
        unit_offset[last]
    ));
    for l in (1..=last).rev() {
        backward_layer(&mut line, l, &spans[l], l == last, &unit_offset, activation);
    }
    line("    }".into());
    line("}".into());
    Some(w)
}

/// The kernel's signature and the head of its loop over this thread's samples.
fn forward_rows_header(line: &mut dyn FnMut(String), params: usize) {
    line("@compute @workgroup_size(64)".into());
    line("fn forward_backward_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {".into());
    line("    let k = gid.y;".into());
    line("    let net = nets[k];".into());
    line("    let n = net.sample_count;".into());
    line(format!("    let pb = k * {params}u;"));
    line("    for (var s = gid.x; s < n; s += groups.x * 64u) {".into());
    line("        let g = net.sample_offset + s;".into());
    line("        let sample = samples[g];".into());
    line("        let ab = net.act_offset + s;".into());
}

/// Layer `l` forward: its inputs into registers x{l}_{j}, then each output's sum and
/// activation (the last layer's single output, linear, into `y`).
fn forward_layer(
    line: &mut dyn FnMut(String),
    l: usize,
    span: &LayerSpan,
    is_last: bool,
    unit_offset: &[usize],
    activation: Activation,
) {
    for j in 0..span.inputs {
        let value = if l == 0 {
            if j == 0 {
                "sample.x".to_string()
            } else {
                "sample.y".to_string()
            }
        } else {
            format!("acts[ab + {}u * n]", unit_offset[l - 1] + j)
        };
        line(format!("        let x{l}_{j} = {value};"));
    }
    let sum = |line: &mut dyn FnMut(String), i: &str| {
        line(format!(
            "            var z = params[pb + {}u + {i}];",
            span.bias_offset
        ));
        for j in 0..span.inputs {
            line(format!(
                "            z = z + params[pb + {}u + {i} * {}u] * x{l}_{j};",
                span.weight_offset + j,
                span.inputs
            ));
        }
    };
    if is_last {
        line("        var y: f32;".into());
        line("        {".into());
        sum(line, "0u");
        line("            y = z;".into());
        line("        }".into());
    } else {
        line(format!(
            "        for (var i = 0u; i < {}u; i++) {{",
            span.outputs
        ));
        sum(line, "i");
        let act = match activation {
            Activation::Tanh => "tanh_f32(z)".to_string(),
            Activation::Relu => "max(z, 0.0)".to_string(),
        };
        line(format!(
            "            acts[ab + ({}u + i) * n] = {act};",
            unit_offset[l]
        ));
        line("        }".into());
    }
}

/// Layer `l` backward: its deltas into registers e{l}_{i}, then each input's delta
/// δ_prev[j] = (0 + Σ_i W[i][j]·δ[i]) · f'(a_prev[j]).
fn backward_layer(
    line: &mut dyn FnMut(String),
    l: usize,
    span: &LayerSpan,
    is_last: bool,
    unit_offset: &[usize],
    activation: Activation,
) {
    for i in 0..span.outputs {
        let value = if is_last {
            "dout".to_string()
        } else {
            format!("deltas[ab + {}u * n]", unit_offset[l] + i)
        };
        line(format!("        let e{l}_{i} = {value};"));
    }
    line(format!(
        "        for (var j = 0u; j < {}u; j++) {{",
        span.inputs
    ));
    line("            var b = 0.0;".into());
    for i in 0..span.outputs {
        line(format!(
            "            b = b + params[pb + {}u + j] * e{l}_{i};",
            span.weight_offset + i * span.inputs
        ));
    }
    line(format!(
        "            let at = ab + ({}u + j) * n;",
        unit_offset[l - 1]
    ));
    line("            let a = acts[at];".into());
    let derivative = match activation {
        Activation::Tanh => "(1.0 - a * a)",
        Activation::Relu => "select(0.0, 1.0, a > 0.0)",
    };
    line(format!("            deltas[at] = b * {derivative};"));
    line("        }".into());
}
