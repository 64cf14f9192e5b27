"""Generates the FLIP test pairs and their expected values.

The inputs are synthetic (drawn here, seeded); the expected values come from
the reference implementation of FLIP, NVlabs/flip v1.7 (BSD-3-Clause), run
through its Python bindings (`pip install flip-evaluator==1.7`, which
compiles the C++ FLIP.h). Run from this directory:

    python3 generate.py

Writes <name>.ref.png, <name>.test.png (8-bit sRGB), <name>.<ppd>.f32 (the
reference error map, little-endian f32, row-major from the top) and
shapes.default.magma.png (the tool's magma picture of that map),
expected.txt (one line per case: name ppd mean weighted_median q1 q3 min max,
the pooled values as the reference tool's `flip` command prints them).
"""

import re
import subprocess

import numpy as np
from PIL import Image
import flip_evaluator as flip

W, H = 64, 48
rng = np.random.default_rng(20200720)


def srgb8(lin):
    lin = np.clip(lin, 0.0, 1.0)
    s = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    return np.round(s * 255).astype(np.uint8)


def shapes():
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    ref = np.zeros((H, W, 3))
    ref[..., 0] = 0.1 + 0.8 * x / W
    ref[..., 1] = 0.2 + 0.6 * y / H
    ref[..., 2] = 0.5 + 0.3 * np.sin(x / 5.0)
    disc = (x - 20) ** 2 + (y - 20) ** 2 < 64
    ref[disc] = [0.9, 0.1, 0.1]
    ref[30:42, 40:56] = [0.05, 0.05, 0.6]
    checker = ((x.astype(int) // 2 + y.astype(int) // 2) % 2).astype(bool)
    patch = (x >= 4) & (x < 16) & (y >= 34) & (y < 46)
    ref[patch & checker] = [1.0, 1.0, 1.0]
    ref[patch & ~checker] = [0.0, 0.0, 0.0]
    test = ref.copy()
    disc2 = (x - 21) ** 2 + (y - 20) ** 2 < 64  # the disc moved one pixel
    test[disc & ~disc2] = ref[~disc][0]
    test[disc2] = [0.9, 0.1, 0.1]
    test[30:42, 40:56] = [0.05, 0.3, 0.6]  # the square's colour changed
    test[patch] = 0.5  # the checker blurred away
    test[2:14, 44:60] += rng.normal(0, 0.05, (12, 16, 3))  # noise
    return srgb8(ref), srgb8(test)


def noise():
    ref = rng.uniform(0, 1, (H, W, 3))
    test = np.clip(ref + rng.normal(0, 0.1, (H, W, 3)), 0, 1)
    return srgb8(ref), srgb8(test)


def pixel():
    ref = np.full((H, W, 3), 0.3)
    test = ref.copy()
    test[17, 40] = [0.8, 0.3, 0.3]
    return srgb8(ref), srgb8(test)


CASES = [("shapes", shapes, [None, 30.0]), ("noise", noise, [None]), ("pixel", pixel, [None])]

lines = []
for name, make, ppds in CASES:
    ref, test = make()
    Image.fromarray(ref).save(f"{name}.ref.png")
    Image.fromarray(test).save(f"{name}.test.png")
    for ppd in ppds:
        rf = flip.load(f"{name}.ref.png")
        tf = flip.load(f"{name}.test.png")
        err, mean, params = flip.evaluate(rf, tf, "LDR", inputsRGB=True, applyMagma=False, parameters={} if ppd is None else {"ppd": ppd})
        err = np.asarray(err, dtype=np.float32).reshape(H, W)
        tag = "default" if ppd is None else f"{ppd:g}"
        err.astype("<f4").tofile(f"{name}.{tag}.f32")
        out = subprocess.run(["flip", "-r", f"{name}.ref.png", "-t", f"{name}.test.png", "-v", "2", "-nerm"] + ([] if ppd is None else ["-ppd", str(ppd)]),
                             capture_output=True, text=True).stdout
        def grab(label):
            return float(re.search(label + r":\s*([0-9.eE+-]+)", out).group(1))
        vals = [grab("Mean"), grab("Weighted median"), grab("1st weighted quartile"), grab("3rd weighted quartile"), grab("Min"), grab("Max")]
        if name == "shapes" and ppd is None:  # the tool's magma picture of the map
            subprocess.run(["flip", "-r", f"{name}.ref.png", "-t", f"{name}.test.png", "-v", "0",
                            "-d", ".", "-b", f"{name}.{tag}.magma"], check=True)
        lines.append(f"{name} {tag} " + " ".join(f"{v:.6f}" for v in vals) + f" {mean:.9g}")
        print(lines[-1], repr(params["ppd"]))

with open("expected.txt", "w") as f:
    f.write("# name ppd mean weighted_median q1 q3 min max (flip tool, 6 decimals) mean (Python API, 9 digits)\n")
    f.write("\n".join(lines) + "\n")
