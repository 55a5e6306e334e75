#!/usr/bin/env python3
"""Where a network bake's foreground error lies, per target: its level or its pattern.

After `nelf eval network CAPTURE... -o SCORES` (which writes SCORES/captureK_network.nelf
and captureK_truth.nelf), renders both bakes at every target of the captures with
`nelf render` (2x2 rays per pixel, as the scores) and prints, per target, in 8-bit sRGB
inside the true mask:

* the foreground PSNR of the network bake and of the ground-truth bake;
* the network bake's foreground PSNR once each channel is scaled to the target's true
  foreground mean (what fixing the level alone, not the pattern, would give);
* the share of the pixels, and of each bake's squared error, in the ring of pixels
  within 2 of the silhouette.

    pip install numpy scipy pillow OpenEXR
    python3 scripts/error_split.py SCORES CAPTURE...   (the captures in the eval's order)
"""
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR
from PIL import Image
from scipy import ndimage

NELF = Path(__file__).resolve().parent.parent / "target/release/nelf"


def read_rgb(path):
    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        if "RGB" in channels:
            return np.asarray(channels["RGB"].pixels, dtype=np.float64)
        return np.stack([np.asarray(channels[c].pixels, dtype=np.float64) for c in "RGB"], -1)


def srgb8(linear):
    x = np.clip(linear, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.round(x * 255.0) / 255.0


def psnr(sse, count):
    return 10.0 * np.log10(count / sse)


def main(scores, captures):
    print("target                                   net bake  truth bake  net, level fixed  ring px  ring share of SSE (net / truth)")
    with tempfile.TemporaryDirectory() as tmp:
        for k, capture in enumerate(captures):
            capture = Path(capture)
            for target in sorted((capture / "targets").glob("target_[0-9][0-9][0-9].exr")):
                name = target.stem
                mask = np.asarray(Image.open(capture / "targets" / f"{name}_mask.png").convert("L")) >= 128
                ring = mask & ~ndimage.binary_erosion(mask, iterations=2)
                want = srgb8(read_rgb(target))
                images = {}
                for kind in ("network", "truth"):
                    out = Path(tmp) / f"{k}_{name}_{kind}.exr"
                    subprocess.run(
                        [str(NELF), "render", str(Path(scores) / f"capture{k}_{kind}.nelf"),
                         "--view-of", f"{capture}:{name}",
                         "--envmap", str(capture / "lighting" / f"{name}.exr"),
                         "--pixel-grid", "2", "-o", str(out)],
                        check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                    images[kind] = read_rgb(out)
                count = 3 * mask.sum()
                sse = {kind: ((srgb8(im) - want) ** 2).sum(-1) for kind, im in images.items()}
                net = images["network"]
                level = read_rgb(target)[mask].mean(0) / np.maximum(net[mask].mean(0), 1e-12)
                fixed = ((srgb8(net * level) - want) ** 2).sum(-1)[mask].sum()
                shares = [sse[kind][ring].sum() / sse[kind][mask].sum() for kind in ("network", "truth")]
                print(f"{str(capture) + ':' + name:<40} {psnr(sse['network'][mask].sum(), count):8.2f}  "
                      f"{psnr(sse['truth'][mask].sum(), count):10.2f}  {psnr(fixed, count):16.2f}  "
                      f"{ring.sum() / mask.sum():7.2f}  {shares[0]:.2f} / {shares[1]:.2f}")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
