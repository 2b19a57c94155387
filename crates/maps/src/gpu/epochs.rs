//! The host epoch loop both training kernel families share ([`super::train`], [`super::lavapipe`]): epochs recorded in submissions of Step slots, losses read back every `loss_every` epochs, the trained weights read back; the kernel records its own dispatches.

use std::ops::Range;

use wgpu::util::DeviceExt;

use super::context::GpuContext;
use super::layout::Step;
use crate::nn::{diverged, Mlp, ModelConfig};
use errmap_core::{Error, Result};

/// Most epochs recorded into one submission (and Step slots in the step buffer).
pub const EPOCHS_PER_SUBMISSION: u32 = 256;

/// Bytes between consecutive slots of a dynamically offset uniform buffer on this device.
pub fn uniform_align(ctx: &GpuContext) -> u64 {
    ctx.limits.min_uniform_buffer_offset_alignment.max(16) as u64
}

/// A buffer holding `contents`.
pub fn init_buffer(
    device: &wgpu::Device,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage,
    })
}

/// The uniform buffer of one submission's Step slots, `align` bytes apart.
pub fn step_buffer(device: &wgpu::Device, align: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("steps"),
        size: EPOCHS_PER_SUBMISSION as u64 * align,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// The first `size` bytes of `buffer` as a binding (one slot of a dynamically offset buffer).
pub fn sized(buffer: &wgpu::Buffer, size: u64) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer,
        offset: 0,
        size: std::num::NonZeroU64::new(size),
    })
}

/// Byte offset of slot `slot` in a buffer of slots `align` bytes apart.
pub fn slot_offset(slot: u32, align: u64) -> u32 {
    (slot as u64 * align) as u32
}

/// Where one training run's epoch loop reads and writes.
pub struct EpochLoop<'a> {
    pub ctx: &'a GpuContext,
    pub config: &'a ModelConfig,
    /// The Step slots, written before each submission ([`step_buffer`]).
    pub steps: &'a wgpu::Buffer,
    /// Bytes between Step slots.
    pub align: u64,
    /// One loss (f32) per network, filled by the kernel in a submission that reads the loss.
    pub losses: &'a wgpu::Buffer,
    pub net_count: usize,
    /// Index of the group's first network in the whole batch (for divergence errors).
    pub first_index: usize,
}

impl EpochLoop<'_> {
    /// Runs every epoch of the schedule. `record(pass, epochs, read_loss)` records the
    /// kernel's dispatches for `epochs` (the Step of epoch `e` in slot `e - epochs.start`);
    /// with `read_loss` it also records what fills the losses.
    pub fn run(
        &self,
        mut record: impl FnMut(&mut wgpu::ComputePass<'_>, Range<u32>, bool),
    ) -> Result<()> {
        let mut epoch = 0u32;
        while epoch < self.config.epochs {
            let (end, read_loss) = submission_end(self.config, epoch);
            self.write_steps(epoch..end);
            let mut encoder =
                self.ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("epochs"),
                    });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("epochs"),
                    timestamp_writes: None,
                });
                record(&mut pass, epoch..end, read_loss);
            }
            self.ctx.queue.submit([encoder.finish()]);
            if read_loss {
                self.check_losses(end - 1)?;
            }
            self.ctx.check("training")?;
            epoch = end;
        }
        Ok(())
    }

    /// Writes the Step of each epoch of `epochs` into its slot.
    fn write_steps(&self, epochs: Range<u32>) {
        let mut slots = vec![0u8; (epochs.len() as u64 * self.align) as usize];
        for e in epochs.clone() {
            let at = ((e - epochs.start) as u64 * self.align) as usize;
            slots[at..at + std::mem::size_of::<Step>()]
                .copy_from_slice(bytemuck::bytes_of(&Step::at(self.config, e)));
        }
        self.ctx.queue.write_buffer(self.steps, 0, &slots);
    }

    /// Reads the losses back; a non-finite one is the divergence of its network at `epoch`.
    fn check_losses(&self, epoch: u32) -> Result<()> {
        let bytes = self
            .ctx
            .read_buffer(self.losses, self.net_count as u64 * 4, "training")?;
        let losses: &[f32] = bytemuck::try_cast_slice(&bytes)
            .map_err(|e| Error::Internal(format!("loss read-back: {e}")))?;
        if let Some(k) = losses.iter().position(|l| !l.is_finite()) {
            return Err(diverged(self.first_index + k, epoch));
        }
        Ok(())
    }

    /// The trained networks from `params` (network k's parameters at float `k * stride`);
    /// a non-finite parameter is the divergence of its network.
    pub fn read_trained(
        &self,
        params: &wgpu::Buffer,
        initial: &[Mlp],
        stride: usize,
    ) -> Result<Vec<Mlp>> {
        let bytes = self.ctx.read_buffer(
            params,
            (self.net_count * stride * 4) as u64,
            "reading trained weights",
        )?;
        let trained: &[f32] = bytemuck::try_cast_slice(&bytes)
            .map_err(|e| Error::Internal(format!("parameter read-back: {e}")))?;
        let nets: Vec<Mlp> = initial
            .iter()
            .zip(trained.chunks_exact(stride))
            .map(|(net, p)| Mlp {
                layer_sizes: net.layer_sizes.clone(),
                activation: net.activation,
                params: p[..net.params.len()].to_vec(),
            })
            .collect();
        if let Some(k) = nets
            .iter()
            .position(|n| n.params.iter().any(|p| !p.is_finite()))
        {
            return Err(diverged(self.first_index + k, self.config.epochs));
        }
        Ok(nets)
    }
}

/// The end of the submission that starts at `epoch`, and whether the losses are read after
/// it: submissions end at loss read-back epochs, so the loss is read only there.
fn submission_end(config: &ModelConfig, epoch: u32) -> (u32, bool) {
    let next_loss = (epoch / config.loss_every + 1) * config.loss_every;
    let end = config
        .epochs
        .min(epoch + EPOCHS_PER_SUBMISSION)
        .min(next_loss);
    (end, end == next_loss || end == config.epochs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn submissions_end_at_loss_epochs_and_at_most_256_epochs_apart() {
        let config = ModelConfig {
            epochs: 600,
            loss_every: 100,
            ..Default::default()
        };
        assert_eq!(submission_end(&config, 0), (100, true));
        assert_eq!(submission_end(&config, 500), (600, true));
        let sparse = ModelConfig {
            epochs: 600,
            loss_every: 1000,
            ..Default::default()
        };
        // 256 epochs, no loss; then 256 more; then the last 88 with the loss of the end.
        assert_eq!(submission_end(&sparse, 0), (256, false));
        assert_eq!(submission_end(&sparse, 256), (512, false));
        assert_eq!(submission_end(&sparse, 512), (600, true));
    }
}
