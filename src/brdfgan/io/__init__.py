"""Reading and writing images and map sets on disk."""
