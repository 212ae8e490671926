"""The training platform: config groups compose, the GAN step, the schedule, resume, train.py."""

from __future__ import annotations

import csv
import math
import re
import warnings
from pathlib import Path

import hydra
import lightning as L
import pytest
import torch
from hydra.errors import ConfigCompositionException
from omegaconf import DictConfig
from safetensors.torch import save_file
from torch import nn

from brdfgan.config_check import ConfigValueError
from brdfgan.training.run import TrainConfigError, build, train, warm_start
from brdfgan.training.schedule import LinearDecaySchedule
from tests.conftest import ROOT, compose_train, random_maps, run_python

CONF = ROOT / "conf"
LOSSES = ["full", "no_adv", "no_feat", "no_param", "no_render"]


@pytest.mark.integration
@pytest.mark.parametrize("loss", LOSSES)
@pytest.mark.parametrize("experiment", ["null", "cpu", "debug", "paper", "procedural"])
def test_every_loss_and_experiment_composes_and_builds(tmp_path: Path, loss: str, experiment: str) -> None:
    chosen = {"null": [], "debug": ["debug=default"]}.get(experiment, [f"experiment={experiment}"])
    cfg = compose_train([f"loss={loss}", *chosen], tmp_path)
    if experiment == "paper":
        assert cfg.trainer.devices == 4 and cfg.trainer.strategy.startswith("ddp")
        assert cfg.trainer.max_epochs == 200 and cfg.data.batch_size == 8
        assert cfg.data.epoch_samples // (4 * 8) == 5000  # 5000 steps per epoch on 4 GPUs
        assert cfg.model.generator.width == 64 and cfg.model.generator.residual_blocks == 9
        assert cfg.model.optimizer.lr == 2e-4 and list(cfg.model.optimizer.betas) == [0.5, 0.999]
        return  # building needs 4 GPUs
    if experiment == "procedural":
        # 128² crops of the 256² procedural dataset (the v3 recipe: many materials, phone-like
        # captures, sensor effects on), validated on whole photos.
        assert cfg.data.train_crop == 128 and cfg.data.data_dir.endswith("/procedural")
        spec = cfg.data.prepare.spec
        assert spec.materials >= 1000 and spec.resolution == 256 and not spec.families
        assert spec.mixing.fraction > 0 and spec.recolor.probability > 0 and spec.capture.tilt_max_deg > 0
        assert cfg.data.sensor.enabled
        # v3: cross-entropy metallic term and the unit-z normal head, whatever the loss group.
        assert cfg.loss.metallic_loss == "bce" and cfg.model.generator.normal_head == "unit_z"
    _, module, trainer = build(cfg)
    switches = module.loss.switches
    assert switches.adversarial == (loss != "no_adv") and switches.feature == (loss != "no_feat")
    assert switches.parameter == (loss != "no_param") and switches.rendering == (loss != "no_render")
    assert isinstance(trainer, L.Trainer)


@pytest.mark.integration
def test_procedural_finetune_is_stage_one_without_a_discriminator(tmp_path: Path) -> None:
    stage1 = compose_train(["experiment=procedural"], tmp_path)
    stage2 = compose_train(["experiment=procedural_finetune"], tmp_path)
    assert stage2.init_from.endswith("logs/procedural/gan/checkpoints/last.ckpt")
    assert stage2.data == stage1.data and stage2.model.generator == stage1.model.generator
    assert stage2.loss == stage1.loss and not stage1.loss.switches.adversarial  # v3: one supervised stage
    _, module, _ = build(stage2)
    assert module.discriminator is None and module.loss.switches.parameter and module.loss.switches.rendering


@pytest.mark.integration
@pytest.mark.parametrize("group", ["trainer=gpu", "trainer=ddp", "logger=tensorboard", "logger=wandb"])
def test_other_groups_compose(tmp_path: Path, group: str) -> None:
    cfg = compose_train([group], tmp_path)
    assert cfg.trainer._target_ == "lightning.pytorch.Trainer"


@pytest.mark.integration
def test_paper_model_has_the_paper_generator(tmp_path: Path) -> None:
    cfg = compose_train(["model=paper", "loss=no_adv"], tmp_path)
    generator = hydra.utils.instantiate(cfg.model.generator)
    assert abs(sum(p.numel() for p in generator.parameters()) / 1e6 - 45.6) < 0.2


@pytest.mark.integration
def test_wrong_key_or_type_fails_at_composition(tmp_path: Path) -> None:
    with pytest.raises(ConfigCompositionException, match="no_such_key"):
        compose_train(["no_such_key=1"], tmp_path)
    with pytest.raises(ConfigCompositionException, match="seed=abc"):
        compose_train(["seed=abc"], tmp_path)


@pytest.mark.integration
def test_without_adversarial_and_feature_terms_there_is_no_discriminator(tmp_path: Path) -> None:
    cfg = compose_train(["loss=supervised"], tmp_path)
    assert cfg.loss == compose_train(["loss=no_adv", "loss.switches.feature=false"], tmp_path).loss
    _, module, _ = build(cfg)
    assert module.discriminator is None
    assert module.loss.switches.parameter and module.loss.switches.rendering
    assert not any("discriminator" in name for name, _ in module.named_parameters())
    cfg = compose_train(["loss=full"], tmp_path)
    _, module, _ = build(cfg)
    assert module.discriminator is not None


@pytest.mark.integration
def test_validation_loss_renders_every_sample_under_the_same_fixed_lights(tmp_path: Path) -> None:
    # val/loss is a per-sample quantity: the batch's value is the mean of its samples' values,
    # whatever the batch size or position, and the same on every call.
    _, module, _ = build(compose_train(["debug=default", "loss=supervised", "loss.compile=false"], tmp_path))
    module.eval()
    torch.manual_seed(0)
    photos, maps = torch.rand(3, 3, 32, 32), random_maps(32, 32, batch=(3,))

    def val_loss(index: list[int]) -> float:
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # self.log outside a Trainer
            return float(module.validation_step({"photo": photos[index], "maps": maps[index]}, 7))

    each = [val_loss([i]) for i in range(3)]
    assert val_loss([0, 1, 2]) == pytest.approx(sum(each) / 3, rel=1e-5)
    assert val_loss([2, 0]) == pytest.approx((each[2] + each[0]) / 2, rel=1e-5)
    assert len(set(each)) == 3  # the samples differ, so the check above can fail


def test_linear_decay_schedule() -> None:
    schedule = LinearDecaySchedule(total_steps=10, constant_fraction=0.5)
    assert [schedule(s) for s in range(11)] == pytest.approx([1, 1, 1, 1, 1, 1.0, 0.8, 0.6, 0.4, 0.2, 0.0])
    with pytest.raises(ValueError):
        LinearDecaySchedule(0)


def _state_dict_file(module: L.LightningModule, path: Path) -> Path:
    torch.save({"state_dict": module.state_dict(), "global_step": 123}, path)
    return path


def _same(a: nn.Module | list[torch.Tensor], b: nn.Module, atol: float = 0.0) -> bool:
    first = list(a.state_dict().values()) if isinstance(a, nn.Module) else a
    return all(torch.allclose(x.float(), y.float(), atol=atol, rtol=0) for x, y in
               zip(first, b.state_dict().values(), strict=True))  # fmt: skip


@pytest.mark.integration
def test_warm_start_takes_the_weights_and_nothing_else(tmp_path: Path) -> None:
    # build() seeds every run with its config's seed: different seeds, different initial weights.
    _, gan, _ = build(compose_train(["loss=full", "seed=1"], tmp_path))
    checkpoint = _state_dict_file(gan, tmp_path / "gan.ckpt")
    content_loss = ["loss=supervised", "seed=2"]
    # A GAN checkpoint into a run without a discriminator: the generator only.
    _, content_only, _ = build(compose_train(content_loss, tmp_path))
    assert not _same(gan.generator, content_only.generator)
    assert warm_start(content_only, checkpoint) == ["generator"]
    assert _same(gan.generator, content_only.generator)
    # Both networks when both sides have one.
    _, other_gan, _ = build(compose_train(["loss=full", "seed=3"], tmp_path))
    assert warm_start(other_gan, checkpoint) == ["generator", "discriminator"]
    assert _same(gan.discriminator, other_gan.discriminator)
    # A safetensors weights file (fp16) holds the generator; the discriminator stays as it was.
    safetensors = tmp_path / "g.safetensors"
    save_file({k: v.half().contiguous() for k, v in gan.generator.state_dict().items()}, str(safetensors))
    _, from_weights, _ = build(compose_train(["loss=no_adv", "seed=4"], tmp_path))
    discriminator = [p.clone() for p in from_weights.discriminator.state_dict().values()]
    assert warm_start(from_weights, safetensors) == ["generator"]
    assert _same(discriminator, from_weights.discriminator)
    assert _same(gan.generator, from_weights.generator, atol=1e-3)


@pytest.mark.integration
def test_warm_start_errors_name_the_file(tmp_path: Path) -> None:
    _, module, _ = build(compose_train(["loss=supervised"], tmp_path))
    _, wider, _ = build(compose_train(["loss=no_adv", "model.generator.width=8"], tmp_path))
    narrow = _state_dict_file(wider, tmp_path / "narrow.ckpt")
    with pytest.raises(TrainConfigError, match=r"init_from: the generator in .*narrow.ckpt does not fit"):
        warm_start(module, narrow)
    junk = tmp_path / "junk.ckpt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(TrainConfigError, match=r"init_from: .*junk.ckpt is not a checkpoint"):
        warm_start(module, junk)
    discriminator_only = tmp_path / "d.ckpt"
    torch.save({"state_dict": {"discriminator.w": torch.zeros(1)}}, discriminator_only)
    with pytest.raises(TrainConfigError, match="holds no generator weights"):
        warm_start(module, discriminator_only)


def _fit(cfg: DictConfig, ckpt_path: str | None = None) -> tuple[L.LightningModule, L.Trainer]:
    L.seed_everything(cfg.seed, workers=True)
    datamodule, module, trainer = build(cfg)
    trainer.fit(module, datamodule=datamodule, ckpt_path=ckpt_path)
    return module, trainer


@pytest.mark.integration
@pytest.mark.mitsuba
@pytest.mark.parametrize("loss", ["full", "no_adv"])
def test_gan_step_counts_and_schedule_follow_generator_steps(tiny_data: Path, loss: str) -> None:
    cfg = compose_train(["debug=default", f"loss={loss}", "logger=csv", "callbacks=none"], tiny_data)
    cfg.loss.switches.feature = loss == "full"
    module, trainer = _fit(cfg)
    batches = trainer.datamodule.train_batches_per_epoch * cfg.trainer.max_epochs
    optimizers_per_batch = 2 if module.discriminator is not None else 1
    assert trainer.global_step == batches * optimizers_per_batch
    # Generator steps drive the lr: at the end it has decayed to 0 whatever global_step says.
    g_opt = trainer.optimizers[0]
    assert g_opt.param_groups[0]["lr"] == pytest.approx(0.0, abs=1e-12)
    logged = trainer.callback_metrics
    assert "train/g_total" in logged and "val/loss" in logged
    assert ("train/d_total" in logged) == (loss == "full")
    assert math.isfinite(float(logged["val/loss"]))


@pytest.mark.integration
@pytest.mark.mitsuba
@pytest.mark.parametrize(("debug", "batches"), [("fdr", 1), ("limit", 3 * 2)])
def test_debug_configs_run_the_loop_on_the_batches_they_name(
    tiny_data: Path, debug: str, batches: int
) -> None:
    # debug=fdr: one batch per stage; debug=limit: 3 epochs of 2 training batches. Two optimizer
    # steps per batch (discriminator and generator).
    module, trainer = _fit(compose_train([f"debug={debug}", "logger=csv"], tiny_data))
    assert trainer.global_step == 2 * batches and module.generator.config()["width"] == 8
    assert math.isfinite(float(trainer.callback_metrics["val/loss"]))


@pytest.mark.integration
def test_debug_overfit_trains_on_a_few_batches_for_many_epochs(tmp_path: Path) -> None:
    trainer = compose_train(["debug=overfit"], tmp_path).trainer
    assert trainer.overfit_batches == 3 and trainer.max_epochs == 20 and trainer.accelerator == "cpu"


@pytest.mark.integration
@pytest.mark.mitsuba
def test_resume_continues_with_the_same_step_count_and_lr(tiny_data: Path, tmp_path: Path) -> None:
    overrides = ["debug=default", "logger=csv", "trainer.max_epochs=3"]
    full = compose_train(overrides, tiny_data)
    full.paths.output_dir = str(tmp_path / "full")
    _, straight = _fit(full)

    first = compose_train([*overrides[:-1], "trainer.max_epochs=1"], tiny_data)
    first.paths.output_dir = str(tmp_path / "interrupted")
    _, first_trainer = _fit(first)
    last = tmp_path / "interrupted" / "checkpoints" / "last.ckpt"
    assert last.is_file()
    # last.ckpt holds the final state, whether or not the last epoch improved the metric.
    assert torch.load(last, weights_only=True)["global_step"] == first_trainer.global_step
    resumed_cfg = compose_train(overrides, tiny_data)
    resumed_cfg.paths.output_dir = str(tmp_path / "interrupted")
    resumed_module, resumed = _fit(resumed_cfg, ckpt_path=str(last))
    assert resumed.global_step == straight.global_step
    for a, b in zip(resumed.optimizers, straight.optimizers, strict=True):
        assert a.param_groups[0]["lr"] == pytest.approx(b.param_groups[0]["lr"])
    # The interrupted run was configured for 1 epoch; resumed with 3, the schedule follows the
    # new length (not the checkpoint's), so every learning rate after the resume point is the
    # straight run's — not 0 from the 1-epoch schedule that had already decayed.
    schedulers = resumed_module.lr_schedulers()
    assert all(s.lr_lambdas[0].total_steps == 3 * resumed.datamodule.train_batches_per_epoch
               for s in (schedulers if isinstance(schedulers, list) else [schedulers]))  # fmt: skip

    def lrs(run: str) -> dict[int, float]:  # every csv of the run: the resumed part is a new version
        rows = [row for path in (tmp_path / run).rglob("metrics.csv") for row in csv.DictReader(path.open())]
        column = next(k for k in rows[0] if k.startswith("lr-"))
        return {int(r["step"]): float(r[column]) for r in rows if r.get(column)}

    straight_lrs, resumed_lrs = lrs("full"), lrs("interrupted")
    after_resume = [step for step in straight_lrs if step >= straight.global_step // 3]
    assert after_resume and any(straight_lrs[step] > 0 for step in after_resume)
    assert [resumed_lrs[step] for step in after_resume] == pytest.approx(
        [straight_lrs[step] for step in after_resume]
    )
    assert list((tmp_path / "interrupted" / "checkpoints").glob("epoch*.ckpt"))


@pytest.mark.integration
@pytest.mark.mitsuba
def test_train_py_runs_the_loop_and_returns_the_metric(tiny_data: Path) -> None:
    result = run_python("train.py", "debug=default", cwd=tiny_data)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = sorted((tiny_data / "logs" / "debug" / "runs").iterdir())
    checkpoints = {p.name for p in (runs[-1] / "checkpoints").iterdir()}
    assert "last.ckpt" in checkpoints and any(name.startswith("epoch") for name in checkpoints)
    assert (runs[-1] / "csv").exists()


@pytest.mark.integration
@pytest.mark.mitsuba
def test_train_py_prints_each_log_line_once_and_not_the_whole_config(tiny_data: Path) -> None:
    # Lightning's own stderr handler used to print every line a second time beside Hydra's console.
    result = run_python("train.py", "debug=fdr", "task_name=once", "seed=3", cwd=tiny_data)
    assert result.returncode == 0, result.stderr[-3000:]
    console = result.stdout + result.stderr
    assert console.count("Seed set to 3") == 1
    assert console.count("Total params") == 1  # the model summary
    assert "run folder: " in console and "_target_:" not in console
    # Lightning's rank-zero lines stay, its cloud-logging advertisement goes.
    assert "GPU available: " in console and "💡" not in console and "litlogger" not in console
    run = sorted((tiny_data / "logs" / "once" / "runs").iterdir())[-1]
    assert "_target_:" in (run / ".hydra" / "config.yaml").read_text()


@pytest.mark.integration
@pytest.mark.parametrize(
    ("overrides", "error", "message"),
    [
        (["ckpt_path=/no.ckpt"], TrainConfigError, "ckpt_path: checkpoint /no.ckpt does not exist"),
        (["init_from=/no.ckpt"], TrainConfigError, "init_from: /no.ckpt does not exist"),
        (["init_from={tmp}/a.ckpt", "ckpt_path={tmp}/b.ckpt"], TrainConfigError, "set one"),
        (["+model.generator.no_such_arg=1"], ConfigValueError, "model.generator.no_such_arg: not a"),
    ],
)
def test_bad_run_input_is_a_user_error_before_any_work(
    tmp_path: Path, overrides: list[str], error: type[Exception], message: str
) -> None:
    for name in ("a.ckpt", "b.ckpt"):
        (tmp_path / name).write_bytes(b"")
    cfg = compose_train(["debug=default", *(o.format(tmp=tmp_path) for o in overrides)], tmp_path)
    with pytest.raises(error, match=re.escape(message)):
        train(cfg)
    assert not (tmp_path / "data").exists()  # nothing was prepared


@pytest.mark.integration
def test_train_py_reports_a_user_error_in_one_line(tmp_path: Path) -> None:
    # The command-line property the in-process cases above rely on: one line, exit 2, no traceback.
    result = run_python("train.py", "debug=default", "ckpt_path=/nonexistent.ckpt", cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-2000:]
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert lines == ["error: ckpt_path: checkpoint /nonexistent.ckpt does not exist"], result.stderr[-2000:]


@pytest.mark.integration
def test_ablation_sweep_config_lists_the_grid(tmp_path: Path) -> None:
    result = run_python("train.py", "--config-dir", str(ROOT / "sweeps"), "--config-name", "ablation",
                        "--cfg", "hydra", cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    assert "loss: full,no_adv,no_feat,no_param,no_render" in result.stdout
    assert "seed: 0,1,2" in result.stdout
    torch.manual_seed(0)  # keep the random state of later tests independent of this one


@pytest.mark.integration
@pytest.mark.mitsuba
@pytest.mark.slow  # 13-18 s: kept out of make test's 6 minutes (make test-slow runs it)
def test_ddp_on_two_cpu_processes_trains_and_tests(tiny_data: Path) -> None:
    # The paper trains with DDP; two gloo processes on the CPU exercise the same code path:
    # per-rank shard splitting, both networks in one module, toggled optimizers.
    result = run_python("train.py",
        "debug=default", "trainer.devices=2", "+trainer.strategy=ddp_find_unused_parameters_true",
        "task_name=ddp", cwd=tiny_data,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    runs = sorted((tiny_data / "logs" / "ddp" / "runs").iterdir())
    assert (runs[-1] / "checkpoints" / "last.ckpt").is_file()
    assert "test/loss" in result.stdout + result.stderr


@pytest.mark.integration
def test_seed_reaches_the_data_order_and_trainer_switches_need_no_plus(tmp_path: Path) -> None:
    overrides = ["debug=default", "seed=2", "trainer.limit_train_batches=3", "trainer.fast_dev_run=true"]
    cfg = compose_train(overrides, tmp_path)
    assert cfg.data.seed == 2 and cfg.loss.seed == 2
    assert cfg.trainer.limit_train_batches == 3 and cfg.trainer.fast_dev_run is True
    assert compose_train(["debug=default"], tmp_path).data.seed == 0
    trainer = hydra.utils.instantiate(cfg.trainer)  # every listed key is a real Trainer argument
    assert trainer.fast_dev_run is True
    # The switches users type, each without `+`; a misspelt one still fails at composition.
    typed = {"limit_val_batches": 2, "limit_test_batches": 1, "max_steps": 7, "val_check_interval": 0.5,
             "check_val_every_n_epoch": 2, "log_every_n_steps": 3, "precision": "bf16-mixed", "devices": 1,
             "accelerator": "cpu"}  # fmt: skip
    switched = compose_train(["debug=default", *(f"trainer.{k}={v}" for k, v in typed.items())], tmp_path)
    assert {key: switched.trainer[key] for key in typed} == typed
    with pytest.raises(ConfigCompositionException):
        compose_train(["debug=default", "trainer.limit_train_batchs=3"], tmp_path)
