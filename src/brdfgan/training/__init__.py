"""Training: the GAN LightningModule, its learning-rate schedule and the typed run config."""
