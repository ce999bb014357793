"""The codec contract every codec on osnerf's links meets, the codec registry, checkpoints (the
knowledge base), focus for any codec, fitting to a declared input size, and what every link
scheme returns."""
