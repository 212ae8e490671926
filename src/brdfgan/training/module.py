"""The conditional GAN as a LightningModule with manual optimization (paper §4, docs/conventions.md#gan-step).

Per training batch: a discriminator step, then a generator step, each inside
``toggled_optimizer`` with ``manual_backward`` and optional ``clip_gradients``. The learning
rate follows :class:`~brdfgan.training.schedule.LinearDecaySchedule` over *generator* steps —
schedulers are stepped by hand after each generator step, because ``global_step`` counts every
optimizer step (two per batch with a discriminator) and would halve the schedule.

A loss term that is switched off is not computed: without the adversarial and the feature term
there is no discriminator at all — no forward, no step, no optimizer state, no parameters.

Resuming is exact: a checkpoint stores every source of randomness the step draws from (the
rendering loss's own generator; Python's, NumPy's and torch's global generators), and the data
stream continues at the batch it had reached (:class:`~brdfgan.data.loading.datamodule.ShardDataModule`),
so an interrupted and resumed run ends with the same weights, bit for bit, as a straight one.
"""

from __future__ import annotations

import logging
import random
from collections.abc import Callable, Mapping
from typing import Any, cast

import lightning as L
import numpy as np
import torch
from torch import Tensor, nn
from torch.optim import Optimizer
from torch.optim.lr_scheduler import LambdaLR
from torch.profiler import record_function
from torchmetrics import MetricCollection

from brdfgan.errors import UserError
from brdfgan.losses.parameter import parameter_loss
from brdfgan.losses.rendering import rendering_loss
from brdfgan.losses.total import GANLoss
from brdfgan.metrics import fixed_render_configs, hotspot_centres
from brdfgan.models.heads import network_photos
from brdfgan.training.schedule import LinearDecaySchedule

log = logging.getLogger(__name__)

OptimizerFactory = Callable[..., Optimizer]

# Seed of the light/view configurations val/loss and test/loss render under: drawn once
# (fixed_render_configs, the evaluation metrics' draw), so every batch, batch size, epoch and model
# is compared under the same lights.
VALIDATION_RENDER_SEED = 2019
# Where a checkpoint keeps the random generators' states (see on_save_checkpoint).
RNG_STATE_KEY = "brdfgan_rng_states"


class SVBRDFGAN(L.LightningModule):
    """Generator + optional multi-scale discriminator trained with the paper's losses.

    Args:
        generator: photo ``(B, 3, H, W)`` → maps ``(B, 8, H, W)``.
        discriminator: a factory (Hydra ``_partial_``) building the discriminator; called only
            when the loss needs one.
        loss: the loss terms and their switches.
        optimizer: a factory ``params → Optimizer`` (Hydra ``_partial_``; paper: Adam 2e-4,
            β = (0.5, 0.999)), used for both networks.
        constant_lr_fraction: share of training at the base learning rate before the linear
            decay (paper: 0.5).
        total_steps: generator steps of the whole run; default ``max_epochs ×`` the datamodule's
            ``train_batches_per_epoch`` (or ``trainer.max_steps`` when set).
        gradient_clip: max gradient norm per network (``None``: no clipping).
        metrics: a factory of the evaluator's metric collection (:mod:`brdfgan.metrics`), so
            validation and test report the same numbers as ``evaluate.py``.
        channels_last: keep the networks' weights and activations in the NHWC memory format
            (faster convolutions on CUDA tensor cores; slower on CPU: docs/benchmarks.md#renderer-speed).

    The phases of a training step are labelled for ``torch.profiler`` (``brdfgan/…``; see
    ``benchmarks/bench_train.py``); the labels cost nothing when no profiler runs.
    """

    def __init__(
        self,
        generator: nn.Module,
        discriminator: Callable[[], nn.Module] | None,
        loss: GANLoss,
        optimizer: OptimizerFactory,
        constant_lr_fraction: float = 0.5,
        total_steps: int | None = None,
        gradient_clip: float | None = None,
        metrics: Callable[[], MetricCollection] | None = None,
        channels_last: bool = False,
    ) -> None:
        super().__init__()
        self.automatic_optimization = False
        # A rank may get no validation batch when val_samples is below the number of ranks
        # (ShardStream's exact lengths); Lightning refuses such a rank unless allowed.
        self.allow_zero_length_dataloader_with_multiple_devices = True
        self.generator = generator
        self.loss = loss
        # Drawn once: every validation and test batch renders under these (VALIDATION_RENDER_SEED).
        self.evaluation_render_configs = fixed_render_configs(
            loss.rendering_sampling.num_configs, VALIDATION_RENDER_SEED, loss.plane_half_size
        )
        self.uses_discriminator = loss.switches.needs_discriminator
        if self.uses_discriminator and discriminator is None:
            raise UserError("model.discriminator: the loss needs one (adversarial or feature term)")
        self.discriminator = discriminator() if self.uses_discriminator and discriminator else None
        self.optimizer_factory = optimizer
        self.constant_lr_fraction = constant_lr_fraction
        self.total_steps = total_steps
        self.gradient_clip = gradient_clip
        self.channels_last = channels_last
        if channels_last:
            self.generator.to(memory_format=torch.channels_last)  # type: ignore[call-overload]
            if self.discriminator is not None:
                self.discriminator.to(memory_format=torch.channels_last)  # type: ignore[call-overload]
        self.val_metrics: MetricCollection | None = metrics() if metrics is not None else None
        self.test_metrics: MetricCollection | None = metrics() if metrics is not None else None
        # In the checkpoint only: the trackers get the whole run config once (brdfgan.tracking).
        self.save_hyperparameters(
            ignore=["generator", "discriminator", "loss", "optimizer", "metrics"], logger=False
        )

    def setup(self, stage: str) -> None:
        # Each DDP rank draws its own rendering-loss configurations.
        self.loss.reseed(int(self.loss.seed) + self.global_rank)

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        return self.generator(photo, flash)

    # -- exact resume ------------------------------------------------------------------------

    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        # Plain types and tensors only: checkpoints are read with torch.load(weights_only=True).
        kind, keys, position, has_gauss, cached = cast(
            tuple[str, np.ndarray, int, int, float], np.random.get_state(legacy=True)
        )
        checkpoint[RNG_STATE_KEY] = {
            "loss": self.loss.rng_state(),
            "python": random.getstate(),
            "numpy": (
                str(kind),
                torch.from_numpy(keys.astype(np.int64)),
                int(position),
                int(has_gauss),
                float(cached),
            ),
            "torch": torch.get_rng_state(),
        }

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        # Runs after setup() (which reseeds the loss), so the stored states win.
        states = checkpoint.get(RNG_STATE_KEY)
        if states is None:  # a checkpoint from before exact resume: continue as it used to
            log.warning("checkpoint has no random-generator states; the resumed run is not exact")
            return
        self.loss.set_rng_state(states["loss"])
        version, internal, gauss = states["python"]
        random.setstate((version, tuple(internal), gauss))
        kind, keys, position, has_gauss, cached = states["numpy"]
        np.random.set_state((kind, keys.numpy().astype(np.uint32), position, has_gauss, cached))
        torch.set_rng_state(states["torch"])

    # -- optimisation ------------------------------------------------------------------------

    def _schedule_steps(self) -> int:
        if self.total_steps is not None:
            return self.total_steps
        trainer = self.trainer
        if trainer.max_steps and trainer.max_steps > 0:
            # max_steps counts optimizer steps: two per batch when a discriminator trains.
            return max(1, trainer.max_steps // (2 if self.uses_discriminator else 1))
        datamodule = getattr(trainer, "datamodule", None)
        per_epoch = getattr(datamodule, "train_batches_per_epoch", None)
        if per_epoch is None or trainer.max_epochs is None or trainer.max_epochs < 0:
            raise UserError("cannot infer the schedule length: set model.total_steps or trainer.max_epochs")
        return max(1, trainer.max_epochs * per_epoch)

    def configure_optimizers(self) -> Any:
        schedule = LinearDecaySchedule(self._schedule_steps(), self.constant_lr_fraction)
        g_opt = self.optimizer_factory(self.generator.parameters())
        optimizers = [g_opt]
        if self.discriminator is not None:
            optimizers.append(self.optimizer_factory(self.discriminator.parameters()))
        schedulers = [{"scheduler": LambdaLR(opt, schedule), "interval": "step"} for opt in optimizers]
        return optimizers, schedulers

    def on_train_start(self) -> None:
        # A resumed run gets its schedulers' state back, including the schedule length they were
        # built with (LambdaLR stores the schedule object's fields). The length follows this
        # run's configuration instead, so a run can be extended or shortened on resume by
        # changing trainer.max_epochs or model.total_steps; an unchanged configuration gives
        # the same schedule, and the current learning rate is recomputed for the step reached.
        schedule = LinearDecaySchedule(self._schedule_steps(), self.constant_lr_fraction)
        for scheduler in self._schedulers():
            if list(scheduler.lr_lambdas) == [schedule] * len(scheduler.lr_lambdas):
                continue
            log.info("learning-rate schedule: %s generator steps (the checkpoint had %s)",
                     schedule.total_steps, getattr(scheduler.lr_lambdas[0], "total_steps", "?"))  # fmt: skip
            scheduler.lr_lambdas = [schedule] * len(scheduler.lr_lambdas)
            for group, base_lr in zip(scheduler.optimizer.param_groups, scheduler.base_lrs, strict=True):
                group["lr"] = base_lr * schedule(scheduler.last_epoch)

    def _schedulers(self) -> list[LambdaLR]:
        """The learning-rate schedulers of configure_optimizers (one per network)."""
        schedulers = self.lr_schedulers()
        found = schedulers if isinstance(schedulers, list) else [schedulers]
        return [scheduler for scheduler in found if isinstance(scheduler, LambdaLR)]

    def _optimizers(self) -> tuple[Any, Any | None]:
        optimizers = self.optimizers()
        if isinstance(optimizers, list):
            return optimizers[0], optimizers[1] if len(optimizers) > 1 else None
        return optimizers, None

    def _step(self, optimizer: Any, loss: Tensor, name: str) -> None:
        optimizer.zero_grad(set_to_none=True)
        with record_function(f"brdfgan/{name}_backward"):
            self.manual_backward(loss)
        with record_function(f"brdfgan/{name}_optimizer"):
            if self.gradient_clip is not None:
                self.clip_gradients(
                    optimizer, gradient_clip_val=self.gradient_clip, gradient_clip_algorithm="norm"
                )
            optimizer.step()

    def _inputs(self, batch: Mapping[str, Any]) -> tuple[Tensor, Tensor]:
        photo, maps = network_photos(batch), batch["maps"]
        if self.channels_last:
            photo = photo.contiguous(memory_format=torch.channels_last)
            maps = maps.contiguous(memory_format=torch.channels_last)
        return photo, maps

    def training_step(self, batch: Mapping[str, Any], batch_idx: int) -> None:
        photo, maps = self._inputs(batch)
        g_opt, d_opt = self._optimizers()
        with record_function("brdfgan/generator_forward"):
            fake = self.generator(photo, batch.get("flash"))
        logged: dict[str, Tensor] = {}

        if self.discriminator is not None and d_opt is not None:
            with self.toggled_optimizer(d_opt):
                with record_function("brdfgan/discriminator_forward"):
                    d_real = self.discriminator(photo, maps)
                    d_fake = self.discriminator(photo, fake.detach())
                    d_terms = self.loss.discriminator_terms(d_real, d_fake)
                self._step(d_opt, d_terms["d_total"], "discriminator")
            logged.update(d_terms)

        with self.toggled_optimizer(g_opt):
            d_fake_g = d_real_g = None
            if self.discriminator is not None:
                with record_function("brdfgan/generator_adversarial_forward"):
                    d_fake_g = self.discriminator(photo, fake)
                    with torch.no_grad():  # the real features are targets for feature matching
                        d_real_g = self.discriminator(photo, maps) if self.loss.switches.feature else None
            g_terms = self.loss.generator_terms(fake, maps, d_fake_g, d_real_g)
            self._step(g_opt, g_terms["g_total"], "generator")
        logged.update(g_terms)

        with record_function("brdfgan/schedule_and_logging"):
            for scheduler in self._schedulers():
                scheduler.step()
            # Tensors, not numbers: Lightning reads them only when it writes a row
            # (log_every_n_steps), so the step itself never waits for the device.
            self.log_dict(
                {f"train/{name}": value.detach() for name, value in logged.items()},
                prog_bar=False,
                on_step=True,
                on_epoch=True,
                batch_size=photo.shape[0],
            )
            self.log("train/g_total_bar", g_terms["g_total"].detach(), prog_bar=True, logger=False)
            self.log("train/lr", g_opt.param_groups[0]["lr"], on_step=True, on_epoch=False)

    def on_train_epoch_end(self) -> None:
        datamodule = getattr(self.trainer, "datamodule", None)
        skipped = getattr(datamodule, "skipped", None)
        if skipped is not None:
            self.log("data/skipped", float(skipped.total), on_epoch=True, on_step=False)

    # -- evaluation --------------------------------------------------------------------------

    def _evaluate(self, batch: Mapping[str, Any], stage: str) -> Tensor:
        photo, maps = self._inputs(batch)
        fake = self.generator(photo, batch.get("flash"))
        terms = parameter_loss(fake, maps)
        configs = self.evaluation_render_configs.expand(photo.shape[0])
        terms["render"] = rendering_loss(fake, maps, configs, self.loss.plane_half_size)
        terms["loss"] = terms["param"] + terms["render"]
        metrics = self.val_metrics if stage == "val" else self.test_metrics
        if metrics is not None:
            meta = batch.get("meta")
            hotspot = None if meta is None else hotspot_centres(meta, *maps.shape[-2:]).to(maps.device)
            metrics.update(fake, maps, hotspot=hotspot, flash=batch.get("flash"), photo=photo)
        self.log_dict(
            {f"{stage}/{name}": value for name, value in terms.items()},
            on_epoch=True,
            on_step=False,
            prog_bar=False,
            batch_size=photo.shape[0],
            sync_dist=True,
        )
        return terms["loss"]

    def _log_metrics(self, stage: str) -> None:
        metrics = self.val_metrics if stage == "val" else self.test_metrics
        if metrics is None:
            return
        values = metrics.compute()
        if values:
            self.log_dict({f"{stage}/{name}": value for name, value in values.items()}, sync_dist=False)
        metrics.reset()

    def on_validation_epoch_end(self) -> None:
        self._log_metrics("val")

    def on_test_epoch_end(self) -> None:
        self._log_metrics("test")

    def validation_step(self, batch: Mapping[str, Any], batch_idx: int) -> Tensor:
        return self._evaluate(batch, "val")

    def test_step(self, batch: Mapping[str, Any], batch_idx: int) -> Tensor:
        return self._evaluate(batch, "test")
