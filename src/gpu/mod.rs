//! The wgpu path: adapter choice, device limits, buffers and pipelines for training and evaluating networks in WGSL compute shaders.
