"""Training any trainable codec through a channel: the loop, its config, state and resume, batches,
data, training channels and torchrun."""

from semcodec.jscc.channels import TRAIN_CHANNELS, train_channel
from semcodec.training.config import TrainConfig
from semcodec.training.loop import build_codec, train, train_inputs, validate, with_architecture
from semcodec.training.state import (
    RESUMABLE_FIELDS,
    ResumeRefused,
    check_resume,
    describe_changes,
    load_train_state,
)

__all__ = [
    "RESUMABLE_FIELDS",
    "ResumeRefused",
    "TRAIN_CHANNELS",
    "TrainConfig",
    "build_codec",
    "check_resume",
    "describe_changes",
    "load_train_state",
    "train",
    "train_channel",
    "train_inputs",
    "validate",
    "with_architecture",
]
