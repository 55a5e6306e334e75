#!/usr/bin/env python3
"""Summary of `nelf eval network` scores on held-out heads, pooled over any number of runs.

    python3 scripts/heads_summary.py SCORES/network.json [MORE/network.json ...]

`scripts/eval_heldout_heads.sh` calls it on its own run; given the runs of several head
sets (the five test heads, `FIRST=6 COUNT=8`, ...) it pools their targets. Prints, per
head, foreground PSNR (8-bit sRGB, mean of its targets) of the network, its bake, the
ground-truth bake and the flat colour; the rule of the script (the bake beats the flat
colour on at least 4 in 5 of the heads and by at least 0.5 dB on their mean); the
share of the gap between the flat colour and the ground-truth bake that the network and
its bake close, on the mean over every target (the issue's aim), foreground and whole
image; with `--photos`, the same for the photographs' bake; mean ꟻLIP and SSIM of every
source beside the flat colour's (scores that carry them); and, for the bake's foreground share, the 5-95 % interval over 2,000 bootstrap
resamples of the heads (seed 0), so that a share near a threshold is read against the
spread of the heads. Runs with `--bakes-only` (no direct renders of the network) show
the network's column as "-" and leave it out of the shares. Exits 1 when the rule is
not met.
"""
import json
import random
import sys


def mean(rows, kind, key):
    """Mean of `kind`'s `key` over `rows`; None where a row has no `kind` (--bakes-only)."""
    if any(r[kind] is None for r in rows):
        return None
    return sum(r[kind][key] for r in rows) / len(rows)


def dB(value, width):
    return f"{value:{width}.2f}" if value is not None else f"{'-':>{width}}"


def share(rows, kind, key, flat_key):
    flat, truth, value = mean(rows, "network_bake", flat_key), mean(rows, "truth_bake", key), mean(rows, kind, key)
    return None if value is None else 100.0 * (value - flat) / (truth - flat)


def bootstrap_share(rows, groups, kind):
    """`kind`'s foreground share of the gap, with its 5-95 % interval over 2,000
    bootstrap resamples of the heads (`groups`, seed 0)."""
    draw = random.Random(0)
    shares = sorted(
        share([r for _ in groups for r in draw.choice(groups)], kind, "foreground_psnr", "flat_foreground_psnr")
        for _ in range(2000)
    )
    return (f"{share(rows, kind, 'foreground_psnr', 'flat_foreground_psnr'):.1f} %, "
            f"5-95 % bootstrap interval over the heads {shares[100]:.1f}-{shares[1899]:.1f} %")


def main(paths):
    rows = []
    for path in paths:
        rows += json.load(open(path))["rows"]
    if not rows:
        sys.exit(f"no scored targets in {', '.join(paths)}")
    heads = {}
    for r in rows:
        heads.setdefault(r["capture"], []).append(r)
    wins, margin = 0, 0.0
    print("head                      network   bake   truth bake   flat colour  (foreground PSNR, dB)")
    for capture, targets in heads.items():
        net, bake = mean(targets, "network", "foreground_psnr"), mean(targets, "network_bake", "foreground_psnr")
        truth, flat = mean(targets, "truth_bake", "foreground_psnr"), mean(targets, "network_bake", "flat_foreground_psnr")
        wins += bake > flat
        margin += (bake - flat) / len(heads)
        print(f"{capture:<24}  {dB(net, 7)}  {bake:6.2f}  {truth:10.2f}  {flat:11.2f}")
    ok = 5 * wins >= 4 * len(heads) and margin >= 0.5
    print(f"bake beats the flat colour on {wins} of {len(heads)} heads, by {margin:+.2f} dB on the mean: "
          + ("met" if ok else "not met"))
    for scope, key, flat_key in (("foreground", "foreground_psnr", "flat_foreground_psnr"), ("whole-image", "psnr", "flat_psnr")):
        net, net_share = mean(rows, "network", key), share(rows, "network", key, flat_key)
        net_text = f"network {net:.2f} ({net_share:.0f} % of the gap), " if net is not None else "network not rendered, "
        print(f"{scope} PSNR: {net_text}"
              f"bake {mean(rows, 'network_bake', key):.2f} ({share(rows, 'network_bake', key, flat_key):.0f} %), "
              f"flat colour {mean(rows, 'network_bake', flat_key):.2f}, ground-truth bake {mean(rows, 'truth_bake', key):.2f}")
    photos = all(r.get("photos_bake") for r in rows)
    if photos:
        for scope, key, flat_key in (("foreground", "foreground_psnr", "flat_foreground_psnr"), ("whole-image", "psnr", "flat_psnr")):
            print(f"{scope} PSNR of the photographs' bake: {mean(rows, 'photos_bake', key):.2f} "
                  f"({share(rows, 'photos_bake', key, flat_key):.1f} % of the gap)")
    if all("foreground_flip" in r["network_bake"] for r in rows):
        kinds = ["network", "network_bake", "truth_bake"] + (["photos_bake"] if photos else [])
        for scope, key in (("foreground", "foreground_flip"), ("whole-image", "flip")):
            values = ", ".join(
                f"{kind} {mean(rows, kind, key):.3f}" for kind in kinds if mean(rows, kind, key) is not None
            )
            print(f"{scope} mean FLIP (lower is better): {values}, "
                  f"flat colour {mean(rows, 'network_bake', 'flat_' + key):.3f}")
        print("SSIM: " + ", ".join(
            f"{kind} {mean(rows, kind, 'ssim'):.3f}" for kind in kinds if mean(rows, kind, "ssim") is not None
        ) + f", flat colour {mean(rows, 'network_bake', 'flat_ssim'):.3f}")
    if len(heads) > 1:
        groups = list(heads.values())
        print(f"the bake's foreground share over {len(heads)} heads ({len(rows)} targets): "
              + bootstrap_share(rows, groups, "network_bake"))
        if photos:
            print("the photographs' bake's foreground share: " + bootstrap_share(rows, groups, "photos_bake"))
    return 0 if ok else 1


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1:]))
