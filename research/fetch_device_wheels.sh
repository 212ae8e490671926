#!/usr/bin/env bash
# Fetch into .whl/ (git-ignored) the wheels that research/gpu_check.sh needs on the lent GPU machine
# (kind nvidia-h200: Python 3.12, x86-64, torch 2.11, Lightning 2.6.6, cv2, numpy, PyYAML, …, and
# no network). These are the packages that `train.py experiment=paper` imports and that machine
# lacks (see /work/.library/device/KINDS.md), with the ones they need that it also lacks, at the
# versions of this checkout's .venv. Run it here, once; it skips wheels already in .whl/ and keeps
# one version per package (two would stop the install there). Prints the folder's size: the wheels
# travel with the working tree (64 MiB a call, carry: [".whl"]).
#
# There, before research/gpu_check.sh (the exact command is in that script's top comment):
#   python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
#       --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site || exit
set -euo pipefail
cd "$(dirname "$0")/.."
DEST=.whl

# Compiled (cp312 manylinux x86_64). numpy itself is there (2.5 in 2026-11); these were built
# against the numpy 2 ABI, which later 2.x releases keep.
BINARY=(
    "zstandard==0.25.0"   # brdfgan.data.storage.shards: the u16z shard members
    "kornia_rs==0.2.0"    # kornia's required native half
    "OpenEXR==3.5.3"      # brdfgan.io.images (imported by the data and training modules)
)
# Pure Python (py3-none-any).
PURE=(
    "hydra-core==1.3.8"   # train.py
    "omegaconf==2.3.1"    # hydra-core's, and ours
    "webdataset==1.0.2"   # brdfgan.data.loading.datamodule
    "braceexpand==0.1.7"  # webdataset's
    "kornia==0.9.0"       # brdfgan.data.materials.recolor, brdfgan.data.tools.statistics
)
# Published as an sdist only: built here into a py3-none-any wheel (omegaconf and hydra need 4.9.*).
SDIST=("antlr4-python3-runtime==4.9.3")

PLATFORMS=(
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64
    --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform manylinux1_x86_64
)
TARGET=(--only-binary=:all: --python-version 3.12 --implementation cp --abi cp312)

mkdir -p "$DEST"
shopt -s nullglob nocaseglob nocasematch  # wheel names keep the project's case or lower it, depending on the builder

# A pin's wheel-name prefix: PEP 427 escapes runs of "-", "_", "." in the name to one "_".
wheel_name() { echo "${1%%==*}" | sed -E 's/[-_.]+/_/g'; }
wheel_version() { echo "${1##*==}"; }

# True when the pin's wheel is there; removes any other version of the same package first.
present() {
    local name version file found=1
    name=$(wheel_name "$1")
    version=$(wheel_version "$1")
    for file in "$DEST/$name"-*.whl; do
        if [[ "$(basename "$file")" == "$name-$version-"* ]]; then
            found=0
        else
            echo "removing $(basename "$file"): not the pinned $1"
            rm -f -- "$file"
        fi
    done
    return $found
}

fetch() {  # pin, then pip's platform arguments
    local pin=$1
    shift
    if present "$pin"; then
        echo "have $pin"
        return
    fi
    echo "fetching $pin"
    python3 -m pip download -q --no-deps "${TARGET[@]}" "$@" -d "$DEST" "$pin"
}

for pin in "${BINARY[@]}"; do fetch "$pin" "${PLATFORMS[@]}"; done
for pin in "${PURE[@]}"; do fetch "$pin" --platform any; done
for pin in "${SDIST[@]}"; do
    if present "$pin"; then
        echo "have $pin"
    else
        echo "building $pin"
        .venv/bin/pip wheel -q --no-deps "$pin" -w "$DEST"
    fi
done

echo "wheels in $DEST/:"
ls -1 "$DEST"
du -sh "$DEST"
