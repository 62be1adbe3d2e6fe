"""Input values that ask for more work than any machine has stop before the work, naming the property."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf

from mocapedit.data import examples, walker
from mocapedit.model import limits
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.processor import solve


@pytest.fixture
def crowd(tmp_path):
    clip = walker.walk(frames=48, name="walk")
    specs = [examples.AgentSpec(f"a{i}", clip, (3.0 * i, 0.0, 0.0), 0.0) for i in range(3)]
    return examples.build_crowd_stage(tmp_path / "shot.usda", specs)


def _settings(stage, **values):
    types = {"sampleStep": Sdf.ValueTypeNames.Double, "maxIterations": Sdf.ValueTypeNames.Int}
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings", attributes={
        "collisionAvoidance": (Sdf.ValueTypeNames.Bool, True),
        **{k: (types[k], v) for k, v in values.items()}})


def test_a_tiny_sample_step_is_refused_with_the_step_that_would_do(crowd):
    _settings(crowd, sampleStep=1e-7)
    with pytest.raises(MocapEditError, match=r"</Edits/settings>\.sampleStep: .*use at least") as info:
        solve(crowd)
    least = float(str(info.value).rsplit(" ", 1)[-1])
    _settings(crowd, sampleStep=least)
    assert sum(47.0 / least + 1 for _ in range(3)) <= limits.MAX_SAMPLES


def test_endless_iterations_are_refused(crowd):
    _settings(crowd, maxIterations=10**9)
    with pytest.raises(MocapEditError, match=r"</Edits/settings>\.maxIterations"):
        solve(crowd)
    with pytest.raises(MocapEditError, match=r"maxIterations"):
        solve(crowd, max_iterations=limits.MAX_ITERATIONS + 1)


@pytest.mark.parametrize("key, value, needle", [
    ("sample_step", 0, r"solve\(sample_step=0\): must be positive"),          # ZeroDivisionError
    ("sample_step", -1.0, r"solve\(sample_step=-1\.0\): must be positive"),   # IndexError
    ("sample_step", float("nan"), r"sample_step=nan\): must be a finite number"),
    ("max_wait", float("nan"), r"max_wait=nan\): must be a finite number of seconds"),  # from the C++ solver
    ("max_wait", -1.0, r"max_wait=-1\.0\): must be a finite number of seconds, 0 or more"),  # solved silently
    ("max_iterations", "10", r"max_iterations='10'\): must be a whole number"),      # TypeError
    ("margin", -0.5, r"margin=-0\.5\): must not be negative"),
    ("min_time_interval", 2.0, r"min_time_interval=2\.0\): must be in \(0, 1\]"),
    ("foot_locking", "yes", r"foot_locking='yes'\): must be True or False"),
    ("speed", 1.0, r"unknown solve setting 'speed'"),
])
def test_solve_keyword_settings_are_held_to_the_prims_rules(crowd, key, value, needle):
    """``solve(max_wait=...)`` and the other settings by keyword skipped the checks a
    MocapSolveSettings prim gets, and failed later with unrelated exceptions, or not at all."""
    with pytest.raises(MocapEditError, match=needle):
        solve(crowd, collisions=True, **{key: value})


@pytest.mark.parametrize("time", [1e308, -1e12])
def test_a_time_beyond_any_shot_is_refused(crowd, time):
    examples.add_time_constraint(crowd, "/Edits/t", "/World/Crowd/a0", 20, time)
    with pytest.raises(MocapEditError, match=r"</Edits/t>\.time: .* is beyond"):
        solve(crowd)


def test_a_clip_stretched_over_ages_is_refused_naming_its_constraints(crowd):
    examples.add_time_constraint(crowd, "/Edits/start", "/World/Crowd/a1", 0, 0.0)
    examples.add_time_constraint(crowd, "/Edits/end", "/World/Crowd/a1", 47, 5e7)
    with pytest.raises(MocapEditError, match=r"</Edits/start>, </Edits/end> stretch </World/Crowd/a1>"):
        solve(crowd)


@pytest.mark.parametrize("kwargs, needle", [
    ({"guides": "no"}, r"solve\(guides='no'\): must be True or False"),        # "no" is truthy: guides were written
    ({"collisions": "yes"}, r"solve\(collisions='yes'\): must be True or False \(or None\)"),
    ({"bake_timing": "x"}, r"solve\(bake_timing='x'\): must be True or False"),
    ({"components": 3}, r"solve\(components=3\): give a ComponentPool"),     # AttributeError deep in the path pass
])
def test_solve_keywords_of_the_wrong_kind_are_refused(crowd, kwargs, needle):
    with pytest.raises(MocapEditError, match=needle):
        solve(crowd, **kwargs)


def test_numpy_numbers_are_numbers_to_the_keyword_settings(crowd):
    """``max_iterations=np.int64(5)`` was refused as not a whole number, then failed writing the
    layer's provenance; numpy's numbers are taken as Python's."""
    result = solve(crowd, collisions=np.True_, guides=np.False_, bake_timing=np.False_,
                   max_iterations=np.int64(5), margin=np.float32(0.05))
    assert result.report.stats.agents == 3


def test_the_report_is_written_as_json_and_a_stage_with_unsaved_changes_gets_no_composed_stage(crowd, tmp_path):
    """A report file named .usda got JSON; and a stage on disk with unsaved changes was solved with
    them while its composed stage sub-layered the file without them (the solve's constraints
    missing from what it wrote)."""
    crowd.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"report .*r\.usda: this file is written as \.json"):
        solve(crowd, output=str(tmp_path / "e.usda"), report_json=str(tmp_path / "r.usda"))
    examples.add_time_constraint(crowd, "/Edits/t", "/World/Crowd/a0", 20, 25.0)   # not saved
    with pytest.raises(MocapEditError, match=r"the stage has unsaved changes .*save it first"):
        solve(crowd, output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert not (tmp_path / "e.usda").exists() and not (tmp_path / "c.usda").exists()
    solve(crowd, output=str(tmp_path / "e.usda"))          # without a composed stage it is solved as it is


def test_a_region_is_held_to_the_limit_on_the_fields_its_shape_uses(crowd):
    """A box region that also authors a radius (a circle's field, unused) is not refused for it;
    a circle whose radius is 1e12 m is."""
    examples.define_mocap_prim(crowd, "/Edits/box", "MocapAvoidRegion", attributes={
        "shape": (Sdf.ValueTypeNames.Token, "box"), "size": (Sdf.ValueTypeNames.Double3, (1.0, 1.0, 1.0)),
        "radius": (Sdf.ValueTypeNames.Double, 1e12)})
    solve(crowd)
    crowd.GetPrimAtPath("/Edits/box").GetAttribute("shape").Set("circle")
    with pytest.raises(MocapEditError, match=r"</Edits/box>\.radius: 1e\+12 stage units is more than 1e\+08 m"):
        solve(crowd)
