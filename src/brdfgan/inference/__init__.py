"""Inference: loading trained generators (safetensors weights, training checkpoints)."""
