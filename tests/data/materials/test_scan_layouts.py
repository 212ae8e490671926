"""brdfgan.data.materials.scanned: material sets in the brdfgan, ambientCG, Poly Haven and MatSynth layouts.

Every set here is written with Pillow (not our own writer), so the reader is checked against files
as a library ships them: the values expected are the files' own pixel values.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from brdfgan.data.materials.scanned import (
    ARM_CHANNELS,
    ScanSet,
    detect_material_set,
    find_material_sets,
    read_material_set,
    read_scanned_material,
    scanned_material_folders,
)
from brdfgan.data.storage.spec_checks import DatasetConfigError
from tests.conftest import SHARED

SCANS = SHARED / "scans"
SIDE = 16


@dataclass
class Truth:
    """The pixel values of a set's files: uint8 (or uint16 roughness), ``(H, W[, 3])``."""

    base: np.ndarray
    normal: np.ndarray  # OpenGL, (n + 1) / 2
    rough: np.ndarray
    metal: np.ndarray | None

    def maps(self) -> torch.Tensor:
        """What the reader must return. Shape: ``(8, H, W)``."""

        def unit(a: np.ndarray) -> torch.Tensor:
            scale = 65535.0 if a.dtype == np.uint16 else 255.0
            return torch.from_numpy(a.astype(np.float64) / scale)

        n = unit(self.normal).permute(2, 0, 1) * 2 - 1
        metal = unit(self.metal)[None] if self.metal is not None else torch.zeros(1, *self.rough.shape)
        return torch.cat(
            [unit(self.base).permute(2, 0, 1), n / n.norm(dim=0), unit(self.rough)[None], metal]
        ).float()


def truth(seed: int, *, side: int = SIDE, smooth: bool = False, metal: bool = True) -> Truth:
    """Random maps (``smooth`` ones survive JPEG coding); normals tilted up to ~30°, not symmetric."""
    rng = np.random.default_rng(seed)
    v, u = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side), indexing="ij")
    if smooth:
        base = np.stack([60 + 120 * u, 90 + 60 * v, 140 - 50 * u * v], axis=-1)
        xy = np.stack([0.3 * np.sin(3 * u + 1), 0.2 * np.cos(2 * v) + 0.1], axis=-1)
        rough, metallic = 40 + 150 * v, 200 * u
    else:
        base = rng.integers(0, 256, (side, side, 3))
        xy = rng.uniform(-0.35, 0.35, (side, side, 2)) + np.array([0.0, 0.1])
        rough, metallic = rng.integers(0, 256, (side, side)), rng.integers(0, 256, (side, side))
    n = np.concatenate([xy, np.sqrt(1 - (xy**2).sum(-1, keepdims=True))], axis=-1)

    def u8(a: np.ndarray) -> np.ndarray:
        return np.clip(np.round(a), 0, 255).astype(np.uint8)

    return Truth(u8(base), u8((n + 1) / 2 * 255), u8(rough), u8(metallic) if metal else None)


def save(path: Path, array: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    options = {"quality": 95, "subsampling": 0} if path.suffix.lower() in (".jpg", ".jpeg") else {}
    Image.fromarray(array).save(path, **options)
    return path


def dx(normal: np.ndarray) -> np.ndarray:
    """The DirectX file of an OpenGL normal file: green inverted."""
    flipped = normal.copy()
    flipped[..., 1] = 255 - flipped[..., 1]
    return flipped


def write_set(folder: Path, names: dict[str, str], t: Truth) -> Path:
    """Write ``t`` under the file names ``names`` (keys base, normal, rough, metal; normal_dx writes
    the DirectX file)."""
    arrays = {
        "base": t.base,
        "normal": t.normal,
        "normal_dx": dx(t.normal),
        "rough": t.rough,
        "metal": t.metal,
    }
    for key, name in names.items():
        array = arrays[key]
        assert array is not None
        save(folder / name, array)
    return folder


def brdfgan_set(folder: Path, t: Truth) -> Path:
    names = {"base": "albedo.png", "normal": "normal.png", "rough": "roughness.png"}
    return write_set(folder, names | ({"metal": "metallic.png"} if t.metal is not None else {}), t)


def matsynth_set(folder: Path, t: Truth) -> Path:
    names = {"base": "basecolor.png", "normal": "normal.png", "rough": "roughness.png"}
    return write_set(folder, names | ({"metal": "metallic.png"} if t.metal is not None else {}), t)


def ambientcg_set(folder: Path, t: Truth, *, normal: str = "NormalGL", ext: str = "jpg") -> Path:
    tag = f"Bricks075A_1K-{ext.upper()}"
    names = {
        "base": f"{tag}_Color.{ext}",
        "normal" if normal == "NormalGL" else "normal_dx": f"{tag}_{normal}.{ext}",
        "rough": f"{tag}_Roughness.{ext}",
    }
    write_set(folder, names | ({"metal": f"{tag}_Metalness.{ext}"} if t.metal is not None else {}), t)
    save(folder / f"{tag}_Displacement.{ext}", t.rough)  # ignored
    save(folder / "Bricks075A.png", t.base)  # the preview: ignored
    return folder


def polyhaven_set(folder: Path, t: Truth, *, separate_roughness: bool = False) -> Path:
    """A Poly Haven set with DirectX normals whose roughness and metallic come from the ARM file
    (G, B), or roughness from its own file."""
    assert t.metal is not None
    arm = np.stack([np.full_like(t.rough, 200), t.rough, t.metal], axis=-1)
    if separate_roughness:  # the ARM's G then must not be used
        arm[..., ARM_CHANNELS["roughness"]] = 255 - t.rough
    write_set(folder, {"base": "rusty_metal_02_diff_1k.png", "normal_dx": "rusty_metal_02_nor_dx_1k.png"}, t)
    save(folder / "rusty_metal_02_arm_1k.png", arm)
    if separate_roughness:
        save(folder / "rusty_metal_02_rough_1k.png", t.rough)
    return folder


# --- each layout read to the files' values --------------------------------------------------------


@pytest.mark.parametrize("layout", ["brdfgan", "matsynth"])
def test_named_file_layouts_read_exactly(tmp_path: Path, layout: str) -> None:
    t = truth(1)
    folder = (brdfgan_set if layout == "brdfgan" else matsynth_set)(tmp_path / "set", t)
    scan = detect_material_set(folder)
    assert scan is not None and scan.layout == layout and scan.normal_convention == "opengl"
    torch.testing.assert_close(read_material_set(scan), t.maps(), atol=1e-6, rtol=0)
    assert read_scanned_material(folder, 8).shape == (8, 8, 8)


def test_ambientcg_jpeg_set_reads_within_jpeg_tolerance(tmp_path: Path) -> None:
    t = truth(2, smooth=True)
    folder = ambientcg_set(tmp_path / "Bricks075A_1K-JPG", t)
    save(folder / "._Bricks075A_1K-JPG_Color.jpg", t.base)  # macOS resource fork junk: hidden, ignored
    scan = detect_material_set(folder)
    assert scan is not None and scan.layout == "ambientcg"
    assert scan.basecolor.name == "Bricks075A_1K-JPG_Color.jpg" and scan.metallic is not None
    got, want = read_material_set(scan), t.maps()
    assert got.shape == (8, SIDE, SIDE)
    torch.testing.assert_close(got[0:3], want[0:3], atol=3 / 255, rtol=0)
    torch.testing.assert_close(got[3:6], want[3:6], atol=0.03, rtol=0)
    torch.testing.assert_close(got[6:8], want[6:8], atol=3 / 255, rtol=0)


def test_directx_normals_are_flipped_to_opengl(tmp_path: Path) -> None:
    t = truth(3, metal=False)
    gl = detect_material_set(ambientcg_set(tmp_path / "gl", t, ext="png"))
    dx_set = detect_material_set(ambientcg_set(tmp_path / "dx", t, normal="NormalDX", ext="png"))
    assert gl is not None and dx_set is not None
    assert (gl.normal_convention, dx_set.normal_convention) == ("opengl", "directx")
    gl_maps, dx_maps = read_material_set(gl), read_material_set(dx_set)
    assert gl_maps[4].mean() > 0.05  # tilted towards +Y, as written
    torch.testing.assert_close(dx_maps, gl_maps, atol=1e-6, rtol=0)
    torch.testing.assert_close(gl_maps, t.maps(), atol=1e-6, rtol=0)
    assert torch.all(gl_maps[7] == 0)  # no Metalness file: dielectric


def test_both_normals_present_prefers_opengl(tmp_path: Path) -> None:
    t = truth(4)
    folder = ambientcg_set(tmp_path / "set", t, ext="png")
    save(folder / "Bricks075A_1K-PNG_NormalDX.png", np.zeros_like(t.normal))  # would be rejected
    scan = detect_material_set(folder)
    assert scan is not None and scan.normal.name.endswith("NormalGL.png")
    torch.testing.assert_close(read_material_set(scan), t.maps(), atol=1e-6, rtol=0)


@pytest.mark.parametrize("separate_roughness", [False, True])
def test_polyhaven_roughness_and_metallic_come_from_arm(tmp_path: Path, separate_roughness: bool) -> None:
    t = truth(5)
    scan = detect_material_set(
        polyhaven_set(tmp_path / "rusty_metal_02", t, separate_roughness=separate_roughness)
    )
    assert scan is not None and scan.layout == "polyhaven" and scan.normal_convention == "directx"
    assert scan.metallic is not None and scan.metallic.name == "rusty_metal_02_arm_1k.png"
    assert scan.metallic_channel == 2 and scan.roughness_channel == (None if separate_roughness else 1)
    torch.testing.assert_close(read_material_set(scan), t.maps(), atol=1e-6, rtol=0)


def test_sixteen_bit_png_reads_at_full_precision(tmp_path: Path) -> None:
    t = truth(6, metal=False)
    t.rough = (np.arange(SIDE * SIDE, dtype=np.uint16).reshape(SIDE, SIDE) * 250 + 7).astype(np.uint16)
    folder = matsynth_set(tmp_path / "m", t)
    assert Image.open(folder / "roughness.png").mode.startswith("I")  # really a 16-bit file
    maps = read_scanned_material(folder, SIDE)
    torch.testing.assert_close(maps[6].double(), torch.from_numpy(t.rough / 65535.0), atol=1e-7, rtol=0)
    assert torch.all(maps[7] == 0)  # MatSynth without metallic.png


# --- folders of sets ------------------------------------------------------------------------------


def mixed_root(root: Path) -> dict[str, Truth]:
    truths = {name: truth(10 + i) for i, name in enumerate(["d_ours", "c_ambient", "b_poly", "a_matsynth"])}
    brdfgan_set(root / "d_ours", truths["d_ours"])
    ambientcg_set(root / "c_ambient", truths["c_ambient"], normal="NormalDX", ext="png")
    polyhaven_set(root / "b_poly", truths["b_poly"])
    matsynth_set(root / "a_matsynth", truths["a_matsynth"])
    (root / "notes").mkdir()  # no map files: not a set
    (root / "README.md").write_text("scans")
    return truths


def test_mixed_layouts_in_one_root_sorted_by_name(tmp_path: Path) -> None:
    truths = mixed_root(tmp_path)
    sets, skipped = find_material_sets(tmp_path)
    assert not skipped
    assert [(s.name, s.layout) for s in sets] == [
        ("a_matsynth", "matsynth"),
        ("b_poly", "polyhaven"),
        ("c_ambient", "ambientcg"),
        ("d_ours", "brdfgan"),
    ]
    assert scanned_material_folders(tmp_path) == tuple(s.folder for s in sets)
    for scan in sets:
        torch.testing.assert_close(read_material_set(scan), truths[scan.name].maps(), atol=1e-6, rtol=0)
        assert read_scanned_material(scan.folder, 8).shape == (8, 8, 8)


def test_a_folder_holding_one_set_is_that_set(tmp_path: Path) -> None:
    folder = ambientcg_set(tmp_path / "Bricks075A_1K-JPG", truth(7, smooth=True))
    sets, _ = find_material_sets(folder)
    assert [s.folder for s in sets] == [folder]
    brdfgan_set(folder / "inner", truth(8))
    with pytest.raises(
        DatasetConfigError, match=r"holds map files itself and material sets in sub-folders \(inner\)"
    ):
        find_material_sets(folder)


def one_line(error: pytest.ExceptionInfo[DatasetConfigError]) -> str:
    message = str(error.value)
    assert "\n" not in message
    return message


def test_incomplete_set_is_an_error_or_skipped(tmp_path: Path) -> None:
    mixed_root(tmp_path)
    t = truth(9)
    write_set(
        tmp_path / "e_broken", {"base": "Rock_2K-JPG_Color.jpg", "rough": "Rock_2K-JPG_Roughness.jpg"}, t
    )
    with pytest.raises(DatasetConfigError) as error:
        find_material_sets(tmp_path)
    message = one_line(error)
    assert "e_broken" in message and "no normal map" in message and "NormalGL" in message
    with pytest.raises(DatasetConfigError, match=r"e_broken.*no normal map"):
        scanned_material_folders(tmp_path)
    sets, skipped = find_material_sets(tmp_path, skip_incomplete=True)
    assert [s.name for s in sets] == ["a_matsynth", "b_poly", "c_ambient", "d_ours"]
    assert [(folder.name, "no normal map" in why) for folder, why in skipped] == [("e_broken", True)]
    assert len(scanned_material_folders(tmp_path, skip_incomplete=True)) == 4
    with pytest.raises(DatasetConfigError, match=r"e_broken.*no normal map"):
        read_scanned_material(tmp_path / "e_broken", 8)


def test_set_without_base_colour_or_with_two_candidates(tmp_path: Path) -> None:
    t = truth(11)
    write_set(tmp_path / "a", {"normal": "normal.png", "rough": "roughness.png"}, t)
    with pytest.raises(DatasetConfigError) as error:
        find_material_sets(tmp_path)
    assert "a: incomplete material set: no base colour map" in one_line(error)
    ambientcg_set(tmp_path / "b", t, ext="png")
    save(tmp_path / "b" / "Bricks075A_2K-PNG_Color.png", t.base)
    with pytest.raises(DatasetConfigError, match=r"b: several basecolor files \(Bricks075A_1K"):
        detect_material_set(tmp_path / "b")


def test_empty_or_missing_root(tmp_path: Path) -> None:
    with pytest.raises(DatasetConfigError, match="folder of scanned materials not found"):
        find_material_sets(tmp_path / "nowhere")
    (tmp_path / "empty" / "sub").mkdir(parents=True)
    with pytest.raises(DatasetConfigError, match="no material sets"):
        scanned_material_folders(tmp_path / "empty", key="--scanned")


# --- unreadable files and sizes -------------------------------------------------------------------


def test_corrupt_file_is_named(tmp_path: Path) -> None:
    folder = brdfgan_set(tmp_path / "s", truth(12))
    (folder / "normal.png").write_bytes(b"not a png at all")
    scan = detect_material_set(folder)
    assert scan is not None  # names only: the file is opened when read
    with pytest.raises(DatasetConfigError) as error:
        read_material_set(scan)
    assert "normal.png: corrupt or unreadable image" in one_line(error)


def test_mismatched_and_non_square_sizes_name_the_file(tmp_path: Path) -> None:
    t = truth(13)
    folder = brdfgan_set(tmp_path / "mismatch", t)
    save(folder / "roughness.png", t.rough[:8, :8])
    with pytest.raises(DatasetConfigError) as error:
        read_scanned_material(folder, 8)
    assert "roughness.png: size 8x8" in one_line(error)

    wide = Truth(t.base[:8], t.normal[:8], t.rough[:8], t.metal[:8] if t.metal is not None else None)
    folder = polyhaven_set(tmp_path / "wide", wide)
    with pytest.raises(DatasetConfigError) as error:
        read_scanned_material(folder, 8)
    assert "rusty_metal_02_diff_1k.png: maps are 16x8 (WxH), expected square" in one_line(error)


def test_scan_set_is_frozen_and_lists_its_files(tmp_path: Path) -> None:
    scan = detect_material_set(brdfgan_set(tmp_path / "s", truth(14, metal=False)))
    assert isinstance(scan, ScanSet)
    assert scan.files == {
        "basecolor": tmp_path / "s" / "albedo.png",
        "normal": tmp_path / "s" / "normal.png",
        "roughness": tmp_path / "s" / "roughness.png",
        "metallic": None,
    }
    with pytest.raises(AttributeError):
        scan.layout = "matsynth"  # type: ignore[misc]


# --- the real scans -------------------------------------------------------------------------------


@pytest.mark.skipif(not SCANS.is_dir(), reason="the scanned materials (../shared/scans) are not here")
def test_real_scans_are_found_and_two_read() -> None:
    sets, skipped = find_material_sets(SCANS)
    assert not skipped and all(s.layout == "brdfgan" for s in sets)
    manifest = json.loads((SCANS / "manifest.json").read_text())
    assert [s.name for s in sets] == sorted(manifest["materials"])
    metal = next(s for s in sets if s.name.startswith("Metal"))  # bare metal (some sets are ~0)
    assert metal.metallic is not None
    for scan in (sets[0], metal):
        maps = read_material_set(scan, 64)
        assert maps.shape == (8, 64, 64) and torch.isfinite(maps).all()
        assert torch.allclose(maps[3:6].norm(dim=0), torch.ones(64, 64), atol=1e-4) and maps[5].min() >= 0
        assert maps[0:3].std() > 0.01  # a real texture
    native = read_material_set(sets[0])
    with Image.open(sets[0].basecolor) as image:  # another decoder: libjpeg versions differ by a level
        pillow = torch.from_numpy(np.asarray(image.convert("RGB"), dtype=np.float32) / 255).permute(2, 0, 1)
    assert native.shape[1:] == pillow.shape[1:] and native.shape[1] == native.shape[2]
    assert (native[0:3] - pillow).abs().mean() < 1 / 255
    assert torch.equal(read_scanned_material(metal.folder, 64), read_material_set(metal, 64))
    assert read_material_set(metal, 64)[7].mean() > 0.5
