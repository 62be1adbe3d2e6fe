"""The edits layer's writer: agents with the same baked animation share one prim, and only those,
also when each agent's arrays are made as the writer reaches it (a streamed crowd: the writer may
keep nothing of an agent's arrays once it has written them)."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from pxr import Sdf

from mocapedit.model.data import Agent, StageInfo
from mocapedit.usd import writer

JOINTS = ["Hips", "Hips/Spine"]
TIMES = np.arange(4, dtype=np.float64)


def _agent(i: int) -> Agent:
    path = f"/World/agent_{i:02d}"
    return Agent(path=path, skeleton_path=f"{path}/Skel", animation_path=f"{path}/Skel/Anim", clip_key=("c",),
                 joints=JOINTS, parents=np.array([-1, 0]), rest_transforms=np.tile(np.eye(4), (2, 1, 1)),
                 anim_to_skel=np.array([0, 1]), sample_times=TIMES, skel_to_world=np.eye(4)[None],
                 agent_parent_to_world=np.eye(4)[None], xform_op_order=[], root_joint=0, hip_joint=0,
                 collision_radius=0.3, collision_height=1.8, collide=True, path_curve=None)


def _turn(i: int) -> float:
    """The angle agent i's spine is turned by: agents 0 and 1 alike, every other its own."""
    return 0.1 * max(i, 1)


class _Streamed(Mapping):
    """Each agent's edit made when asked for, in one buffer that the next agent's overwrites."""

    def __init__(self, count: int):
        self.paths = [_agent(i).path for i in range(count)]
        self.buffer = np.zeros((len(TIMES), len(JOINTS), 4), dtype=np.float32)

    def __getitem__(self, path):
        i = self.paths.index(path)
        rotations = self.buffer
        rotations[:] = 0.0
        rotations[..., 3] = 1.0
        rotations[:, 1, 0], rotations[:, 1, 3] = np.sin(_turn(i) / 2), np.cos(_turn(i) / 2)
        return writer.AgentEdit(animation=writer.BakedAnimation(joints=JOINTS, times=TIMES, translations=None,
                                                                rotations=rotations, scales=None))

    def __iter__(self):
        return iter(self.paths)

    def __len__(self):
        return len(self.paths)


def test_streamed_agents_share_an_animation_only_when_it_is_the_same():
    count = 12
    agents = {a.path: a for a in map(_agent, range(count))}
    info = StageInfo("Y", 1.0, 24.0, 0.0, 3.0, "in.usda", ["in.usda"])
    layer = writer.build_layer(writer.LayerContent(info=info, agents=agents, edits=_Streamed(count)))
    sources = []
    for i, agent in enumerate(agents.values()):
        rel = layer.GetRelationshipAtPath(f"{agent.skeleton_path}.skel:animationSource")
        target = rel.targetPathList.explicitItems[0]
        sources.append(target)
        spine = layer.QueryTimeSample(Sdf.Path(f"{target}.rotations"), 2.0)[1]
        assert abs(spine.GetImaginary()[0] - np.sin(_turn(i) / 2)) < 1e-6, agent.path
    assert sources[0] == sources[1]
    assert len(set(sources)) == count - 1
