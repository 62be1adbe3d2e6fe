"""The report's typed entries: JSON keys written once, absent figures left out, unknown keys kept."""
from __future__ import annotations

import json

import pytest

from mocapedit.model.report import (AgentEntry, AgentPlausibility, ConstraintEntry, Report, ShotPlausibility,
                                    Stats, format_text, StoredReport)


def _report() -> Report:
    r = Report(input="in.usda", output="out.usda")
    r.stats.agents, r.stats.edited_agents, r.stats.remaining_overlaps = 2, 1, 0
    r.stats.plausibility = ShotPlausibility(agents=1, length_ratio_range=(1.0, 1.2), time_warp_range=(1.0, 1.0))
    entry = r.agent("/a")
    entry.frames, entry.edited, entry.length_ratio = 10, True, 1.2
    entry.add_notes("moved")
    entry.plausibility = AgentPlausibility(spin_frames=0, time_warp=[1.0, 1.0])
    r.agent("/b").frames = 10
    r.constraints.append(ConstraintEntry(prim="/c", kind="position", agent="/a", frame=3, hard=True,
                                         residual=0.0, met=True, position=[1.0, 2.0, 3.0]))
    r.constraints.append(ConstraintEntry(prim="/S", kind="collision", agent="/a", frame=4, target="/b",
                                         target_frame=4, residual=0.1, met=False, time=4.0,
                                         held_by_constraints=False))
    return r


def test_entries_write_their_json_keys_and_leave_out_what_is_not_measured():
    d = _report().to_layer_dict()
    assert d["agents"]["/b"] == {"frames": 10}
    assert d["agents"]["/a"] == {"frames": 10, "edited": True, "lengthRatio": 1.2, "notes": ["moved"],
                                 "plausibility": {"spinFrames": 0, "timeWarp": [1.0, 1.0]}}
    # A constraint always names its target (None when it has none), never a collision's figures.
    assert d["constraints"][0] == {"prim": "/c", "kind": "position", "agent": "/a", "frame": 3, "target": None,
                                   "targetFrame": None, "hard": True, "residual": 0.0, "met": True,
                                   "position": [1.0, 2.0, 3.0]}
    assert d["constraints"][1]["heldByConstraints"] is False and d["constraints"][1]["time"] == 4.0
    assert d["stats"]["remainingOverlaps"] == 0 and "collisionIterations" not in d["stats"]
    assert d["stats"]["plausibility"]["maxDirectionDeviationAgent"] is None   # always written


def test_a_report_reads_back_the_same_json_unknown_keys_included():
    d = json.loads(json.dumps(_report().to_dict()))
    d["agents"]["/a"]["futureFigure"] = [1, 2]
    d["stats"]["futureCount"] = 3
    d["constraints"][0]["futureFlag"] = True
    d["agents"]["/b"]["footSkateSource"] = None        # a figure that was not finite is stored as null
    back = Report.from_dict(d)
    assert isinstance(back.agents["/a"], AgentEntry) and isinstance(back.agents["/a"].plausibility, AgentPlausibility)
    assert isinstance(back.stats, Stats) and isinstance(back.stats.plausibility, ShotPlausibility)
    assert back.agents["/a"].extra == {"futureFigure": [1, 2]}
    assert back.agents["/b"].foot_skate_source is None and "footSkateSource" not in back.agents["/b"]
    assert json.loads(json.dumps(back.to_dict())) == d


def test_entries_answer_by_their_stored_keys_as_the_json_does():
    r = _report()
    a, c = r.agents["/a"], r.constraints[1]
    assert a["lengthRatio"] == a.length_ratio == 1.2 and "lengthRatio" in a
    assert "minSeparation" not in a and a.get("minSeparation", -1.0) == -1.0
    with pytest.raises(KeyError):
        a["minSeparation"]
    assert c.get("met", True) is False and c["targetFrame"] == 4
    a["solver"] = "LDLT"
    a["somethingNew"] = 1
    assert a.solver == "LDLT" and a.extra == {"somethingNew": 1}
    assert Stats.keys_of("edited_agents", "plausibility") == ["editedAgents", "plausibility"]


def test_format_text_lists_figures_it_has_no_words_for():
    r = _report()
    r.agents["/a"].delay = 1.5
    r.stats.plausibility = r.agents["/a"].plausibility = None
    text = format_text(StoredReport(file="e.usda", report=r))
    assert "delay 1.5" in text and "length ratio 1.2" in text
    assert "/c          position   3      -       0         hard      yes" in text
    assert "/S          collision  4      /b@4    0.1       soft      NO" in text


@pytest.mark.parametrize("unknown", [float("nan"), None], ids=["as solved", "read back from a layer"])
def test_walking_figures_of_a_shot_where_no_moved_source_walks_read_as_such(unknown):
    # Agents that only stand or shuffle have no walking direction: solve has NaN, the layer null.
    r = _report()
    p = r.stats.plausibility
    p.max_extra_facing_rate, p.max_extra_turn_per_frame_at_60fps, p.max_extra_facing_rate_agent = 0.0, 0.0, "/a"
    p.spinning_agents, p.reversing_agents, p.mean_length_ratio = 0, 0, 1.1
    p.max_direction_deviation = p.max_turned_direction_deviation = unknown
    p.max_edit_turn, p.mean_foot_skate_ratio, p.max_foot_skate_ratio = 0.0, 1.0, 1.0
    r.agents["/a"].plausibility.max_direction_deviation = unknown
    text = format_text(StoredReport(file="e.usda", report=Report.from_dict(json.loads(json.dumps(r.to_dict())))
                                    if unknown is None else r))
    assert "nan" not in text.lower()
    assert "no walking direction to compare" in text


def test_the_shot_lines_say_one_agent_in_the_singular():
    from mocapedit.model.report import ShotPlausibility, Stats, foot_locking_lines, plausibility_lines
    stats = Stats(foot_contacts_locked=1, foot_locked_agents=1)
    assert "legs locked on 1 agent;" in foot_locking_lines(stats)[0] and "1 contact;" in foot_locking_lines(stats)[0]
    assert plausibility_lines(ShotPlausibility(agents=1))[0].startswith("plausibility of 1 moved agent:")
