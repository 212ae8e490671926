"""Outputs: texture files, material.glb and material.json, written as one folder atomically."""
