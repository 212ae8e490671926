"""Intake: photo files decoded to linear RGB, then cropped, resized and exposed for the network."""
