import itertools, torch, numpy as np, cv2
from pathlib import Path
from brdfgan.core.svbrdf import NORMAL, BASECOLOR
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pair.relief_fit import (CONFOUNDS, GUARD_STEPS, VALUE_FLOOR, PairFitConfig, _fit_light, _initial_light, _Level, _working_normals, material_confounds, usable_ratio_mask, sh_basis, flash_shading, SH_TERMS)
from research.pair_fit_table import shard_pairs
config = PairFitConfig()
v4 = load_model(None).generator.eval()
rows = []
for i, pair in enumerate(itertools.islice(shard_pairs(Path("data/pas_pairs"), True, "val"), 20)):
    with torch.no_grad():
        network = v4(pair.flash_only[None], pair.frame)[0]
    usable = usable_ratio_mask(pair.flash_only, pair.room, pair.valid, network, pair.frame, config)
    if usable.mean() < 0.5: continue
    log_ratio = pair.room.clamp_min(VALUE_FLOOR).log() - pair.flash_only.clamp_min(VALUE_FLOOR).log()
    size = 256
    level = _Level.of(log_ratio, usable, pair.frame, size)
    out = []
    for normal in (torch.tensor([0., 0, 1]).view(1, 3, 1, 1).expand(1, 3, size, size).contiguous(), _working_normals(pair.truth[NORMAL], size)):
        light = _fit_light(level, normal, _initial_light(level, torch.zeros(1, 1, size, size)), 300, config)
        with torch.no_grad():
            irr = torch.einsum("ck,bkhw->bchw", light, sh_basis(normal)).clamp_min(1e-4)
            model = irr.log() - flash_shading(normal, level.frame).log()
        out.append(model)
        print(i, "light", [round(float(v), 3) for v in light[1]])
    lum = lambda t: t[0].mean(0).numpy()
    lr = lum(level.log_ratio)
    tiles = [lr, lum(out[1]), lr - lum(out[1]), lr - lum(out[0])]
    lo, hi = np.percentile(lr, 2), np.percentile(lr, 98)
    img = [np.clip((t - (lo if k < 2 else -(hi - lo) / 2)) / (hi - lo), 0, 1) for k, t in enumerate(tiles)]
    photo = pair.flash_only.permute(1, 2, 0).numpy() ** (1 / 2.2)
    room = (pair.room / pair.room.max()).permute(1, 2, 0).numpy() ** (1 / 2.2)
    row = np.concatenate([photo, room] + [np.repeat(t[..., None], 3, 2) for t in img], 1)
    rows.append(row)
    if len(rows) == 4: break
cv2.imwrite("/tmp/look.png", (np.concatenate(rows, 0)[..., ::-1] * 255).astype(np.uint8)[::2, ::2])
