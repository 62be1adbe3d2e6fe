"""Input values that ask for more work than any machine has stop before the work, naming the property."""
from __future__ import annotations

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
