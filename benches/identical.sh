#!/usr/bin/env bash
# Renders every bundled and hazard scene with both backends (1 sample at
# the scene's size, and 2x2 samples at 96x72, each with its G-buffer) into
# OUT, with the binary BIN. Run it with the binary before a change and the
# one after, then `diff -r` the two folders: a change that is meant to be
# bit-identical leaves no difference. 100 render sets, about a minute.
#
#   benches/identical.sh BIN OUT
set -euo pipefail
bin=$1
out=$2
cd "$(dirname "$0")/.."
mkdir -p "$out"
for scene in scenes/*.toml tests/data/hazards/*.toml; do
    name=$(basename "$scene" .toml)
    for backend in raster ray; do
        d="$out/$name-$backend"
        mkdir -p "$d/g1" "$d/g2"
        "$bin" render --backend "$backend" -o "$d/s1.png" --linear16 --gbuffer "$d/g1" "$scene" >/dev/null
        "$bin" render --backend "$backend" -o "$d/s2.png" --linear16 --size 96x72 --samples 2 --gbuffer "$d/g2" "$scene" >/dev/null
    done
done
