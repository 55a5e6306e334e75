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


def main() -> int:
    if len(sys.argv) < 4:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    out, paths = sys.argv[1], sys.argv[2:]
    files = [load_file(p) for p in paths]
    first = files[0]
    for path, f in zip(paths[1:], files[1:]):
        missing = sorted(k for k in set(first) ^ set(f) if not k.startswith("nelf."))
        if missing:
            print(f"{path}: tensors differ from {paths[0]}'s: {missing[:5]}", file=sys.stderr)
            return 1
    averaged = {}
    for name, tensor in first.items():
        if name.startswith("nelf."):
            for path, f in zip(paths[1:], files[1:]):
                if name in f and not np.array_equal(f[name], tensor):
                    print(f"{path}: {name} is {f[name]}, {paths[0]} says {tensor}", file=sys.stderr)
                    return 1
            averaged[name] = tensor
        elif tensor.dtype.kind == "f":
            for path, f in zip(paths[1:], files[1:]):
                if f[name].shape != tensor.shape:
                    print(f"{path}: {name} has shape {f[name].shape}, not {tensor.shape}", file=sys.stderr)
                    return 1
            averaged[name] = np.mean([f[name] for f in files], axis=0).astype(tensor.dtype)
        else:
            averaged[name] = tensor
    save_file(averaged, out)
    print(f"{out}: the mean of {len(paths)} weight files, {len(averaged)} tensors")
    return 0


if __name__ == "__main__":
    sys.exit(main())
