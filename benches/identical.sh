#!/usr/bin/env bash
# Renders every bundled and hazard scene with both backends (1 sample at
# the scene's size as 8-bit sRGB and as 16-bit linear, and 2x2 samples at
# 96x72, each with its G-buffer) into OUT, with the binary BIN. Run it with
# the binary before a change and the one after, then compare the two
# folders: a change that is meant to be bit-identical leaves no
# difference. 150 renders, about a minute.
#
#   benches/identical.sh BIN OUT
#   benches/identical.sh compare OUT_A OUT_B
#
# `compare` checks every file of the two folders: PNGs by their decoded
# samples (the compressor may differ, the pixels may not), the rest byte
# for byte; it prints each difference and exits 1 if there is one. It
# needs only python3's standard library.
set -euo pipefail
if [ "${1:-}" = compare ]; then
    exec python3 - "$2" "$3" <<'PY'
import os, struct, sys, zlib

def samples(path):
    """The unfiltered image data of a PNG (and its header): what it shows."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            ihdr = body
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    w, h, depth, color, _, _, interlace = struct.unpack(">IIBBBBB", ihdr)
    assert interlace == 0, path
    channels = {0: 1, 2: 3, 4: 2, 6: 4}[color]
    bpp = max(1, channels * depth // 8)
    stride = (w * channels * depth + 7) // 8
    raw = zlib.decompress(idat)
    out, prev = bytearray(), bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += line
        prev = line
    return ihdr, bytes(out)

a_dir, b_dir = sys.argv[1], sys.argv[2]
def files(d):
    return {os.path.relpath(os.path.join(r, f), d) for r, _, fs in os.walk(d) for f in fs}
fa, fb = files(a_dir), files(b_dir)
bad = sorted(fa ^ fb)
for rel in sorted(fa & fb):
    pa, pb = os.path.join(a_dir, rel), os.path.join(b_dir, rel)
    if rel.endswith(".png"):
        same = samples(pa) == samples(pb)
    else:
        same = open(pa, "rb").read() == open(pb, "rb").read()
    if not same:
        bad.append(rel)
for rel in bad:
    print("differs:", rel)
print(f"{len(fa & fb)} files compared, {len(bad)} differ")
sys.exit(1 if bad else 0)
PY
fi
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
        "$bin" render --backend "$backend" -o "$d/s1-srgb.png" "$scene" >/dev/null
        "$bin" render --backend "$backend" -o "$d/s2.png" --linear16 --size 96x72 --samples 2 --gbuffer "$d/g2" "$scene" >/dev/null
    done
done
