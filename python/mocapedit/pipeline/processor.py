"""The processor: read a stage, build and run the solves, author the edits layer.

``solve()`` is the Python API behind ``mocapedit solve``. It never modifies the input;
it returns the edits as a new (anonymous) Sdf layer, saved atomically when ``output`` is
given, plus a :class:`~mocapedit.model.report.Report`.

The solve runs the passes of :data:`mocapedit.pipeline.passes.PASSES`, in order, over a
shared :class:`~mocapedit.pipeline.context.SolveContext`. Each pass reads the source data and
what earlier passes produced (edited paths, time maps, pose edits) and adds its own;
``compose_edits`` turns the result into what the writer authors. A pass does its numerical
work through :mod:`mocapedit.solve` and numpy.
"""
from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from mocapedit.geometry import animation, trajectory
from mocapedit.pipeline import guides, memory
from mocapedit.pipeline.context import EditedPath, SolveContext, SolveOptions  # noqa: F401 (the API's names)
from mocapedit.pipeline.passes import PASSES
from mocapedit.pipeline.passes.path import on_curve
from mocapedit.inspect import inspection, metrics
from mocapedit.model import limits
from mocapedit.solve import threads
from mocapedit.usd import outputs, reader, stage_io, writer
from mocapedit.usd.stage_io import content_hash  # noqa: F401 (batches compare it before solving)
from mocapedit.model.errors import MocapEditError
from mocapedit.model.data import StageData
from mocapedit.model.progress import Progress, Silent
from mocapedit.model.report import AgentPlausibility, Report, ShotPlausibility


def extract_trajectories(ctx: SolveContext) -> None:
    info = ctx.data.info
    task = ctx.progress.task("trajectories", len(ctx.data.agents))
    cache: dict = {}
    for i, (path, agent) in enumerate(ctx.data.agents.items()):
        ctx.trajectories[path] = trajectory.extract(agent, ctx.data.clip_of(agent), info.up_axis,
                                                    info.meters_per_unit, cache)
        task.update(i + 1)
    task.done()


def compose_edits(ctx: SolveContext, parents_at=None) -> None:
    """Turns edited paths, time maps and pose edits into what the writer authors.

    The pose is the source sampled at the (warped) source frame of each output time, then
    modified by the pose edits in order (layering); the edited path carries the whole body
    by one rigid ground motion per output time (the prepended xform op). The poses themselves
    are baked as the writer reaches each agent (:class:`EditsToWrite`): a crowd's baked poses
    are never all in memory at once.

    ``parents_at(path, times)``: an agent's parent-to-world transforms at stage times (read
    from the stage), for re-timed agents under a moving parent.
    """
    up = ctx.data.info.up_axis
    for path in ctx.touched():
        agent, traj = ctx.data.agents[path], ctx.trajectories[path]
        times, frames = ctx.output_frames(path)
        edit = writer.AgentEdit()
        clip = ctx.data.clip_of(agent)
        spec = ctx.retimed_spec(path) or ctx.rotations_spec(path)
        lowered = None
        if spec:
            # The source clip plays on the agent's timing (its own, or the time map), nothing
            # of it is baked but the rotations pose edits change (:func:`baked_animation`) ...
            edit.retimed = writer.RetimedClip(
                layer=spec[0], prim_path=spec[1], joints=list(clip.joints),
                stage_times=ctx.time_maps.get(path, agent.sample_times), clip_times=clip.spec_times)
            # ... and a lowered body is carried by the agent's transform.
            for pose_edit in ctx.pose_edits.get(path, []):
                if pose_edit.drop is not None:
                    lowered = pose_edit.drop if lowered is None else lowered + pose_edit.drop
        edited = ctx.paths.get(path)
        # An animated transform on the agent prim itself (crowd tools put the walk's ground
        # motion there) plays at shot time while a re-timed clip plays its source time: the
        # edit op then stands for it, the prim's transform at each output frame's source time.
        retimed = path in ctx.time_maps
        own_ops = retimed and agent.own_transform is not None
        # Likewise a moving parent plays at shot time: the op carries the body from where the
        # parent is then to where it was at the source time.
        moving_parent = retimed and agent.agent_parent_to_world.shape[0] > 1 and parents_at is not None
        if retimed and agent.inner_transform_animated:
            ctx.report.agent(path).add_notes(
                "a prim between it and its skeleton has an animated transform, which plays at shot time while the "
                "re-timed clip plays its source time: put that motion on the agent prim itself or in the clip to "
                "re-time it too")
        if spec:
            # The ops also at every whole shot frame between the re-timed clip's samples: USD
            # interpolates a translate and a turn about the parent's origin each on its own, so
            # between samples a frame or two apart an agent far from that origin strayed off
            # its path (18 cm within one frame, 55 m out, turning 7 degrees between samples).
            times, frames, lowered = _with_whole_frames(times, frames, lowered)
        # Untimed agents are written at their own frames: nothing to interpolate.
        whole = len(frames) == len(traj.ground) and np.array_equal(frames, np.arange(len(frames)))
        at = (lambda values: values) if whole else (lambda values: animation.interp_frames(values, frames))
        if retimed and agent.skeleton_transform is not None:
            # The skeleton prim's own animated ops too: its transform at each output frame's
            # source time.
            edit.times = times
            edit.skeleton_ops = trajectory.xform_ops(at(agent.skeleton_transform), up)
        if edited is not None or lowered is not None or own_ops or moving_parent:
            moved = edited if edited is not None else traj
            motion = trajectory.ground_motion(at(traj.ground), at(traj.heading), at(moved.ground),
                                              at(moved.heading), up)
            if lowered is not None:
                motion = motion @ trajectory.lowering(lowered, up)
            # A path moved by less than a nanometre is not an edit: only its timing is written.
            if lowered is not None or ctx.moved(path) or own_ops or moving_parent:
                edit.times = times
                parent = agent.agent_parent_to_world
                if parent.shape[0] > 1:  # a moving parent, sampled per source frame
                    agent_view = _with_parent(agent, animation.interp_frames(parent, frames))
                else:
                    agent_view = agent
                op = trajectory.agent_xform_op(agent_view, motion,
                                               parents_at(path, times) if moving_parent else None)
                if own_ops:
                    op = at(agent.own_transform) @ op
                    edit.replaces_ops = True
                edit.xform_ops = trajectory.xform_ops(op, up)
        if edit.retimed is not None or edit.xform_ops or edit.skeleton_ops or _baked(ctx, path, spec):
            ctx.edits[path] = edit


def _with_whole_frames(times: np.ndarray, frames: np.ndarray, lowered: np.ndarray | None):
    """(times, frames, lowered) sampled also at every whole stage frame between the first and the
    last of ``times`` (a re-timed clip's samples, (T,) increasing), the fractional source frame
    at each as the value clip maps it (linearly between its samples), and ``lowered`` (T,) or None
    likewise."""
    times = np.asarray(times, dtype=np.float64)
    if len(times) < 2:
        return times, frames, lowered
    whole = np.arange(np.ceil(times[0] - 1e-9), np.floor(times[-1] + 1e-9) + 1.0)
    at = np.searchsorted(times, whole)
    near = np.minimum(np.abs(whole - times[np.maximum(at - 1, 0)]), np.abs(whole - times[np.minimum(at, len(times) - 1)]))
    dense = np.union1d(times, whole[near > 1e-6])
    if len(dense) == len(times):
        return times, frames, lowered
    return (dense, np.interp(dense, times, frames),
            None if lowered is None else np.interp(dense, times, lowered))


def _baked(ctx: SolveContext, path: str, spec) -> bool:
    """Whether the agent's pose is baked: the rotations its pose edits change over its re-timed
    clip (``spec``), or, with no re-timed clip, its whole warped or edited pose."""
    return path in ctx.pose_edits if spec else (path in ctx.time_maps or path in ctx.pose_edits)


def baked_animation(ctx: SolveContext, path: str) -> writer.BakedAnimation | None:
    """The agent's baked pose (see :func:`compose_edits`), None when nothing of it is baked."""
    spec = ctx.retimed_spec(path) or ctx.rotations_spec(path)
    if not _baked(ctx, path, spec):
        return None
    times, frames = ctx.output_frames(path)
    pose = animation.sample_pose(ctx.data.clip_of(ctx.data.agents[path]), frames)
    for pose_edit in ctx.pose_edits.get(path, []):
        pose = pose_edit.apply(pose, times, frames)
    if spec:  # the rotations alone, over the re-timed source
        return writer.BakedAnimation(joints=pose.joints, times=times, translations=None,
                                     rotations=pose.rotations, scales=None)
    return writer.BakedAnimation(joints=pose.joints, times=times, translations=pose.translations,
                                 rotations=pose.rotations, scales=pose.scales)


class EditsToWrite(Mapping):
    """The composed edits as the writer reads them: each agent's with its baked pose, computed
    when the writer asks for it and dropped once written."""

    def __init__(self, ctx: SolveContext):
        self._ctx = ctx

    def __getitem__(self, path: str) -> writer.AgentEdit:
        edit = self._ctx.edits[path]
        baked = baked_animation(self._ctx, path)
        return edit if baked is None else dataclasses.replace(edit, animation=baked)

    def __iter__(self):
        return iter(self._ctx.edits)

    def __len__(self) -> int:
        return len(self._ctx.edits)


#: Agents whose plausibility is measured together (bounds the memory of a large crowd's arrays).
PLAUSIBILITY_BATCH = 64


@dataclass
class _Measured:
    """One agent of :func:`measure_plausibility`: what its figures are measured from."""
    path: str
    chain: np.ndarray            # (F, J, 4, 4) skeleton-space facing joint, then the feet if measured here
    times: np.ndarray            # (T,) stage times of the edited samples
    frames: np.ndarray           # (T,) source frame each plays
    skate: list                  # [source, edited] foot skate, NaN when measured here or without feet


def measure_plausibility(ctx: SolveContext) -> None:
    """Per edited agent, and for the shot (``stats.plausibility``), the figures of
    :func:`metrics.plausibility_of`: the facing and walking direction of the edited body against
    its source, path length, time warp and foot skate. They come from the same motions the edits
    layer authors, by numpy forward kinematics of the hip and the feet (the composed stage plays
    the same, so FK on it gives the same figures); layered poses are left out. Agents with as
    many source and edited samples are measured together (:func:`metrics.plausibilities_of`)."""
    chains, groups = {}, {}

    def chain(agent, feet: bool) -> np.ndarray:
        """(F, J, 4, 4) skeleton-space facing joint, then the feet when asked, of a clip and skeleton."""
        key = (agent.clip_key, tuple(agent.joints), feet)
        if key not in chains:
            joints = [metrics.default_facing_joint(agent.joints)]
            joints += metrics.default_foot_joints(agent.joints) if feet else []
            clip = ctx.data.clip_of(agent)
            chains[key] = np.stack([trajectory.joint_skel_space(agent, clip, j) for j in joints], axis=1)
        return chains[key]

    for path in sorted(ctx.edits):
        if path not in ctx.paths and path not in ctx.time_maps:
            continue
        agent = ctx.data.agents[path]
        entry = ctx.report.agent(path)
        skate = [float("nan"), float("nan")]
        if entry.foot_skate_unlocked is not None:  # foot locking measured the legs as the layer plays them
            skate = [entry.foot_skate_source, entry.foot_skate_edited]
        times, frames = ctx.output_frames(path)
        item = _Measured(path, chain(agent, entry.foot_skate_unlocked is None), times, frames, skate)
        groups.setdefault((item.chain.shape, len(times)), []).append(item)
    figures = {}
    for items in groups.values():
        for first in range(0, len(items), PLAUSIBILITY_BATCH):
            figures.update(_measure_plausibility(ctx, items[first:first + PLAUSIBILITY_BATCH]))
    for path, (p, skate, frames) in figures.items():
        if ctx.data.agents[path].path_curve and path in ctx.paths:
            figures[path] = (dataclasses.replace(p, max_turn_off_curve=_turn_off_curve(ctx, path, frames)),
                             skate, frames)
    for path in sorted(figures):
        record_plausibility(ctx.report.agent(path), *figures[path])
    if figures:
        ordered = [figures[path][0] for path in sorted(figures)]
        ctx.report.stats.plausibility = ShotPlausibility.from_dict(metrics.worst_plausibility(ordered))


def _turn_off_curve(ctx: SolveContext, path: str, frames: np.ndarray) -> float:
    """Degrees: the largest turn of the agent's edited root path off the way its path curve
    draws it (:func:`metrics.edit_turn`), over the source frames ``frames`` played in the shot."""
    info, agent = ctx.data.info, ctx.data.agents[path]
    first = int(np.clip(np.floor(frames.min() + 1e-9), 0, agent.frame_count - 1))
    end = int(np.clip(np.ceil(frames.max() - 1e-9), first, agent.frame_count - 1)) + 1
    if end - first < 2:
        return 0.0
    turn = metrics.edit_turn(on_curve(ctx, path).ground[first:end], ctx.paths[path].ground[first:end],
                             agent.sample_times[first:end] / info.time_codes_per_second,
                             metrics.WALKING_SPEED_M / info.meters_per_unit)
    return float(np.degrees(np.max(np.abs(turn))))


def record_plausibility(entry, p: metrics.Plausibility, skate, frames: np.ndarray) -> None:
    """An agent's report entry gets its figures ``p``, its foot skate [source, edited] when
    measured (and not measured before) and its worst frames as source frames (``frames``: the
    source frame each edited sample plays)."""
    if np.isfinite(skate).all():
        # Mean foot speed while in contact (stage units per second), over the source's contacts.
        if entry.foot_skate_source is None:
            entry.foot_skate_source = skate[0]
        if entry.foot_skate_edited is None:
            entry.foot_skate_edited = skate[1]
    entry.plausibility = AgentPlausibility(
        max_facing_rate=p.max_facing_rate, source_max_facing_rate=p.source_max_facing_rate,
        max_extra_facing_rate=p.max_extra_facing_rate, spin_frames=p.spin_frames,
        max_direction_deviation=p.max_direction_deviation,
        max_turned_direction_deviation=p.max_turned_deviation, max_edit_turn=p.max_edit_turn,
        max_turn_off_curve=p.max_turn_off_curve if np.isfinite(p.max_turn_off_curve) else None,
        reverses=p.reverses, length_ratio=p.length_ratio,
        time_warp=list(p.time_warp), foot_skate_ratio=p.foot_skate_ratio,
        worst_turn_frame=int(round(frames[max(p.worst_turn_frame, 0)])),
        worst_direction_frame=int(round(frames[p.worst_direction_frame])) if p.worst_direction_frame >= 0 else -1)


def _measure_plausibility(ctx: SolveContext, items: list[_Measured]) -> dict:
    """{path: (Plausibility, [source, edited] foot skate, frames)} of agents whose chains and
    edited samples have the same shapes, by forward kinematics of them all at once."""
    info = ctx.data.info
    up, agents = info.up_axis, [ctx.data.agents[item.path] for item in items]
    parents = [agent.skel_to_world for agent in agents]
    frame_count = items[0].chain.shape[0]
    if any(len(parent) > 1 for parent in parents):  # a moving parent, per source frame
        parents = [np.broadcast_to(parent, (frame_count, 4, 4)) for parent in parents]
    source = np.stack([item.chain for item in items]) @ np.stack(parents)[:, :, None]   # (A, F, J, 4, 4)
    times = np.stack([item.times for item in items])
    frames = np.stack([item.frames for item in items])
    # A moved agent that plays its source frame by frame is carried from the source samples
    # themselves when all of the batch do (interpolating at whole frames gives the same values
    # but for the sign of zeros); the others are interpolated at their frames, as the layer plays them.
    whole = (frames == np.arange(frames.shape[1])).all(axis=1) & (frames.shape[1] == frame_count)
    moved = np.array([item.path in ctx.paths for item in items])
    edited = source.copy() if whole.all() else animation.interp_frames(source, frames)
    if whole.all() and not moved.all():   # the agents not moved: as the layer's timing plays them
        rows = np.flatnonzero(~moved)
        edited[rows] = animation.interp_frames(source[rows], frames[rows])
    if moved.any():
        rows = np.flatnonzero(moved) if not moved.all() else slice(None)
        carried = [items[k].path for k in np.flatnonzero(moved)]
        trajs, paths = [ctx.trajectories[p] for p in carried], [ctx.paths[p] for p in carried]

        def at(values):
            values = np.stack(values)
            return values if whole[rows].all() else animation.interp_frames(values, frames[rows])
        edited[rows] = edited[rows] @ trajectory.ground_motion(
            at([t.ground for t in trajs]), at([t.heading for t in trajs]),
            at([p.ground for p in paths]), at([p.heading for p in paths]), up)[:, :, None]
    seconds = 1.0 / info.time_codes_per_second
    skate = np.array([item.skate for item in items], dtype=np.float64)       # (A, 2)
    # (A, T) the edited samples that play in the shot: the figures are of what is seen.
    shot = np.stack([metrics.in_shot(item.times, info.start_time, info.end_time) for item in items])
    if source.shape[2] > 1:
        units = (up, info.meters_per_unit, info.time_codes_per_second)
        # A retimed agent against its source as its timing plays it (see the feet pass).
        same = np.array([times.shape[1] == len(agent.sample_times) and np.allclose(item.times, agent.sample_times)
                         for item, agent in zip(items, agents)])
        feet = source[:, :, 1:, 3, :3]
        played = feet if same.all() else animation.interp_frames(feet, frames)
        if same.any() and not same.all():
            played[same] = feet[same]
        contact = metrics.foot_skate_of_positions(played, times, *units).contact & shot[:, :, None]
        before = metrics.foot_skate_of_positions(played, times, *units, contact=contact)
        after = metrics.foot_skate_of_positions(edited[:, :, 1:, 3, :3], times, *units, contact=contact)
        skate = np.stack([before.mean, after.mean], axis=1)
    # Each agent over the samples that play in the shot, against the source frames they play.
    windows = [metrics.shot_window(keep, item.frames, len(agent.sample_times)) for keep, item, agent
               in zip(shot, items, agents)]
    figures = metrics.plausibilities_of(
        [item.path for item in items], [agent.sample_times[f0:f1] * seconds for agent, (f0, f1) in zip(agents, windows)],
        [source[k, f0:f1, 0] for k, (f0, f1) in enumerate(windows)],
        [times[k][keep] * seconds for k, keep in enumerate(shot)], [edited[k][keep, 0] for k, keep in enumerate(shot)],
        up, info.meters_per_unit, skate[:, 0], skate[:, 1],
        edited_frames=[frames[k][keep] - f0 for k, (keep, (f0, _)) in enumerate(zip(shot, windows))])
    return {item.path: (p, [float(v) for v in s], item.frames[keep])
            for item, p, s, keep in zip(items, figures, skate, shot)}


def _with_parent(agent, parent_to_world):
    return dataclasses.replace(agent, agent_parent_to_world=parent_to_world)


def inspect(ctx: SolveContext) -> None:
    """After every pass: the report figures no pass measured, and the guides."""
    crowd = inspection.from_context(ctx)
    remaining = inspection.complete_report(ctx, crowd)
    guides.build(ctx, crowd, remaining)


def options_text(guides: bool = True, collisions: bool | None = None, bake_timing: bool = False,
                 **overrides) -> str:
    """The solve options as the edits layer records them (``customLayerData`` mocapedit
    ``options``): compact JSON with sorted keys, so a re-run can tell whether an existing
    output was made with the same options."""
    import json
    options = dict(overrides, guides=guides, collisions=collisions, bake_timing=bake_timing)
    return json.dumps(options, sort_keys=True, separators=(",", ":"))


@dataclass
class SolveResult:
    layer: object                 # the edits layer (an Sdf.Layer)
    report: Report
    data: StageData


def _left_as_authored(paths: list[str], noun: str, which: str) -> str:
    """"2 skeletons without X are left as authored (<a>, <b>)": the count and the first three."""
    many = len(paths) > 1
    return (f"{len(paths)} {noun}{'s' if many else ''} {which} {'are' if many else 'is'} left as authored ("
            + ", ".join(f"<{r}>" for r in paths[:3]) + (", ..." if len(paths) > 3 else "") + ")")


def solve(stage_or_path, output: str | None = None, composed: str | None = None,
          guides: bool = True, collisions: bool | None = None, progress: Progress | None = None,
          report_json: str | None = None, bake_timing: bool = False, components=None,
          **overrides) -> SolveResult:
    """Solves every edit authored on a stage and returns the edits layer and a report.

    Args:
      stage_or_path: a ``Usd.Stage`` or the path of a stage file. The input is read only.
      output: if given, the edits layer is saved there (``.usda`` or ``.usdc``), atomically.
      composed: if given (needs ``output``), a stage that sub-layers the edits over the input.
      report_json: if given (needs ``output``), the report is saved there as JSON. The edits, the composed stage
        and the report are renamed into place together, after all three are written.
      guides: author guide geometry under ``/MocapEdit/Guides``.
      collisions: force collision avoidance on or off; None follows MocapSolveSettings.
      progress: a :class:`~mocapedit.model.progress.Progress`; silent by default.
      bake_timing: bake agents whose only edit is timing into SkelAnimation samples instead
        of re-timing their source clips with value clips (the same motion, a larger layer).
      components: a :class:`~mocapedit.pipeline.context.ComponentPool` that solves the path
        pass's independent components and locks the feet elsewhere (Dask workers); the result
        is the same bytes.
      overrides: MocapSolveSettings values by their Python names (``max_iterations=...``).

    Raises:
      MocapEditError: bad input, naming the prim and property; an output path that names
        the input, a layer it uses, another output or a folder. Nothing is written.
    """
    if progress is not None and not isinstance(progress, Progress):
        raise MocapEditError(f"progress is a {type(progress).__name__}; give a mocapedit.model.progress.Progress "
                             f"(or None for silence)")
    progress = progress or Silent()
    overrides = {k: v.item() if isinstance(v, np.generic) else v for k, v in overrides.items()}   # numpy scalars
    for name, value, none_ok in (("guides", guides, False), ("bake_timing", bake_timing, False),
                                 ("collisions", collisions, True)):
        if not (isinstance(value, (bool, np.bool_)) or (none_ok and value is None)):
            raise MocapEditError(f"solve({name}={value!r}): must be True or False" + (" (or None)" if none_ok else ""))
    guides, bake_timing = bool(guides), bool(bake_timing)
    collisions = None if collisions is None else bool(collisions)
    if components is not None and not (hasattr(components, "map") and isinstance(getattr(components, "chunks", None), int)):
        raise MocapEditError(f"solve(components={components!r}): give a ComponentPool (see "
                             "mocapedit.pipeline.batch.DaskComponents) or None")
    threads.check_environment()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    source = stage_io.open_input(stage_or_path)
    stage, input_name, input_file = source.stage, source.name, source.file
    if (composed or report_json) and not output:
        raise MocapEditError("a composed stage or a report needs an output path for the edits layer (-o)")
    if composed and not input_file:
        raise MocapEditError("a composed stage sub-layers the input file, but this stage is in memory; "
                             "save it first or leave out the composed stage")
    if composed and source.unsaved:
        raise MocapEditError(f"a composed stage sub-layers {input_file}, but the stage has unsaved changes the "
                             "solve would see and the composed stage would not; save it first or leave out the "
                             "composed stage")
    outputs.check_outputs([outputs.Output(output, "edits layer"),
                           outputs.Output(composed, "composed stage"),
                           outputs.Output(report_json, "report", kind="text", extensions=(".json",))],
                          outputs.input_files(stage))

    data = reader.read_stage(stage, progress)
    limits.check_overrides(data.settings, overrides)
    limits.check_settings(data)
    limits.check_constraint_times(data)
    limits.check_constraint_positions(data)
    limits.check_region_sizes(data)
    timings["read"] = time.perf_counter() - t0

    report = Report(input=input_name, output=output)
    if not data.agents and not data.skel_roots_without_agent and not data.point_instanced_agents:
        report.note("the stage has no agents: no SkelRoot or Skeleton prim on it, and none with MocapAgentAPI; "
                    "check that this is the shot you meant")
    if data.skel_roots_without_agent:
        report.note(_left_as_authored(data.skel_roots_without_agent, "skeleton", "without MocapAgentAPI")
                    + "; apply MocapAgentAPI to the SkelRoot or Skeleton prim of each agent to edit "
                    "it (`mocapedit import-bvh --agent` writes clips that have it)")
    for note in reader.clip_unit_notes(data):
        report.note(note)
    if data.point_instanced_agents:
        report.note(_left_as_authored(data.point_instanced_agents, "agent", "inside a PointInstancer")
                    + ": a prototype plays at the instancer's points, which cannot be edited one by one; "
                    "make each instance an agent of its own to edit it")
    ctx = SolveContext(data=data, options=SolveOptions(guides=guides, collisions=collisions,
                                                       overrides=overrides, bake_timing=bake_timing,
                                                       components=components),
                       report=report, progress=progress)
    t = time.perf_counter()
    extract_trajectories(ctx)
    timings["trajectories"] = time.perf_counter() - t
    for solve_pass in PASSES:
        t = time.perf_counter()
        solve_pass.run(ctx)
        memory.give_back()
        timings[solve_pass.name] = time.perf_counter() - t
    t = time.perf_counter()
    compose_edits(ctx, lambda path, times: reader.parent_to_world_at(stage, path, times))
    timings["compose"] = time.perf_counter() - t
    t = time.perf_counter()
    inspect(ctx)
    timings["inspect"] = time.perf_counter() - t
    t = time.perf_counter()
    measure_plausibility(ctx)
    memory.give_back()
    timings["plausibility"] = time.perf_counter() - t

    constraint_count = sum(len(x) for x in (data.position_constraints, data.relative_constraints,
                                            data.time_constraints, data.sync_constraints))
    # The passes' own run-wide figures (collisionIterations, ...) are kept beside these.
    stats = report.stats
    stats.agents, stats.edited_agents, stats.clips = len(data.agents), len(ctx.edits), len(data.clips)
    stats.constraints, stats.groups = constraint_count, len(data.groups)
    stats.avoid_regions, stats.animation_layers = len(data.avoid_regions), len(data.layers)
    for path, traj in ctx.trajectories.items():
        entry = report.agent(path)
        if entry.frames is None:
            entry.frames = int(len(traj.ground))
        if entry.edited is None:
            entry.edited = path in ctx.edits
        if traj.projected_hip and entry.trajectory_joint is None:
            entry.trajectory_joint = data.agents[path].joints[traj.joint]

    t = time.perf_counter()
    provenance = stage_io.provenance(stage, options_text(guides, collisions, bake_timing, **overrides))
    layer = writer.build_layer(writer.LayerContent(
        info=data.info, agents=data.agents, edits=EditsToWrite(ctx), guides=ctx.guides,
        provenance=provenance, stats=report.stats.to_dict(), report=report.to_layer_dict(),
        anchor=os.path.dirname(os.path.abspath(output)) if output else None))
    # The layer holds the edits now: their arrays (10,000 moved agents: 250 MB of transforms)
    # go before USD's exporter allocates its own buffers.
    ctx.release()
    memory.give_back()
    if output:
        timings["write"] = time.perf_counter() - t
        timings["total"] = time.perf_counter() - t0
        report.timings = dict(timings)
        with outputs.Writes() as w:
            w.add(output, writer.export_layer(layer))
            if composed:
                w.add(composed, writer.export_layer(writer.composed_layer(
                    composed, output, input_file, data.info, source.default_prim)))
            if report_json:
                w.add(report_json, outputs.write_text(report.to_json() + "\n"))
    timings["write"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    report.timings = timings
    return SolveResult(layer=layer, report=report, data=data)
