"""Training any trainable codec through a channel: the loop, its config, state and resume, batches,
data, training channels and torchrun."""
