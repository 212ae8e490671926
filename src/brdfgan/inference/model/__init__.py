"""The model stage: loading a generator, running it (tiled when large), its memory needs."""
