//! Small neural networks for error maps: the MLP parameter layout (shared with the shaders), normalisation, the Trainer trait and the CPU reference trainer.
