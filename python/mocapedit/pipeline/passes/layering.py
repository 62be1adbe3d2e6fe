"""Animation layers (MocapAnimationLayer), blended or added on a joint subtree.

Each layer prim applies to the agents of its ``agents`` relationship; the layers of one
agent stack in stage order. Layering happens in each joint's local space on the
time-warped source pose (the pose at every output time of the agent, after the time pass)
and before the path edit, whose rigid ground motion then carries the layered body: the
result equals sampling the warped source, layering it, then moving it by hand.

Only agents whose pose actually changes get a pose edit. Agents that play the same clip
on the same skeleton at the same times under the same layers share one computation, and
the writer authors one baked animation for them all.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit.geometry import animation
from mocapedit.solve import layering
from mocapedit.pipeline.context import SolveContext


@dataclass
class LayeredPose:
    """The pose edit of an agent's layers: its stack of layers applied at the output times."""
    plan: layering.AgentLayers

    def apply(self, pose: animation.Pose, out_times: np.ndarray, src_frames: np.ndarray) -> animation.Pose:
        return self.plan.apply(pose, out_times)


def check_layers(ctx: SolveContext) -> None:
    """Before any other pass: every layer's weights, and its joint and clip against the
    skeleton of each of its agents, so a bad layer stops the solve before the work."""
    data = ctx.data
    checked = set()
    for layer in data.layers:
        layering.check_weights(layer)
        for agent_path in layer.agents:
            agent = data.agents[agent_path]
            key = (layer.path, agent.skeleton_path)
            if key not in checked:
                checked.add(key)
                layering.resolve_layer(agent, layer, data.clips[layer.clip_key])


def run(ctx: SolveContext) -> None:
    data = ctx.data
    if not data.layers:
        return
    stacks: dict[str, list] = {}
    for layer in data.layers:
        if not layer.agents:
            ctx.report.note(f"layer <{layer.path}> has no agents: it changes nothing")
        for agent_path in layer.agents:
            stacks.setdefault(agent_path, []).append(layer)

    plans: dict[tuple, layering.AgentLayers] = {}
    poses: dict[tuple, animation.Pose] = {}
    deltas: dict = {}
    layered = samples = 0
    task = ctx.progress.task("layering", len(stacks))
    for i, agent_path in enumerate(sorted(stacks)):
        agent, layers = data.agents[agent_path], stacks[agent_path]
        source = data.clip_of(agent)
        key = (tuple(layer.path for layer in layers), agent.clip_key, tuple(agent.joints),
               agent.parents.tobytes(), agent.rest_transforms.tobytes())
        plan = plans.get(key)
        if plan is None:
            plan = plans[key] = layering.plan_agent(
                agent, source, [(layer, data.clips[layer.clip_key]) for layer in layers], deltas)
        times, frames = ctx.output_frames(agent_path)
        entry = ctx.report.agent(agent_path)
        notes = entry.add_notes()
        for p in plan.layers:
            notes.append(f"layer <{p.layer.path}>: {p.describe()}")
        pose_key = (agent.clip_key, frames.tobytes())
        pose = poses.get(pose_key)
        if pose is None:  # unwarped agents of one clip all play frames 0, 1, ...: one pose
            pose = poses[pose_key] = animation.sample_pose(source, frames)
        if plan.changes(pose, times):
            ctx.pose_edits.setdefault(agent_path, []).append(LayeredPose(plan))
            layered += 1
            samples += len(times) * sum(len(p.pose_columns) for p in plan.layers)
        else:
            notes.append("layers leave the pose unchanged: not written")
        task.update(i + 1)
    task.done()
    ctx.report.stats.layered_agents = layered
    ctx.report.stats.layered_joint_samples = samples

