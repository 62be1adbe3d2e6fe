"""Every example stage solves to the values stored in tests/golden (see golden_values.py)."""
from __future__ import annotations

import numpy as np
import pytest

from golden_values import GOLDEN, compare, load, numeric_values, solve_stage, stages


@pytest.mark.parametrize("stage", stages(), ids=lambda p: p.stem)
def test_example_stage_solves_to_the_stored_values(stage, tmp_path):
    stored_file = GOLDEN / f"{stage.stem}.npz"
    assert stored_file.exists(), f"no stored values for {stage.name}: run tests/golden_values.py --write"
    compare(numeric_values(solve_stage(stage, tmp_path)), load(stored_file), stage.stem)


def test_the_comparison_catches_a_change():
    stored = {"d|/A.x|default": np.array([1.0, 2.0]), "f|/A.q|sample 7": np.array([0.5])}
    compare({k: v.copy() for k, v in stored.items()}, stored, "same")
    with pytest.raises(AssertionError):
        compare({**stored, "d|/A.x|default": np.array([1.0, 2.0 + 1e-7])}, stored, "moved")
    with pytest.raises(AssertionError, match="fields differ"):
        compare({"d|/A.x|default": stored["d|/A.x|default"]}, stored, "missing")
