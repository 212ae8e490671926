#!/usr/bin/env bash
# Install the Khronos glTF validator (npm package gltf-validator) into the project-local, git-ignored
# .node/ folder, for tests/inference/outputs/test_gltf.py. Optional tooling: this script always exits 0, so a machine
# without npm or without network access still builds; the validator test then skips with a reason.
set -u

VERSION="2.0.0-dev.3.10"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PREFIX="$ROOT/.node"

if [ -f "$PREFIX/node_modules/gltf-validator/package.json" ] \
    && grep -q "\"version\": \"$VERSION\"" "$PREFIX/node_modules/gltf-validator/package.json"; then
    exit 0  # already installed: keep `make setup` fast and offline-friendly
fi
if ! command -v npm >/dev/null 2>&1; then
    echo "note: npm not found; gltf-validator not installed (the glTF validator test will be skipped)" >&2
    exit 0
fi
mkdir -p "$PREFIX"
# Short fetch timeout and one retry: an offline machine must not stall `make setup` for minutes.
if npm install --prefix "$PREFIX" --no-save --no-audit --no-fund --loglevel=error --silent \
    --fetch-retries=1 --fetch-timeout=30000 \
    "gltf-validator@$VERSION" >/dev/null; then
    echo "installed gltf-validator@$VERSION into .node/"
else
    echo "warning: npm could not install gltf-validator@$VERSION; the glTF validator test will be skipped" >&2
fi
exit 0
