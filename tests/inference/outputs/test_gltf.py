"""material.glb export: GLB structure parsed back by hand, geometry/tangent conventions, and the
official Khronos glTF validator (npm ``gltf-validator`` in ``.node/``; skipped when not installed)."""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from brdfgan.inference.outputs.gltf import build_glb, write_glb
from tests.conftest import ROOT

VALIDATOR = ROOT / ".node" / "node_modules" / "gltf-validator"
NUMPY_TYPES = {5126: np.float32, 5123: np.uint16}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def _png(seed: int, size: int = 16) -> bytes:
    """A real 3-channel 8-bit PNG of random content (distinct per seed, so byte equality means something)."""
    pixels = np.random.default_rng(seed).integers(0, 256, (size, size, 3), dtype=np.uint8)
    ok, encoded = cv2.imencode(".png", pixels)
    assert ok
    return encoded.tobytes()


@pytest.fixture(scope="module")
def pngs() -> dict[str, bytes]:
    return {"basecolor_png": _png(1), "normal_png": _png(2), "metallic_roughness_png": _png(3)}


class Glb:
    """A GLB parsed back with struct/json only, checking the container rules on the way."""

    def __init__(self, data: bytes) -> None:
        assert len(data) % 4 == 0
        magic, version, length = struct.unpack_from("<4sII", data, 0)
        assert (magic, version, length) == (b"glTF", 2, len(data))
        json_length, json_type = struct.unpack_from("<I4s", data, 12)
        assert json_type == b"JSON" and json_length % 4 == 0
        raw_json = data[20 : 20 + json_length]
        self.json: dict[str, Any] = json.loads(raw_json.decode("utf-8"))
        # Padding is spaces (so the chunk stays valid JSON text), never NULs.
        assert raw_json.rstrip(b" ") == raw_json.rstrip() and b"\0" not in raw_json
        offset = 20 + json_length
        bin_length, bin_type = struct.unpack_from("<I4s", data, offset)
        assert bin_type == b"BIN\0" and bin_length % 4 == 0
        assert offset + 8 + bin_length == len(data)
        self.bin = data[offset + 8 :]
        declared = self.json["buffers"][0]["byteLength"]
        assert declared <= bin_length <= declared + 3
        assert set(self.bin[declared:]) <= {0}

    def view(self, index: int) -> bytes:
        view = self.json["bufferViews"][index]
        start = view.get("byteOffset", 0)
        return self.bin[start : start + view["byteLength"]]

    def accessor(self, index: int) -> np.ndarray:
        acc = self.json["accessors"][index]
        array = np.frombuffer(self.view(acc["bufferView"]), dtype=NUMPY_TYPES[acc["componentType"]])
        return array.reshape(acc["count"], WIDTHS[acc["type"]])

    @property
    def primitive(self) -> dict[str, Any]:
        return self.json["meshes"][0]["primitives"][0]

    def attribute(self, name: str) -> np.ndarray:
        return self.accessor(self.primitive["attributes"][name]).astype(np.float64)


def test_container_header_chunks_and_buffer_view_alignment(pngs: dict[str, bytes]) -> None:
    glb = Glb(build_glb(**pngs))
    assert glb.json["asset"] == {"version": "2.0", "generator": "brdfgan"}
    for view in glb.json["bufferViews"]:
        assert view["buffer"] == 0 and view["byteOffset"] % 4 == 0
        assert view["byteOffset"] + view["byteLength"] <= glb.json["buffers"][0]["byteLength"]
    # Vertex views are ARRAY_BUFFER, the index view ELEMENT_ARRAY_BUFFER, image views have no target.
    primitive = glb.primitive
    accessors, views = glb.json["accessors"], glb.json["bufferViews"]
    for index in primitive["attributes"].values():
        assert views[accessors[index]["bufferView"]]["target"] == 34962
    assert views[accessors[primitive["indices"]]["bufferView"]]["target"] == 34963
    for image in glb.json["images"]:
        assert "target" not in views[image["bufferView"]]


def test_images_are_the_given_png_bytes_bound_to_the_right_slots(pngs: dict[str, bytes]) -> None:
    glb = Glb(build_glb(**pngs))
    gltf = glb.json

    def image_bytes(texture_info: dict[str, Any]) -> bytes:
        image = gltf["images"][gltf["textures"][texture_info["index"]]["source"]]
        assert image["mimeType"] == "image/png" and "uri" not in image
        return glb.view(image["bufferView"])

    material = gltf["materials"][0]
    pbr = material["pbrMetallicRoughness"]
    assert image_bytes(pbr["baseColorTexture"]) == pngs["basecolor_png"]
    assert image_bytes(pbr["metallicRoughnessTexture"]) == pngs["metallic_roughness_png"]
    assert image_bytes(material["normalTexture"]) == pngs["normal_png"]


def test_material_sampler_and_scene_graph(pngs: dict[str, bytes]) -> None:
    gltf = Glb(build_glb(**pngs, name="oak", generator="brdfgan test")).json
    assert gltf["asset"]["generator"] == "brdfgan test"
    assert gltf["scene"] == 0 and gltf["scenes"] == [{"name": "oak", "nodes": [0]}]
    assert gltf["nodes"] == [{"name": "oak", "mesh": 0}]
    assert len(gltf["meshes"]) == 1 and len(gltf["meshes"][0]["primitives"]) == 1
    material = gltf["materials"][0]
    assert material["name"] == "oak" and material["doubleSided"] is False
    pbr = material["pbrMetallicRoughness"]
    assert pbr["baseColorFactor"] == [1, 1, 1, 1] and pbr["metallicFactor"] == pbr["roughnessFactor"] == 1
    assert gltf["samplers"] == [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}]
    assert all(texture["sampler"] == 0 for texture in gltf["textures"])
    assert len(gltf["textures"]) == len(gltf["images"]) == 3


@pytest.mark.parametrize("size", [1.0, 0.3, 2.5])
def test_accessors_counts_types_and_position_bounds(pngs: dict[str, bytes], size: float) -> None:
    glb = Glb(build_glb(**pngs, size=size))
    accessors = glb.json["accessors"]
    attributes = glb.primitive["attributes"]
    expected = {"POSITION": "VEC3", "NORMAL": "VEC3", "TANGENT": "VEC4", "TEXCOORD_0": "VEC2"}
    assert {name: accessors[i]["type"] for name, i in attributes.items()} == expected
    assert all(
        accessors[i]["count"] == 4 and accessors[i]["componentType"] == 5126 for i in attributes.values()
    )
    indices = accessors[glb.primitive["indices"]]
    assert (indices["count"], indices["componentType"], indices["type"]) == (6, 5123, "SCALAR")
    assert glb.primitive.get("mode", 4) == 4

    position = glb.accessor(attributes["POSITION"])
    pos_accessor = accessors[attributes["POSITION"]]
    # min/max must equal the stored float32 values exactly (the validator checks this).
    assert pos_accessor["min"] == position.min(axis=0).tolist()
    assert pos_accessor["max"] == position.max(axis=0).tolist()
    np.testing.assert_allclose(pos_accessor["min"], [-size / 2, 0, -size / 2], rtol=1e-6)
    np.testing.assert_allclose(pos_accessor["max"], [size / 2, 0, size / 2], rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(glb.attribute("NORMAL"), axis=1), 1.0)
    tangent = glb.attribute("TANGENT")
    np.testing.assert_allclose(np.linalg.norm(tangent[:, :3], axis=1), 1.0)
    assert set(tangent[:, 3].tolist()) <= {-1.0, 1.0}
    uv = glb.attribute("TEXCOORD_0")
    assert uv.min() == 0.0 and uv.max() == 1.0


def _triangles(glb: Glb) -> np.ndarray:
    indices = glb.accessor(glb.primitive["indices"]).reshape(-1, 3).astype(np.int64)
    assert indices.max() < 4
    return indices


def test_winding_is_counter_clockwise_seen_from_the_normal_side(pngs: dict[str, bytes]) -> None:
    glb = Glb(build_glb(**pngs))
    position, normal = glb.attribute("POSITION"), glb.attribute("NORMAL")
    np.testing.assert_allclose(normal, [[0, 1, 0]] * 4)  # documented: the plane faces +Y
    for a, b, c in _triangles(glb):
        face = np.cross(position[b] - position[a], position[c] - position[a])
        assert np.linalg.norm(face) > 0
        for vertex in (a, b, c):
            np.testing.assert_allclose(face / np.linalg.norm(face), normal[vertex], atol=1e-7)


def test_tangent_frame_maps_image_directions_as_documented(pngs: dict[str, bytes]) -> None:
    """Image +X (columns, +u) → tangent → world +X; image up (towards row 0, −v) → bitangent →
    world −Z; so an OpenGL normal-map texel tilted "up" (green > 0.5) tilts towards the image's top edge."""
    glb = Glb(build_glb(**pngs, size=2.0))
    position, normal, tangent, uv = (
        glb.attribute(n) for n in ("POSITION", "NORMAL", "TANGENT", "TEXCOORD_0")
    )
    # The image's top-left corner (u, v) = (0, 0) is at the far left of the floor, as documented.
    top_left = np.flatnonzero((uv == [0.0, 0.0]).all(axis=1))
    np.testing.assert_allclose(position[top_left], [[-1, 0, -1]])
    for a, b, c in _triangles(glb):
        # Per triangle, solve position differences = [dP/du dP/dv] · uv differences.
        dp = np.stack([position[b] - position[a], position[c] - position[a]])
        duv = np.stack([uv[b] - uv[a], uv[c] - uv[a]])
        dp_du, dp_dv = np.linalg.solve(duv, dp)
        for vertex in (a, b, c):
            t, w = tangent[vertex, :3], tangent[vertex, 3]
            bitangent = np.cross(normal[vertex], t) * w  # glTF's definition
            np.testing.assert_allclose(t, dp_du / np.linalg.norm(dp_du), atol=1e-7)
            np.testing.assert_allclose(bitangent, -dp_dv / np.linalg.norm(dp_dv), atol=1e-7)
            np.testing.assert_allclose(t, [1, 0, 0])
            np.testing.assert_allclose(bitangent, [0, 0, -1])
            # A texel (n+1)/2 = (0.5, 1, 0.5), i.e. n = +Y in tangent space, points at the top edge (v = 0).
            world = np.array([t, bitangent, normal[vertex]]).T @ np.array([0.0, 1.0, 0.0])
            top_edge_z = position[uv[:, 1] == 0.0][:, 2]
            assert np.all(np.sign(top_edge_z) == np.sign(world[2])) and world[2] != 0


def test_write_glb_is_atomic_and_equals_build_glb(tmp_path: Path, pngs: dict[str, bytes]) -> None:
    target = tmp_path / "material.glb"
    target.write_bytes(b"old")
    assert write_glb(target, **pngs, size=0.5) == target
    assert target.read_bytes() == build_glb(**pngs, size=0.5)
    # A failing export leaves the previous file in place and no temporary behind.
    before = target.read_bytes()
    with pytest.raises(ValueError, match="normal_png"):
        write_glb(target, **{**pngs, "normal_png": b"JFIF not a png"})
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["material.glb"]


@pytest.mark.parametrize("size", [0.0, -1.0, float("nan"), float("inf"), "big"])
def test_rejects_bad_size(pngs: dict[str, bytes], size: Any) -> None:
    with pytest.raises(ValueError, match="size"):
        build_glb(**pngs, size=size)


def test_rejects_non_png_bytes(pngs: dict[str, bytes]) -> None:
    _, jpeg = cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(ValueError, match="basecolor_png: not PNG"):
        build_glb(**{**pngs, "basecolor_png": jpeg.tobytes()})
    with pytest.raises(TypeError, match="metallic_roughness_png"):
        build_glb(**{**pngs, "metallic_roughness_png": "path.png"})  # type: ignore[arg-type]


# --- Khronos glTF validator ------------------------------------------------------------------------

VALIDATE_JS = """
const fs = require("fs");
const validator = require(process.argv[2]);
validator
  .validateBytes(new Uint8Array(fs.readFileSync(process.argv[3])), { maxIssues: 100 })
  .then((report) => process.stdout.write(JSON.stringify(report)))
  .catch((error) => { console.error(String(error)); process.exit(2); });
"""


@pytest.fixture
def validate(tmp_path: Path) -> Callable[[bytes], dict[str, Any]]:
    """Run the official validator on GLB bytes and return its JSON report."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node not found: the Khronos glTF validator needs Node.js")
    if not (VALIDATOR / "package.json").is_file():
        pytest.skip("gltf-validator not installed: run scripts/install_gltf_validator.sh")
    script = tmp_path / "validate.js"
    script.write_text(VALIDATE_JS, encoding="utf-8")

    def run(data: bytes) -> dict[str, Any]:
        asset = tmp_path / "asset.glb"
        asset.write_bytes(data)
        result = subprocess.run(
            [node, str(script), str(VALIDATOR), str(asset)], capture_output=True, text=True, timeout=120
        )
        assert result.returncode == 0, result.stderr
        return json.loads(result.stdout)

    return run


def _codes(report: dict[str, Any], severity: int) -> list[str]:
    return [m["code"] for m in report["issues"]["messages"] if m["severity"] == severity]


def test_khronos_validator_accepts_the_export(validate: Callable, pngs: dict[str, bytes]) -> None:
    report = validate(build_glb(**pngs, size=0.3, normal_scale=1.5))  # occlusion in the ORM texture too
    issues = report["issues"]
    assert (issues["numErrors"], issues["numWarnings"]) == (0, 0), issues["messages"]
    assert issues["numInfos"] == 0 and issues["numHints"] == 0, issues["messages"]
    assert report["mimeType"] == "model/gltf-binary" and report["validatorVersion"] == "2.0.0-dev.3.10"
    info = report["info"]
    assert (info["totalVertexCount"], info["totalTriangleCount"], info["hasTextures"]) == (4, 2, True)
    # The validator decoded the embedded PNG headers, so it really read the images.
    images = [r for r in info["resources"] if r["pointer"].startswith("/images/")]
    assert len(images) == 3
    for resource in images:
        assert resource["storage"] == "buffer-view" and resource["mimeType"] == "image/png"
        assert (resource["image"]["width"], resource["image"]["height"]) == (16, 16)


def test_khronos_validator_reports_a_wrong_length_field(validate: Callable, pngs: dict[str, bytes]) -> None:
    data = bytearray(build_glb(**pngs))
    data[8:12] = struct.pack("<I", len(data) + 4)
    report = validate(bytes(data))
    assert report["issues"]["numErrors"] >= 1
    assert "GLB_LENGTH_MISMATCH" in _codes(report, severity=0)


def test_khronos_validator_reads_the_embedded_pngs(validate: Callable, pngs: dict[str, bytes]) -> None:
    """A truncated PNG (valid signature) is an error: the validator parses the image data itself."""
    report = validate(build_glb(**{**pngs, "normal_png": pngs["normal_png"][:40]}))
    assert "IMAGE_UNEXPECTED_EOS" in _codes(report, severity=0)
