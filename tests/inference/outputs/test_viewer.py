"""The material viewer page (index.html): self-contained, with and without the vendored three.js,
and rendered by headless Chromium from a file:// URL (skipped without Chromium or the bundle)."""

from __future__ import annotations

import base64
import json
import logging
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from brdfgan.core.svbrdf import flat_maps
from brdfgan.inference.outputs.export import ExportOptions, write_material
from brdfgan.inference.outputs.viewer import MAX_TEXTURE_SIDE, TEXTURE_MAPS, THREE_BUNDLE, write_viewer
from brdfgan.io.images import write_image
from tests.conftest import random_maps, tilted_plane

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
# Headless WebGL here is SwiftShader through ANGLE: --use-gl=swiftshader gives no WebGL context.
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
    "--disable-quic", "--no-first-run", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--hide-scrollbars", "--enable-logging=stderr", "--v=0",
)  # fmt: skip
BACKGROUND = np.array([0x20, 0x22, 0x25])  # the 3D view's clear colour (scene.background)
needs_browser = pytest.mark.skipif(
    CHROMIUM is None or not THREE_BUNDLE.is_file(),
    reason="needs Debian's chromium and the vendored three.js (make setup: scripts/install_chromium.sh, "
    "scripts/vendor_three.sh)",
)
FAKE_BUNDLE = "/* brdfgan viewer: three@0.187.0 (test stand-in) */\nvar THREE = {REVISION: '187'};\n"


def _material(
    root: Path, maps: torch.Tensor, options: ExportOptions | None = None, bundle: Path | None = None
) -> Path:
    """``root/mat`` written by write_material with the page as an extra file, the way the pipeline
    adds it (inside the staging folder, after the textures and material.glb)."""
    options = options or ExportOptions()
    metadata = {"name": "mat", "model": {"id": "test-model"}, "warnings": ["a <warning>"]}

    def page(target: Path) -> Path:
        return write_viewer(target, metadata=metadata, options=options, bundle=bundle)

    return write_material(root / "mat", maps, options, metadata, extra_files={"index.html": page})


def _embedded(page: str) -> dict[str, np.ndarray]:
    """The gallery's embedded maps, decoded, by map name."""
    images = {}
    for key, data in re.findall(r'data-map="([^"]+)"[^>]*src="data:image/png;base64,([^"]+)"', page):
        buffer = np.frombuffer(base64.b64decode(data), np.uint8)
        images[key] = cv2.imdecode(buffer, cv2.IMREAD_UNCHANGED)
    return images


def test_page_without_bundle_shows_the_maps_and_says_make_setup(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    missing = tmp_path / "no" / "three.bundle.js"
    with caplog.at_level(logging.WARNING, logger="brdfgan.inference.outputs.viewer"):
        folder = _material(tmp_path, random_maps(24, 32), bundle=missing)
        again = write_viewer(
            tmp_path / "again.html", files={"basecolor": folder / "basecolor.png"}, bundle=missing
        )
    page = (folder / "index.html").read_text()
    assert "make setup" in page and 'data-viewer="no-3d"' in page
    assert "<script" not in page  # nothing to run, nothing loaded
    assert set(_embedded(page)) == set(TEXTURE_MAPS)
    assert "a &lt;warning&gt;" in page and "test-model" in page
    assert "make setup" in again.read_text()
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING and "make setup" in r.getMessage()]
    assert len(warnings) == 1, "the missing bundle is reported once"
    table = json.loads((folder / "material.json").read_text())["files"]
    assert "index.html" in table  # part of the same atomic folder


def test_page_is_self_contained_with_prefixed_files_and_directx_normals(tmp_path: Path) -> None:
    bundle = tmp_path / "three.bundle.js"
    bundle.write_text(FAKE_BUNDLE + 'var s = "</script>";\n')
    options = ExportOptions(file_prefix="mat_", normal_convention="directx", bit_depth=16)
    folder = _material(tmp_path, random_maps(20, 28, seed=3), options, bundle=bundle)
    page = (folder / "index.html").read_text()
    images = _embedded(page)
    assert set(images) == set(TEXTURE_MAPS)
    assert all(image.dtype == np.uint8 and image.shape[:2] == (20, 28) for image in images.values())
    assert 'href="mat_basecolor.png"' in page
    assert '"normalY": -1' in page  # DirectX green flipped in the 3D view, not in the file
    assert "var THREE = {REVISION: '187'}" in page and "<\\/script>" in page  # inlined, and escaped
    assert page.count("</script>") == 3  # the bundle, the config, the page's own module
    # Nothing the page loads from elsewhere: only data: URIs and links (href) to the files beside it.
    assert not re.search(r'src="(?!data:)', page)
    assert "http://" not in page.split("<script>")[0] and "https://" not in page.split("<script>")[0]
    assert 'data-viewer="loading"' in page


def test_large_and_float_maps_are_downscaled_and_encoded_for_the_page(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    big = tmp_path / "basecolor.png"
    write_image(big, rng.random((700, 1300, 3), dtype=np.float32), bit_depth=8)
    height = tmp_path / "height.exr"
    write_image(height, (rng.random((40, 40, 1), dtype=np.float32) - 0.5) * 1e-3)
    page = write_viewer(
        tmp_path / "index.html", files={"basecolor": big, "height": height}, bundle=tmp_path / "none.js"
    ).read_text()
    images = _embedded(page)
    assert images["basecolor"].shape == (round(700 * MAX_TEXTURE_SIDE / 1300), MAX_TEXTURE_SIDE, 3)
    assert images["height"].dtype == np.uint8 and images["height"].shape == (40, 40)
    assert images["height"].min() < 20 and images["height"].max() > 235  # a raw EXR height, normalised


# ------------------------------------------------------------------------------------------ Chromium


def _chromium(page: Path, work: Path, fragment: str = "") -> tuple[dict[str, str], np.ndarray, str]:
    """Open ``page`` from file:// in headless Chromium: the <html> element's attributes once the
    scripts have run, the screenshot (RGB) and the log.

    Virtual time does not wait for work off the page's thread (the textures' ``image.decode()``),
    so on a busy machine the budget can run out with the page still ``loading`` (seen once in CI);
    such a run is repeated with a longer budget. A page that reports ``error`` is returned at once.
    """
    shot = work / "shot.png"
    for budget_ms in (10_000, 40_000, 120_000):
        result = subprocess.run(
            [CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={work / 'profile'}", "--window-size=1000,800",
             f"--virtual-time-budget={budget_ms}", f"--screenshot={shot}", "--dump-dom",
             page.as_uri() + fragment],
            capture_output=True, text=True, timeout=300, check=False,
        )  # fmt: skip
        assert result.returncode == 0, result.stderr[-2000:]
        tag = re.search(r"<html([^>]*)>", result.stdout)
        assert tag is not None, result.stdout[:500]
        attributes = dict(re.findall(r'([\w-]+)="([^"]*)"', tag[1]))
        if attributes.get("data-viewer") != "loading":
            break
    image = cv2.cvtColor(cv2.imread(str(shot), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    return attributes, image, result.stderr


def _console(log: str) -> list[str]:
    """The page's console messages and uncaught errors (Chromium logs every level as INFO:CONSOLE);
    SwiftShader's own performance notes are not the page's."""
    return [
        line
        for line in log.splitlines()
        if (":CONSOLE" in line or "Uncaught" in line) and "GL Driver Message" not in line
    ]


def _canvas(attributes: dict[str, str], image: np.ndarray) -> np.ndarray:
    left, top, width, height = (int(v) for v in attributes["data-canvas-rect"].split(","))
    assert width > 300 and height > 200
    return image[top : top + height, left : left + width].astype(np.float64)


def _plane_pixels(canvas: np.ndarray) -> np.ndarray:
    """Pixels of the canvas that are not the background: the material."""
    return canvas[np.abs(canvas - BACKGROUND).max(axis=-1) > 12]


@pytest.mark.integration
@needs_browser
def test_chromium_renders_the_material_from_file_url(tmp_path: Path) -> None:
    folder = _material(tmp_path, random_maps(64, 64, seed=1))
    attributes, image, log = _chromium(folder / "index.html", tmp_path, "#tiling=3")
    assert _console(log) == []
    assert attributes.get("data-viewer") == "rendered", attributes
    assert attributes["data-three"] == "187" and attributes["data-renderer"]
    canvas = _canvas(attributes, image)
    plane = _plane_pixels(canvas)
    assert len(plane) > 0.15 * canvas.shape[0] * canvas.shape[1], "the plane fills a good part of the view"
    assert plane.std(axis=0).mean() > 10, "random maps look textured, not flat"
    mean = np.array([float(v) for v in attributes["data-mean-rgb"].split(",")])
    assert np.abs(mean - BACKGROUND).max() > 8  # the page's own read-back saw more than the background


@pytest.mark.integration
@needs_browser
def test_chromium_shows_the_base_colour_and_light_from_the_normals_side(tmp_path: Path) -> None:
    # Red, with every normal tilted towards the texture's top (+Y, OpenGL): lit from the top
    # (azimuth 90°) it must be brighter than lit from the bottom (270°), which checks the chain
    # normal.png → three's normalMap → the page's light azimuth.
    maps = tilted_plane(32, normal=(0.0, 0.6, 0.8))
    maps[0:3] = torch.tensor([0.85, 0.04, 0.03]).view(3, 1, 1)
    folder = _material(tmp_path, maps)
    brightness = {}
    for azimuth in (90, 270):
        work = tmp_path / f"azimuth{azimuth}"
        work.mkdir()
        fragment = f"#azimuth={azimuth}&elevation=30&environment=0&intensity=3"
        attributes, image, log = _chromium(folder / "index.html", work, fragment)
        assert _console(log) == []
        assert attributes.get("data-viewer") == "rendered", attributes
        plane = _plane_pixels(_canvas(attributes, image))
        red, green, blue = plane.mean(axis=0)
        assert red > 2 * green and red > 2 * blue, (red, green, blue)
        brightness[azimuth] = red
    assert brightness[90] > 1.3 * brightness[270], brightness


def test_flat_material_page_names_every_file_from_material_json(tmp_path: Path) -> None:
    maps = flat_maps(16, 16, basecolor=(0.5, 0.5, 0.5), roughness=0.5, metallic=0.0)
    folder = write_material(tmp_path / "flat", maps, ExportOptions(file_prefix="x_"), {"name": "flat"})
    write_image(folder / "preview.png", np.full((30, 60, 3), 0.5, np.float32), bit_depth=8)
    (folder / "preview.gif").write_bytes(b"GIF89a")  # shown by reference, never read
    document = json.loads((folder / "material.json").read_text())
    page = write_viewer(folder / "index.html", metadata=document, bundle=tmp_path / "none.js").read_text()
    for name, info in document["files"].items():
        if info["map"] in TEXTURE_MAPS:
            assert f'href="{name}"' in page
    assert "<title>flat" in page
    assert 'data-preview="preview" alt="preview.png" src="data:image/png;base64,' in page
    assert '<img src="preview.gif"' in page
