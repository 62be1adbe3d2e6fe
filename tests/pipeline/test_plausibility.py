"""The report's plausibility figures: agents measured together in batches, as one at a time."""
from __future__ import annotations

import numpy as np

from mocapedit.data import examples, walker
from mocapedit.pipeline import processor


def _figures(report) -> dict:
    return {path: (entry.plausibility.to_dict(), entry.foot_skate_source, entry.foot_skate_edited)
            for path, entry in report.agents.items() if entry.plausibility is not None}


def test_agents_measured_together_get_the_figures_of_each_measured_alone(tmp_path, monkeypatch):
    """Moved, re-timed and both (one agent left alone), of two clip lengths, with and without foot locking: batches of
    agents (forward kinematics stacked, one call of the job) report what batches of one do."""
    clips = [walker.walk(frames=72, fps=24.0, name="walk"), walker.turn(frames=96, fps=24.0, name="turn")]
    specs = [examples.AgentSpec(f"a{i}", clips[i % 2], (3.0 * i, 0.0, 0.0), 20.0 * i) for i in range(8)]
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", specs, up_axis="Y", fps=24.0,
                                       clips_dir=tmp_path / "clips")
    from mocapedit.usd import evaluate
    for i, spec in enumerate(specs):
        agent = f"/World/Crowd/{spec.name}"
        if i % 4 != 3:
            start, end = evaluate.agent_root_positions(stage, agent, [0, 60])
            examples.add_position_constraint(stage, f"/Edits/s{i}", agent, 0, tuple(map(float, start)))
            examples.add_position_constraint(stage, f"/Edits/m{i}", agent, 60,
                                             tuple(map(float, end + np.array([0.4 * (i - 4), 0.0, 0.6]))))
        if i % 3 != 1:
            examples.add_time_constraint(stage, f"/Edits/t{i}", agent, 40, 46.0 + i)
    stage.GetRootLayer().Save()
    path = str(tmp_path / "shot.usda")
    for foot_locking in (True, False):
        together = processor.solve(path, guides=False, collisions=False, foot_locking=foot_locking).report
        monkeypatch.setattr(processor, "PLAUSIBILITY_BATCH", 1)
        alone = processor.solve(path, guides=False, collisions=False, foot_locking=foot_locking).report
        monkeypatch.undo()
        assert len(_figures(together)) == 7  # a7 has no edit
        assert _figures(together) == _figures(alone)
        assert together.stats.plausibility.to_dict() == alone.stats.plausibility.to_dict()
