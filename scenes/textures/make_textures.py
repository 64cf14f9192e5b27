#!/usr/bin/env python3
"""Generates the bundled textures (standard library only; deterministic).

Run from this folder: python3 make_textures.py
All images are RGB or RGBA (never greyscale: POV-Ray 3.7 misreads 8-bit
greyscale PNGs, POVRAY.md §9.2), without gAMA chunks, and are read as
linear values by rendiff and by POV-Ray with `gamma 1.0`.
"""
import math
import struct
import zlib


def png(path, w, h, rows, channels, depth):
    def chunk(kind, data):
        c = struct.pack(">I", len(data)) + kind + data
        return c + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    color_type = {3: 2, 4: 6}[channels]
    raw = b""
    for row in rows:
        raw += b"\x00"
        for px in row:
            for v in px:
                raw += struct.pack(">H", v) if depth == 16 else bytes([v])
    data = b"\x89PNG\r\n\x1a\n"
    data += chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, color_type, 0, 0, 0))
    data += chunk(b"IDAT", zlib.compress(raw, 9))
    data += chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(data)


def lcg(seed):
    state = seed
    while True:
        state = (state * 1103515245 + 12345) & 0x7FFFFFFF
        yield state


# checker.png: 64x64, 8x8 squares of two colours with a red/blue border row
# so orientation (uv origin bottom-left) is visible.
w = h = 64
rows = []
for y in range(h):
    row = []
    for x in range(w):
        if y == 0:
            row.append((230, 40, 40))          # top row red
        elif y == h - 1:
            row.append((40, 60, 230))          # bottom row blue
        elif ((x // 8) + (y // 8)) % 2 == 0:
            row.append((235, 225, 200))
        else:
            row.append((60, 110, 70))
    rows.append(row)
png("checker.png", w, h, rows, 3, 8)

# wood16.png: 48x32 16-bit rings, exercises 16-bit texels.
w, h = 48, 32
rows = []
for y in range(h):
    row = []
    for x in range(w):
        r = math.hypot(x - 10.5, y - 40.0)
        t = 0.5 + 0.5 * math.sin(r * 0.9)
        row.append((int(40000 + 20000 * t), int(22000 + 14000 * t), int(9000 + 6000 * t)))
    rows.append(row)
png("wood16.png", w, h, rows, 3, 16)

# leaf_alpha.png: 32x32 RGBA, a disc of opaque green fading to transparent.
w = h = 32
rows = []
for y in range(h):
    row = []
    for x in range(w):
        d = math.hypot(x - 15.5, y - 15.5) / 15.5
        a = 255 if d < 0.6 else max(0, int(255 * (1.0 - (d - 0.6) / 0.4)))
        row.append((50 + x * 3, 150 + y * 2, 60, a))
    rows.append(row)
png("leaf_alpha.png", w, h, rows, 4, 8)

# bumps.png: 64x64 height map (R = G = B), a grid of smooth domes.
w = h = 64
rows = []
for y in range(h):
    row = []
    for x in range(w):
        u = (x % 16) - 7.5
        v = (y % 16) - 7.5
        r = math.hypot(u, v) / 7.5
        hgt = max(0.0, 1.0 - r * r)
        g = int(round(255 * hgt))
        row.append((g, g, g))
    rows.append(row)
png("bumps.png", w, h, rows, 3, 8)

# noise.png: 32x16 random RGB (a sphere map whose seam and poles show).
w, h = 32, 16
rng = lcg(7)
rows = [[tuple(next(rng) % 256 for _ in range(3)) for _ in range(w)] for _ in range(h)]
png("noise.png", w, h, rows, 3, 8)
