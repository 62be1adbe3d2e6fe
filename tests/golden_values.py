"""Stored results of every example stage: the values later changes must mean to change.

``python tests/golden_values.py --write`` solves every stage in ``example_stages/`` and stores
the numeric values of its edits layer in ``tests/golden/<stage>.npz``; the test compares a
fresh solve with them. Regenerate only when a change is meant to change the results, and
say so in the commit.

The files hold values, never bytes to compare: doubles are compared to 1e-9, floats to a
few units in the last place of a float and halves to theirs, so the test passes on any
x86-64 CPU. Time samples are kept every ``SAMPLE_STRIDE`` frames, which keeps the files
small and still catches any change of a solve (a solve moves every frame of an agent).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from pxr import Sdf

from layer_compare import layer_values

REPO = Path(__file__).resolve().parents[1]
STAGES = REPO / "example_stages"
GOLDEN = Path(__file__).resolve().parent / "golden"
SAMPLE_STRIDE = 11

# Relative tolerance by the precision the value is stored with in the layer.
RTOL = {"d": 1e-9, "f": 4 * np.finfo(np.float32).eps, "h": 4 * np.finfo(np.float16).eps}
ATOL = {"d": 1e-9, "f": 1e-6, "h": 1e-3}


def stages() -> list[Path]:
    return sorted(STAGES.glob("*.usda"))


def _precision(value) -> str:
    """'d', 'f' or 'h': the precision a USD value is stored with."""
    name = type(value).__name__
    if name.startswith(("Vec", "Quat", "Matrix", "Float", "Half", "Double")) or "Array" in name:
        core = name.replace("Array", "")
        if core.endswith("h") or core.startswith("Half"):
            return "h"
        if core.endswith("f") or core.startswith("Float"):
            return "f"
    return "d"


def _keep(field: str) -> bool:
    if not field.startswith("sample "):
        return True
    t = float(field.split(" ", 1)[1])
    return t == int(t) and int(t) % SAMPLE_STRIDE == 0


def numeric_values(layer: Sdf.Layer) -> dict[str, np.ndarray]:
    """{'<precision>|<path>|<field>': float64 array} for every numeric field kept."""
    out = {}
    for (path, field), value in layer_values(layer).items():
        if not _keep(field) or isinstance(value, (bool, str, Sdf.Path)) or value is None:
            continue
        try:
            array = np.array(value, dtype=np.float64)
        except (TypeError, ValueError):
            continue
        if array.dtype.kind != "f":
            continue
        out[f"{_precision(value)}|{path}|{field}"] = array
    return out


def solve_stage(stage: Path, out_dir: Path) -> Sdf.Layer:
    from mocapedit.pipeline import processor
    output = out_dir / f"{stage.stem}.edits.usdc"
    processor.solve(str(stage), output=str(output))
    return Sdf.Layer.FindOrOpen(str(output))


def save(path: Path, values: dict[str, np.ndarray]) -> None:
    """One flat array of values, with the keys and shapes beside it (small, one zip entry each)."""
    keys = sorted(values)
    np.savez_compressed(
        path, keys=np.array(keys), sizes=np.array([values[k].size for k in keys], np.int64),
        shapes=np.array(["x".join(map(str, values[k].shape)) for k in keys]),
        values=np.concatenate([values[k].ravel() for k in keys]) if keys else np.zeros(0))


def load(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as f:
        keys, sizes, shapes, flat = f["keys"], f["sizes"], f["shapes"], f["values"]
    out, start = {}, 0
    for key, size, shape in zip(keys, sizes, shapes):
        dims = tuple(int(d) for d in str(shape).split("x") if d)
        out[str(key)] = flat[start:start + size].reshape(dims)
        start += size
    return out


def compare(fresh: dict[str, np.ndarray], stored: dict[str, np.ndarray], name: str) -> None:
    """Asserts two value sets hold the same keys and values within their precisions."""
    missing, extra = sorted(set(stored) - set(fresh)), sorted(set(fresh) - set(stored))
    assert not missing and not extra, (
        f"{name}: fields differ (missing {missing[:3]}, new {extra[:3]})")
    for key, want in stored.items():
        got = fresh[key]
        assert got.shape == want.shape, f"{name} {key}: shape {got.shape}, stored {want.shape}"
        p = key[0]
        np.testing.assert_allclose(got, want, rtol=RTOL[p], atol=ATOL[p], err_msg=f"{name} {key}")


def main(argv=None) -> int:
    import tempfile
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="store the values (regenerate)")
    args = parser.parse_args(argv)
    if not args.write:
        parser.error("nothing to do: pass --write to regenerate tests/golden/")
    GOLDEN.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for stage in stages():
            values = numeric_values(solve_stage(stage, Path(tmp)))
            save(GOLDEN / f"{stage.stem}.npz", values)
            print(f"{stage.stem}: {len(values)} fields")
    return 0


if __name__ == "__main__":
    sys.exit(main())
