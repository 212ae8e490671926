"""``index.html``: one self-contained page per material — the maps, the previews and an interactive
3D view (three.js) of the material on a 1 m floor plane, with a movable light, a rotatable
environment and a tiling slider.

The page works opened straight from disk (``file://``), which shapes it:

- Chromium runs no module script loaded from a ``file://`` URL (the page's origin is ``null``) and
  refuses, for WebGL, images loaded from ``file://`` (a tainted canvas). So nothing is loaded: the
  vendored three.js bundle (``src/brdfgan/viewer/three.bundle.js``, an IIFE defining ``THREE``, built
  by ``scripts/vendor_three.sh`` at ``make setup``) is inlined, and every texture is embedded as a
  ``data:`` URI (8-bit PNG, at most :data:`MAX_TEXTURE_SIDE` on a side: bigger maps are area-
  downscaled for the page only). The 2D gallery's ``<img>`` elements are the 3D view's textures,
  so each map is embedded once. Links to the files themselves (and ``preview.gif``/``.mp4``, shown
  by reference, not embedded) are relative.
- Without the bundle (no ``make setup``, no npm, offline) the page still shows the maps and the
  previews, with one line saying the 3D view needs ``make setup``; a warning is logged once.

Shading: ``MeshStandardMaterial`` with the base colour (sRGB), the tangent-space normal map (the
normal strength is baked into the loose file, so scale 1; a DirectX file gets ``normalScale.y = −1``)
and the glTF ORM texture as roughness (G), metalness (B) and occlusion (R) maps; a directional light
(azimuth from +X towards the image's top, counter-clockwise like :mod:`~brdfgan.inference.outputs.preview`,
and elevation), a dim hemisphere light and three's ``RoomEnvironment`` as image-based light.
The URL fragment presets the controls: ``index.html#tiling=3&azimuth=90&elevation=30&environment=0``.

Once the first frame is drawn the page sets ``<html data-viewer="rendered">`` with
``data-mean-rgb`` (the frame's mean colour, 0-255), ``data-canvas-rect`` (CSS pixels) and
``data-renderer``; ``"no-3d"`` without the bundle, ``"error"`` (and a visible message) on failure.
"""

from __future__ import annotations

import base64
import html
import json
import logging
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from brdfgan.inference.outputs.export import HIDDEN_OUTPUT_PATTERN, ExportOptions
from brdfgan.io.atomic import write_text_atomic
from brdfgan.io.images import ImageIOError, png_bytes, read_image

__all__ = ["MAX_TEXTURE_SIDE", "TEXTURE_MAPS", "THREE_BUNDLE", "material_files", "write_viewer"]

log = logging.getLogger(__name__)

# Built by scripts/vendor_three.sh (git-ignored); shipped as package data when present.
THREE_BUNDLE = Path(__file__).resolve().parents[2] / "viewer" / "three.bundle.js"
MAX_TEXTURE_SIDE = 1024  # embedded textures: longest side in pixels (the files keep theirs)
MAX_PREVIEW_SIDE = 1600  # the embedded preview.png
# The loose texture maps, in gallery order, with what the page says when material.json does not.
TEXTURE_MAPS: dict[str, str] = {
    "basecolor": "base colour, sRGB",
    "normal": "tangent-space normal (n + 1) / 2",
    "roughness": "perceptual roughness",
    "metallic": "metalness",
    "metallicRoughness": "glTF ORM: R = occlusion, G = roughness, B = metallic",
    "height": "height (16-bit file; 8-bit here)",
    "ao": "ambient occlusion",
    "diffuse": "diffuse albedo, sRGB",
    "specular": "specular F0, sRGB",
}
COLOUR_MAPS = frozenset({"basecolor", "diffuse", "specular"})
PREVIEWS = {"preview": ("preview.png",), "animation": ("preview.gif", "preview.mp4")}
# The 3D view's sliders: id (also the URL fragment's key), label, min, max, step, default, unit.
CONTROLS: tuple[tuple[str, str, float, float, float, float, str], ...] = (
    ("tiling", "Tiling", 1, 8, 1, 1, "×"),  # texture repeats across the 1 m plane
    ("azimuth", "Light azimuth", 0, 360, 1, 45, "°"),
    ("elevation", "Light elevation", 3, 90, 1, 35, "°"),
    ("intensity", "Light intensity", 0, 6, 0.1, 2.5, ""),
    ("environment", "Environment", 0, 1.5, 0.05, 0.4, ""),
    ("rotation", "Environment rotation", 0, 360, 1, 0, "°"),
)
SETUP_NOTE = (
    "The interactive 3D view needs three.js, which <code>make setup</code> vendors "
    "(<code>scripts/vendor_three.sh</code>); this page shows the maps only."
)

_warned_bundles: set[Path] = set()


def write_viewer(
    path: str | os.PathLike[str],
    files: Mapping[str, str | os.PathLike[str]] | None = None,
    metadata: Mapping[str, Any] | None = None,
    *,
    options: ExportOptions | None = None,
    bundle: str | os.PathLike[str] | None = None,
) -> Path:
    """Write the viewer page to ``path`` (atomically) for the material whose files lie beside it.

    Made to run as an ``extra_files`` writer of
    :func:`~brdfgan.inference.outputs.export.write_material` (the textures are already in the
    staging folder then; ``material.json`` is not yet), or on a finished folder.

    Args:
        path: the page, normally ``<material folder>/index.html``.
        files: map name (a key of :data:`TEXTURE_MAPS`, or ``"preview"``/``"animation"``) → file,
            relative to the page's folder or absolute; default :func:`material_files`.
        metadata: what ``material.json`` holds (or the pipeline's metadata): the name, model and
            warnings for the page's header; its ``files`` table, when present, names the files and
            their encodings.
        options: the export options the files were written with (file prefix, format, normal
            convention), for a folder without a ``files`` table.
        bundle: the three.js bundle (default :data:`THREE_BUNDLE`); missing: a page without 3D view.
    Returns:
        ``path``
    """
    path = Path(path)
    directory = path.parent
    metadata = metadata or {}
    table = _files_table(directory, metadata)
    if files is None:
        found = material_files(directory, metadata, options)
    else:
        found = {key: directory / Path(value) for key, value in files.items()}
    convention: str = options.normal_convention if options is not None else "opengl"
    if "normal" in found:
        convention = str(table.get(found["normal"].name, {}).get("convention", convention))
    script = _three_bundle(Path(bundle) if bundle is not None else THREE_BUNDLE)
    page = _page(directory, found, table, metadata, script, convention)
    return write_text_atomic(path, page)


def material_files(
    directory: str | os.PathLike[str],
    metadata: Mapping[str, Any] | None = None,
    options: ExportOptions | None = None,
) -> dict[str, Path]:
    """The material's files in ``directory``: map name → path for the texture maps that exist, plus
    ``"preview"`` (``preview.png``) and ``"animation"`` (``preview.gif`` or ``.mp4``) when present.

    Names come from the ``files`` table (``metadata``'s, else ``material.json``'s), else from
    ``options`` (prefix and format), else from the folder: ``<prefix>basecolor.<png|exr>`` fixes
    the prefix and format of the others.
    """
    directory = Path(directory)
    found: dict[str, Path] = {}
    for name, info in _files_table(directory, metadata or {}).items():
        map_name = info.get("map")
        if map_name in TEXTURE_MAPS and (directory / name).is_file():
            found[map_name] = directory / name
    if not found:
        prefix, extension = _prefix_and_format(directory, options)
        for map_name in TEXTURE_MAPS:
            candidate = directory / f"{prefix}{map_name}.{extension}"
            if candidate.is_file():
                found[map_name] = candidate
    ordered = {map_name: found[map_name] for map_name in TEXTURE_MAPS if map_name in found}
    for key, names in PREVIEWS.items():
        for name in names:
            if (directory / name).is_file():
                ordered[key] = directory / name
                break
    return ordered


def _prefix_and_format(directory: Path, options: ExportOptions | None) -> tuple[str, str]:
    if options is not None:
        return options.file_prefix, options.format
    for extension in ("png", "exr"):
        if (directory / f"basecolor.{extension}").is_file():
            return "", extension
    for extension in ("png", "exr"):
        candidates = sorted(directory.glob(f"*basecolor.{extension}"))
        if candidates:
            return candidates[0].name[: -len(f"basecolor.{extension}")], extension
    return "", "png"


def _files_table(directory: Path, metadata: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """The ``files`` table of ``metadata``, else of ``directory/material.json``; ``{}`` when neither."""
    table = metadata.get("files")
    if not isinstance(table, Mapping):
        try:
            table = json.loads((directory / "material.json").read_text()).get("files")
        except (OSError, ValueError, AttributeError):
            table = None
    if not isinstance(table, Mapping):
        return {}
    return {str(name): dict(info) for name, info in table.items() if isinstance(info, Mapping)}


def _three_bundle(bundle: Path) -> str | None:
    """The bundle's text, ready to inline; ``None`` (and a warning, once per path) when missing."""
    text: str | None
    try:
        text = bundle.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        reason = "missing" if isinstance(error, FileNotFoundError) else f"unreadable ({error})"
        text = None
    else:
        reason = "not usable inline (it contains '<!--')"
        if "<!--" in text:  # would change how the HTML parser ends the <script> element
            text = None
    if text is None:
        if bundle not in _warned_bundles:
            _warned_bundles.add(bundle)
            log.warning(
                "%s: %s; the viewer pages (index.html) get no 3D view: run `make setup` "
                "(scripts/vendor_three.sh vendors three.js)",
                bundle,
                reason,
            )
        return None
    # "</script" inside a string or regex ends the element early; "<\/" means the same in JS.
    return re.sub(r"</(script)", r"<\\/\1", text, flags=re.IGNORECASE)


def _page(
    directory: Path,
    files: Mapping[str, Path],
    table: Mapping[str, Mapping[str, Any]],
    metadata: Mapping[str, Any],
    script: str | None,
    convention: str,
) -> str:
    name = str(metadata.get("name") or _material_name(directory))
    figures: list[str] = []
    for key, file in files.items():
        figure = _figure(key, file, table.get(file.name, {}))
        if figure:
            figures.append(figure)
    has_textures = any(key in TEXTURE_MAPS for key in files)
    three_version = _three_version(script) if script is not None else None
    if script is not None and has_textures:
        units = {key: unit for key, _, _, _, _, _, unit in CONTROLS}
        config = {"normalY": -1 if convention == "directx" else 1, "units": units}
        view = VIEW_HTML.replace("@@CONFIG@@", _script_json(config)).replace("@@CONTROLS@@", _controls())
        scripts = f'<script>\n{script}\n</script>\n<script type="module">\n{VIEW_JS}\n</script>'
        state = "loading"
    else:
        note = SETUP_NOTE if script is None else "No texture maps found beside this page: no 3D view."
        view = f'<p class="note" id="note3d">{note}</p>'
        scripts = ""
        state = "no-3d"
    footer = "brdfgan material viewer" + (f" · three.js r{three_version}" if three_version else "")
    values = {
        "STATE": state,
        "TITLE": html.escape(name),
        "INFO": _info(metadata),
        "VIEW": view,
        "GALLERY": "\n".join(figures),
        "FOOTER": html.escape(footer),
        "SCRIPTS": scripts,
    }
    # One pass: a "@@…@@" inside a value (a warning, the bundle) is never substituted.
    return re.sub(r"@@([A-Z]+)@@", lambda match: values[match[1]], PAGE_HTML)


def _controls() -> str:
    return "\n".join(
        f'<label>{label} <output id="{key}-value"></output>'
        f'<input id="{key}" type="range" min="{low}" max="{high}" step="{step}" value="{value}"></label>'
        for key, label, low, high, step, value, _ in CONTROLS
    )


def _material_name(directory: Path) -> str:
    """The folder's name, also from inside ``write_material``'s hidden staging folder."""
    match = HIDDEN_OUTPUT_PATTERN.match(directory.name)
    return match["name"] if match else directory.name


def _three_version(script: str) -> str | None:
    match = re.search(r"three@([0-9][0-9.]*)", script[:400])
    return match[1].split(".")[1] if match and "." in match[1] else None


def _script_json(value: Any) -> str:
    """JSON safe inside a ``<script>`` element."""
    return json.dumps(value).replace("<", "\\u003c")


def _figure(key: str, file: Path, info: Mapping[str, Any]) -> str | None:
    link = html.escape(file.name, quote=True)
    if key == "animation":
        if file.suffix == ".mp4":
            media = f'<video src="{link}" autoplay loop muted playsinline controls></video>'
        else:
            media = f'<img src="{link}" alt="turntable animation">'
        return f'<figure class="wide">{media}<figcaption><a href="{link}">{link}</a></figcaption></figure>'
    limit = MAX_PREVIEW_SIDE if key == "preview" else MAX_TEXTURE_SIDE
    try:
        data = _page_png(file, key, info, limit)
    except (OSError, ImageIOError, cv2.error, ValueError) as error:
        log.warning("%s: not shown in the viewer page (%s)", file, error)
        return None
    uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
    about = "relit previews" if key == "preview" else str(info.get("encoding") or TEXTURE_MAPS.get(key, key))
    role = "preview" if key == "preview" else "map"
    return (
        f'<figure class="{role}"><a href="{link}"><img data-{role}="{html.escape(key, quote=True)}" '
        f'alt="{link}" src="{uri}"></a>'
        f'<figcaption><a href="{link}">{link}</a><br>{html.escape(about)}</figcaption></figure>'
    )


def _page_png(file: Path, key: str, info: Mapping[str, Any], limit: int) -> bytes:
    """An 8-bit PNG of ``file`` for the page: the file's own bytes when it already is one and
    small enough, else decoded (16-bit, EXR: linear colour maps sRGB-encoded, a raw height
    normalised around 0.5), clipped, area-downscaled to ``limit`` and re-encoded."""
    raw = file.read_bytes()
    if file.suffix.lower() == ".png" and raw[:8] == b"\x89PNG\r\n\x1a\n" and len(raw) > 25 and raw[24] == 8:
        width, height = int.from_bytes(raw[16:20], "big"), int.from_bytes(raw[20:24], "big")
        if max(width, height) <= limit:
            return raw
    values = read_image(file)[..., :3]
    if file.suffix.lower() == ".exr":
        if key == "height":
            reach = float(np.abs(values).max())
            values = 0.5 + 0.5 * values / reach if reach > 0 else np.full_like(values, 0.5)
        elif key in COLOUR_MAPS and info.get("colorspace", "linear") != "srgb":
            values = _srgb_encode(values)
    values = np.clip(np.nan_to_num(values, nan=0.0), 0.0, 1.0).astype(np.float32)
    longest = max(values.shape[:2])
    if longest > limit:
        scale = limit / longest
        size = (max(1, round(values.shape[1] * scale)), max(1, round(values.shape[0] * scale)))
        values = cv2.resize(values, size, interpolation=cv2.INTER_AREA).reshape(size[1], size[0], -1)
    if values.shape[2] == 1:
        values = values[..., 0]
    return png_bytes(values)


def _srgb_encode(linear: np.ndarray) -> np.ndarray:
    linear = np.clip(linear, 0.0, 1.0)
    return np.where(
        linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(np.maximum(linear, 0.0031308), 1 / 2.4) - 0.055
    )


def _info(metadata: Mapping[str, Any]) -> str:
    """A few lines about the material: model, input photo, resolution, warnings."""
    items: list[str] = []
    model = metadata.get("model")
    if isinstance(model, Mapping) and model.get("id"):
        items.append(f"model <code>{html.escape(str(model['id']))}</code>")
    source = metadata.get("input")
    if isinstance(source, Mapping) and source.get("file"):
        items.append(f"photo <code>{html.escape(Path(str(source['file'])).name)}</code>")
    if isinstance(metadata.get("resolution"), int):
        items.append(f"{metadata['resolution']}² px")
    if metadata.get("tileable"):
        items.append("tileable")
    parts = [f'<p class="info">{" · ".join(items)}</p>'] if items else []
    warnings = metadata.get("warnings")
    if isinstance(warnings, list) and warnings:
        lines = "".join(f"<li>{html.escape(str(w))}</li>" for w in warnings)
        parts.append(f'<ul class="warnings">{lines}</ul>')
    links = '<a href="material.glb">material.glb</a> · <a href="material.json">material.json</a>'
    parts.append(f'<p class="info">{links}</p>')
    return "\n".join(parts)


PAGE_HTML = """<!doctype html>
<html lang="en" data-viewer="@@STATE@@">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>@@TITLE@@ · brdfgan material</title>
<style>
body { margin: 0; padding: 16px 24px; font: 14px/1.4 system-ui, sans-serif; }
body { background: #16171a; color: #ddd; }
h1 { font-size: 20px; margin: 0 0 4px; } h2 { font-size: 15px; margin: 20px 0 8px; color: #aaa; }
a { color: #8ab4f8; } code { font-size: 13px; }
.info { margin: 2px 0; color: #aaa; } .warnings { color: #e8b04b; margin: 4px 0; padding-left: 20px; }
.note { color: #e8b04b; }
.viewer { display: flex; gap: 16px; align-items: flex-start; flex-wrap: wrap; }
#view { position: relative; flex: 1 1 480px; max-width: 960px; aspect-ratio: 16 / 10; background: #202225; }
#view canvas { display: block; width: 100%; height: 100%; cursor: grab; touch-action: none; }
.controls { flex: 0 0 220px; display: grid; gap: 10px; }
.controls label { display: block; } .controls output { float: right; color: #aaa; }
.controls input { width: 100%; } .hint { color: #888; font-size: 12px; }
.gallery { display: flex; flex-wrap: wrap; gap: 12px; }
figure { margin: 0; width: 200px; } figure.preview, figure.wide { width: auto; max-width: 100%; }
figure img, figure video { display: block; width: 100%; image-rendering: auto; background: #000; }
figure.preview img, figure.wide img, figure.wide video { width: auto; max-width: 100%; }
figcaption { font-size: 12px; color: #aaa; margin-top: 3px; word-break: break-word; }
footer { margin-top: 24px; color: #666; font-size: 12px; }
</style>
</head>
<body>
<h1>@@TITLE@@</h1>
@@INFO@@
@@VIEW@@
<h2>Maps and previews</h2>
<div class="gallery">
@@GALLERY@@
</div>
<footer>@@FOOTER@@</footer>
@@SCRIPTS@@
</body>
</html>
"""

VIEW_HTML = """<div class="viewer">
<div id="view"><canvas id="canvas"></canvas></div>
<div class="controls">
@@CONTROLS@@
<p class="hint">Drag to orbit, wheel to zoom, right-drag to pan. Azimuth 0° lights from the
texture's right, 90° from its top.</p>
<p class="note" id="note3d" hidden></p>
</div>
</div>
<script type="application/json" id="viewer-config">@@CONFIG@@</script>"""

VIEW_JS = r"""
const root = document.documentElement;
const note = document.getElementById("note3d");
function fail(message) {
  root.dataset.viewer = "error";
  note.hidden = false;
  note.textContent = "3D view failed: " + message;
}
window.addEventListener("error", (event) => fail(event.message));
window.addEventListener("unhandledrejection", (event) => fail(String(event.reason)));
main().catch((error) => fail(String(error)));

async function main() {
const config = JSON.parse(document.getElementById("viewer-config").textContent);
const canvas = document.getElementById("canvas");
let renderer;
try {
  renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
} catch (error) {
  fail("WebGL is not available in this browser (" + error.message + ")");
  return;
}
renderer.toneMapping = THREE.NeutralToneMapping;
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));

const scene = new THREE.Scene();
scene.background = new THREE.Color(0x202225);
const pmrem = new THREE.PMREMGenerator(renderer);
scene.environment = pmrem.fromScene(new THREE.RoomEnvironment(), 0.04).texture;
pmrem.dispose();
scene.add(new THREE.HemisphereLight(0xffffff, 0x30302c, 0.15));
const light = new THREE.DirectionalLight(0xffffff, 2.5);
scene.add(light, light.target);

const camera = new THREE.PerspectiveCamera(30, 16 / 10, 0.01, 50);
camera.position.set(0, 0.88, 1.34);  // 33° above the plane, looking at its centre: all of it in view
const controls = new THREE.OrbitControls(camera, canvas);
controls.target.set(0, 0, 0);
controls.maxPolarAngle = THREE.MathUtils.degToRad(88);
controls.minDistance = 0.2;
controls.maxDistance = 6;
controls.update();

async function texture(map, srgb) {
  const shown = document.querySelector(`img[data-map="${map}"]`);
  if (!shown) return null;
  // A detached copy of the gallery's image (same data: URI): three sizes mipmaps by img.width,
  // which for a laid-out <img> is its CSS width, not the texture's.
  const image = new Image();
  image.src = shown.src;
  await image.decode();
  const result = new THREE.Texture(image);
  result.colorSpace = srgb ? THREE.SRGBColorSpace : THREE.NoColorSpace;
  result.wrapS = result.wrapT = THREE.RepeatWrapping;
  result.anisotropy = renderer.capabilities.getMaxAnisotropy();
  result.needsUpdate = true;
  return result;
}
const orm = await texture("metallicRoughness", false);
const maps = {
  map: await texture("basecolor", true),
  normalMap: await texture("normal", false),
  roughnessMap: orm || (await texture("roughness", false)),  // three reads G
  metalnessMap: orm || (await texture("metallic", false)),   // three reads B
  aoMap: orm || (await texture("ao", false)),                // three reads R, from uv (channel 0)
};
const material = new THREE.MeshStandardMaterial({
  ...Object.fromEntries(Object.entries(maps).filter(([, value]) => value)),
  normalScale: new THREE.Vector2(1, config.normalY),  // the strength is baked into the file
  roughness: maps.roughnessMap ? 1 : 0.5,
  metalness: maps.metalnessMap ? 1 : 0,
});
const plane = new THREE.Mesh(new THREE.PlaneGeometry(1, 1), material);  // 1 m, like material.glb
plane.rotation.x = -Math.PI / 2;  // floor, +Y up; the texture's top points away from the camera
scene.add(plane);
const textures = [...new Set(Object.values(maps).filter((value) => value))];

const inputs = {};
for (const input of document.querySelectorAll(".controls input")) inputs[input.id] = input;
const hash = new URLSearchParams(window.location.hash.slice(1));
for (const [key, value] of hash) if (key in inputs && value !== "") inputs[key].value = value;

function apply() {
  const get = (key) => Number(inputs[key].value);
  for (const item of textures) item.repeat.set(get("tiling"), get("tiling"));
  const azimuth = THREE.MathUtils.degToRad(get("azimuth"));
  const elevation = THREE.MathUtils.degToRad(get("elevation"));
  // Azimuth from +X (the texture's right) towards the texture's top (-Z), like preview.png.
  const reach = 2 * Math.cos(elevation);
  light.position.set(reach * Math.cos(azimuth), 2 * Math.sin(elevation), -reach * Math.sin(azimuth));
  light.intensity = get("intensity");
  scene.environmentIntensity = get("environment");
  scene.environmentRotation.y = THREE.MathUtils.degToRad(get("rotation"));
  for (const [key, input] of Object.entries(inputs)) {
    document.getElementById(key + "-value").textContent = input.value + (config.units[key] || "");
  }
}

function resize() {
  const width = canvas.clientWidth, height = canvas.clientHeight;
  if (width > 0 && height > 0 && (canvas.width !== Math.round(width * renderer.getPixelRatio()))) {
    renderer.setSize(width, height, false);
    camera.aspect = width / height;
    camera.updateProjectionMatrix();
  }
}

let pending = false;
function draw() {
  pending = false;
  resize();
  renderer.render(scene, camera);
}
function requestDraw() {
  if (!pending) {
    pending = true;
    requestAnimationFrame(draw);
  }
}

for (const input of Object.values(inputs)) input.addEventListener("input", () => { apply(); requestDraw(); });
controls.addEventListener("change", requestDraw);
new ResizeObserver(requestDraw).observe(canvas);

apply();
draw();
// What a test (or a curious user) can read: the first frame's mean colour, where it is, who drew it.
// (Read through a small 2D canvas in the same task as the draw, while the frame is still there.)
const probe = document.createElement("canvas");
probe.width = 64;
probe.height = 40;
const context = probe.getContext("2d", { willReadFrequently: true });
context.drawImage(canvas, 0, 0, probe.width, probe.height);
const pixels = context.getImageData(0, 0, probe.width, probe.height).data;
const mean = [0, 0, 0];
for (let i = 0; i < pixels.length; i += 4) for (let c = 0; c < 3; c++) mean[c] += pixels[i + c];
const count = pixels.length / 4;
const gl = renderer.getContext();
const rect = canvas.getBoundingClientRect();
root.dataset.meanRgb = mean.map((sum) => (sum / count).toFixed(1)).join(",");
root.dataset.canvasRect = [rect.left, rect.top, rect.width, rect.height].map(Math.round).join(",");
const debug = gl.getExtension("WEBGL_debug_renderer_info");
root.dataset.renderer = gl.getParameter(debug ? debug.UNMASKED_RENDERER_WEBGL : gl.RENDERER);
root.dataset.three = THREE.REVISION;
if (root.dataset.viewer !== "error") root.dataset.viewer = "rendered";
}  // main
"""
