"""Counts specks in a bake's renders against the truth at a capture's targets, from the
8-bit sRGB PNG pairs `bake_eval ASSET CAPTURE --out DIR` writes (target_NNN_render.png,
target_NNN_truth.png). Needs numpy and Pillow.

    python3 scripts/speck_count.py DIR [DIR ...]

At least 3 px inside the truth's silhouette, a pixel is a *spurious speck* when the
bake's image deviates from the median of its own 5 x 5 neighbourhood by more than
T = 60 (sum of the RGB differences, 0..765) while the truth's deviates by less than T/3;
*dark* when it is also darker than the truth by more than T/3 in luminance; *coloured*
when its error is not shared by the three channels (more than T/2). The reverse, the
truth deviating and the bake not, is detail lost. docs/measurements/2026-12-07-specks.md.
"""

import glob
import sys

import numpy as np
from PIL import Image

T = 60.0
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def load(path):
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)


def deviation(image):
    """|image - median of its 5 x 5 neighbourhood|, summed over RGB."""
    pad = np.pad(image, ((2, 2), (2, 2), (0, 0)), mode="edge")
    window = np.stack([pad[i : i + image.shape[0], j : j + image.shape[1]] for i in range(5) for j in range(5)])
    return np.abs(image - np.median(window, axis=0)).sum(axis=2)


for folder in sys.argv[1:]:
    spurious = dark = coloured = lost = interior = 0
    renders = sorted(glob.glob(f"{folder}/target_*_render.png"))
    if not renders:
        sys.exit(f"{folder}: no target_*_render.png (run bake_eval ASSET CAPTURE --out {folder})")
    for render_path in renders:
        bake, truth = load(render_path), load(render_path.replace("_render", "_truth"))
        inside = truth.sum(axis=2) > 6
        for _ in range(3):
            inside &= np.roll(inside, 1, 0) & np.roll(inside, -1, 0) & np.roll(inside, 1, 1) & np.roll(inside, -1, 1)
        d_bake, d_truth = deviation(bake), deviation(truth)
        speck = inside & (d_bake > T) & (d_truth < T / 3)
        error = bake - truth
        chroma = np.abs(error - error.mean(axis=2, keepdims=True)).sum(axis=2)
        spurious += speck.sum()
        dark += (speck & (bake @ LUMINANCE < truth @ LUMINANCE - T / 3)).sum()
        coloured += (speck & (chroma > T / 2)).sum()
        lost += (inside & (d_truth > T) & (d_bake < T / 3)).sum()
        interior += inside.sum()
    print(f"{folder}: {len(renders)} targets, {interior} interior px; spurious specks {spurious} "
          f"(dark {dark}, coloured {coloured}); detail lost {lost}")
