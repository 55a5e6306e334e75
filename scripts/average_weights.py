#!/usr/bin/env python3
"""Uniform average of several NeLF weight files (stochastic weight averaging,
Izmailov et al., "Averaging Weights Leads to Wider Optima and Better
Generalization", UAI 2018): every float tensor is the mean of the inputs'; the
`nelf.*` record tensors (working image size, source-relative light, shading
prior) are taken from the first file and must agree in all of them.

    python3 scripts/average_weights.py OUT W1 W2 [W3 ...]

The inputs must be checkpoints of one run (same architecture, same tensor names).
Needs `pip install numpy safetensors`.
"""
import sys

import numpy as np
from safetensors.numpy import load_file, save_file


def check_agrees(first, other):
    """What keeps `other` from being averaged with `first`, or None: the same tensor
    names and shapes (the `nelf.*` records may be missing from either, but where both
    have one it must be equal)."""
    names = sorted(k for k in set(first) ^ set(other) if not k.startswith("nelf."))
    if names:
        return f"tensors differ: {names[:5]}"
    for name, tensor in first.items():
        if name not in other:
            continue
        if name.startswith("nelf."):
            if not np.array_equal(other[name], tensor):
                return f"{name} is {other[name]}, not {tensor}"
        elif other[name].shape != tensor.shape:
            return f"{name} has shape {other[name].shape}, not {tensor.shape}"
    return None


def main() -> int:
    if len(sys.argv) < 4:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    out, paths = sys.argv[1], sys.argv[2:]
    files = [load_file(p) for p in paths]
    first = files[0]
    for path, f in zip(paths[1:], files[1:]):
        problem = check_agrees(first, f)
        if problem:
            print(f"{path}: {problem} (against {paths[0]})", file=sys.stderr)
            return 1
    averaged = {
        name: np.mean([f[name] for f in files], axis=0).astype(tensor.dtype)
        if tensor.dtype.kind == "f" and not name.startswith("nelf.")
        else tensor
        for name, tensor in first.items()
    }
    save_file(averaged, out)
    print(f"{out}: the mean of {len(paths)} weight files, {len(averaged)} tensors")
    return 0


if __name__ == "__main__":
    sys.exit(main())
