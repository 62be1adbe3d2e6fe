"""The solver's thread budget (``MOCAPEDIT_THREADS``, :mod:`mocapedit.solve.threads`): how many
threads its jobs may use changes how fast they run, never what they produce."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from pxr import Sdf

from mocapedit.data import examples, walker
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.processor import solve
from mocapedit.solve import avoidance, threads

from conftest import run_cli


def _crossing_stage(path, agents: int = 100):
    """Walkers crossing at random, dense enough for every job to split its work (avoidance
    over 100 x 240 samples, legs locked for tens of agents), one of them bent by a handle."""
    rng = np.random.default_rng(7)
    clips = [walker.walk(frames=240, fps=24.0, speed=1.4 * s, phase=p, name=f"walk{k}")
             for k, (s, p) in enumerate(((0.9, 0.0), (1.1, 0.5)))]
    side = np.sqrt(agents / 0.25)
    specs = [examples.AgentSpec(f"agent_{i:03d}", clips[i % 2],
                                (float(rng.uniform(0, side)), 0.0, float(rng.uniform(0, side))),
                                float(rng.uniform(-180.0, 180.0)), float(rng.integers(0, 12)))
             for i in range(agents)]
    stage = examples.build_crowd_stage(path, specs, fps=24.0, clips_dir=path.parent / "clips")
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings",
                               attributes={"collisionAvoidance": (Sdf.ValueTypeNames.Bool, True)})
    examples.add_position_constraint(stage, "/Edits/handle", "/World/Crowd/agent_000", 120,
                                     (float(specs[0].position[0]) + 1.0, 0.0, float(specs[0].position[2])))
    stage.GetRootLayer().Save()


def test_one_thread_or_two_write_the_same_bytes(tmp_path, budget):
    shot = tmp_path / "shot.usda"
    _crossing_stage(shot)
    layers = []
    for n in (1, 2):
        budget(n)
        assert threads.budget() == n
        out = tmp_path / f"edits{n}.usdc"
        result = solve(str(shot), output=str(out), guides=False)
        assert result.report.stats["collisionsPerIteration"][0] > 20, "the crowd must need avoidance"
        assert result.report.stats.get("footLockedAgents", 0) > 5
        layers.append(out.read_bytes())
    assert layers[0] == layers[1]


def test_avoidance_of_a_dense_crowd_is_the_same_on_one_thread(budget):
    paths = examples.dense_crowd_paths(150, 240, 24.0, 0.25, seed=2)
    problem = avoidance.Problem(names=[f"a{i}" for i in range(len(paths))], paths=paths,
                                frame_times=[np.arange(240.0)] * len(paths), radius=np.full(len(paths), 0.3),
                                height=np.full(len(paths), 1.8), margin=0.05)
    outcomes = []
    for n in (2, 1):
        budget(n)
        outcomes.append(avoidance.resolve(problem, avoidance.Settings()))
    assert outcomes[0].solves > 1 and not outcomes[0].remaining
    for a, b in zip(outcomes[0].paths, outcomes[1].paths):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("text", ["0", "-2", "two", "1.5", "100000"])
def test_a_thread_budget_that_is_not_a_count_of_threads_is_a_clear_error(text, toy_stage, tmp_path, monkeypatch):
    with pytest.raises(MocapEditError, match="MOCAPEDIT_THREADS"):
        threads.check_environment({"MOCAPEDIT_THREADS": text})
    monkeypatch.setenv("MOCAPEDIT_THREADS", text)
    proc = run_cli("solve", toy_stage, "-o", tmp_path / "out.usda")
    assert proc.returncode == 1
    assert "MOCAPEDIT_THREADS" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "out.usda").exists()
    with pytest.raises(MocapEditError, match="MOCAPEDIT_THREADS"):
        solve(str(toy_stage))


def test_a_thread_budget_in_the_environment_is_taken(toy_stage, tmp_path, monkeypatch):
    assert threads.check_environment({}) is None and threads.check_environment({"MOCAPEDIT_THREADS": " "}) is None
    assert threads.check_environment({"MOCAPEDIT_THREADS": "2"}) == 2
    monkeypatch.setenv("MOCAPEDIT_THREADS", "1")
    proc = run_cli("solve", toy_stage, "-o", tmp_path / "out.usda")
    assert proc.returncode == 0, proc.stderr
    # The solver reads it as the process first asks for its budget.
    for text in ("1", "3"):
        child = subprocess.run([sys.executable, "-c", "from mocapedit.solve import threads; print(threads.budget())"],
                               capture_output=True, text=True, env={**os.environ, "MOCAPEDIT_THREADS": text})
        assert child.stdout.strip() == text, child.stderr
