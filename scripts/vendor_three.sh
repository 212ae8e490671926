#!/usr/bin/env bash
# Vendor three.js for the material viewer page (OUT/<name>/index.html, brdfgan.inference.outputs.viewer):
# npm installs three and esbuild (pinned) into the project-local, git-ignored .node/vendor/ folder, and
# esbuild bundles the few three.js classes the page uses (plus OrbitControls and RoomEnvironment
# from three/addons) into ONE minified IIFE, src/brdfgan/viewer/three.bundle.js (git-ignored),
# which defines the global `THREE`. viewer.py inlines that file into every page: Chromium runs
# no module script loaded from a file:// URL, so a page that works opened from disk carries its
# scripts (and its textures) inside itself.
# Optional tooling: this script always exits 0, so a machine without npm or without network access
# still builds; the page then shows the 2D maps only and says the 3D view needs `make setup`.
set -u

THREE_VERSION="0.187.0"
ESBUILD_VERSION="0.28.2"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Its own prefix: `npm install --prefix P --no-save X` removes every other package from P, so
# sharing .node/ with gltf-validator (scripts/install_gltf_validator.sh) would undo one another.
PREFIX="$ROOT/.node/vendor"
BUNDLE="$ROOT/src/brdfgan/viewer/three.bundle.js"

# What the page's script uses (THREE.<name>); add a name here when viewer.py starts using it.
ENTRY='export {
  WebGLRenderer, Scene, PerspectiveCamera, Mesh, PlaneGeometry, MeshStandardMaterial, Texture,
  DirectionalLight, HemisphereLight, PMREMGenerator, Color, Vector2, Vector3, Euler, MathUtils,
  RepeatWrapping, SRGBColorSpace, NoColorSpace, NeutralToneMapping, REVISION,
} from "three";
export { OrbitControls } from "three/addons/controls/OrbitControls.js";
export { RoomEnvironment } from "three/addons/environments/RoomEnvironment.js";'
# The first line of the bundle: the versions and a hash of the entry, so a changed pin or entry rebuilds.
ENTRY_HASH="$(printf '%s' "$ENTRY" | sha1sum | cut -c1-12)"
HEADER="/* brdfgan viewer: three@$THREE_VERSION bundled by esbuild@$ESBUILD_VERSION (scripts/vendor_three.sh, entry $ENTRY_HASH) */"

if [ -f "$BUNDLE" ] && [ "$(head -n 1 "$BUNDLE")" = "$HEADER" ]; then
    exit 0  # already built: keep `make setup` fast and offline-friendly
fi
if ! command -v npm >/dev/null 2>&1 || ! command -v node >/dev/null 2>&1; then
    echo "note: npm not found; three.js not vendored (the viewer pages show the 2D maps only)" >&2
    exit 0
fi

installed() {  # installed PACKAGE VERSION: that exact version is in .node/node_modules
    [ -f "$PREFIX/node_modules/$1/package.json" ] \
        && grep -q "\"version\": \"$2\"" "$PREFIX/node_modules/$1/package.json"
}

mkdir -p "$PREFIX"
if ! installed three "$THREE_VERSION" || ! installed esbuild "$ESBUILD_VERSION"; then
    # Short fetch timeout and one retry: an offline machine must not stall `make setup` for minutes.
    if ! npm install --prefix "$PREFIX" --no-save --no-audit --no-fund --loglevel=error --silent \
        --fetch-retries=1 --fetch-timeout=30000 \
        "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION" >/dev/null; then
        echo "warning: npm could not install three@$THREE_VERSION and esbuild@$ESBUILD_VERSION;" \
            "the viewer pages show the 2D maps only" >&2
        exit 0
    fi
fi

work="$(mktemp -d "$PREFIX/vendor-three.XXXXXX")"
trap 'rm -rf "$work"' EXIT
printf '%s\n' "$ENTRY" >"$work/entry.js"
# The entry lies inside $PREFIX, so esbuild resolves "three" from $PREFIX/node_modules.
if ! "$PREFIX/node_modules/.bin/esbuild" "$work/entry.js" --bundle --format=iife \
    --global-name=THREE --minify --target=es2020 --legal-comments=inline --log-level=warning \
    --outfile="$work/bundle.js"; then
    echo "warning: esbuild could not bundle three@$THREE_VERSION; the viewer pages show the 2D maps only" >&2
    exit 0
fi
mkdir -p "$(dirname "$BUNDLE")"
{ printf '%s\n' "$HEADER"; cat "$work/bundle.js"; } >"$work/three.bundle.js"
mv -f "$work/three.bundle.js" "$BUNDLE"  # one rename: never a half-written bundle
echo "vendored three@$THREE_VERSION into src/brdfgan/viewer/three.bundle.js ($(wc -c <"$BUNDLE") bytes)"
exit 0
