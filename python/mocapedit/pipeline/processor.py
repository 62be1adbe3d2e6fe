"""The processor: read a stage, build and run the solves, author the edits layer.

``solve()`` is the Python API behind ``mocapedit solve``. It never modifies the input;
it returns the edits as a new (anonymous) Sdf layer, saved atomically when ``output`` is
given, plus a :class:`~mocapedit.model.report.Report`.

The solve runs as a list of passes over a shared :class:`SolveContext`. Each pass reads
the source data and what earlier passes produced (edited paths, time maps, layered
poses) and adds its own; ``compose_edits`` turns the result into what the writer
authors. A pass does its numerical work through :mod:`mocapedit._solver` and numpy.
"""
from __future__ import annotations

import hashlib
import os
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from pxr import Sdf, Usd, Vt

from mocapedit.geometry import animation, trajectory
from mocapedit.pipeline import guides
from mocapedit.inspect import inspection, metrics
from mocapedit.model import limits
from mocapedit.usd import outputs, reader, writer
from mocapedit.model.errors import MocapEditError
from mocapedit.model.data import StageData
from mocapedit.model.progress import Progress, Silent
from mocapedit.model.report import Report


@dataclass
class EditedPath:
    """An agent's edited ground path, one row per source frame."""
    ground: np.ndarray            # (F,2)
    heading: np.ndarray           # (F,)


@dataclass
class SolveOptions:
    guides: bool = True
    collisions: bool | None = None     # None: follow MocapSolveSettings.collisionAvoidance
    overrides: dict = field(default_factory=dict)  # settings overrides by python field name
    # Bake time-only edits into SkelAnimation samples instead of re-timing the source clip
    # with value clips (the two play the same motion; the baked form is the reference).
    bake_timing: bool = False


@dataclass
class SolveContext:
    data: StageData
    options: SolveOptions
    report: Report
    progress: Progress
    trajectories: dict[str, trajectory.Trajectory] = field(default_factory=dict)
    # Spatial edits: the edited ground path per source frame.
    paths: dict[str, EditedPath] = field(default_factory=dict)
    # Time edits: the shot time at which each source frame plays, (F,) increasing.
    time_maps: dict[str, np.ndarray] = field(default_factory=dict)
    # Pose edits (layering), applied in order to the time-warped source pose:
    # fn(pose, out_times (T,), src_frames (T,)) -> Pose.
    pose_edits: dict[str, list[Callable]] = field(default_factory=dict)
    # Output times chosen by a pass for an agent (else whole shot frames for a time map,
    # the clip's own samples otherwise).
    out_times: dict[str, np.ndarray] = field(default_factory=dict)
    edits: dict[str, writer.AgentEdit] = field(default_factory=dict)   # what the writer authors
    guides: list = field(default_factory=list)


Pass = Callable[[SolveContext], None]

#: The solve passes as (order, name, fn), run in ascending order. Each module of
#: ``mocapedit.pipeline.passes`` registers its own with ``register_pass`` when imported. Orders in
#: use: 100 path edits, 200 time warp, 300 collision avoidance, 400 layering.
PASSES: list[tuple[float, str, Pass]] = []


def register_pass(order: float, name: str, fn: Pass) -> None:
    """Adds (or replaces, by name) a solve pass."""
    PASSES[:] = [p for p in PASSES if p[1] != name]
    PASSES.append((order, name, fn))
    PASSES.sort(key=lambda p: (p[0], p[1]))


def load_passes() -> None:
    """Imports every module of ``mocapedit.pipeline.passes`` so each registers its pass."""
    import importlib
    import pkgutil

    from mocapedit.pipeline import passes
    for info in sorted(pkgutil.iter_modules(passes.__path__), key=lambda m: m.name):
        importlib.import_module(f"{passes.__name__}.{info.name}")


def extract_trajectories(ctx: SolveContext) -> None:
    info = ctx.data.info
    task = ctx.progress.task("trajectories", len(ctx.data.agents))
    cache: dict = {}
    for i, (path, agent) in enumerate(ctx.data.agents.items()):
        ctx.trajectories[path] = trajectory.extract(agent, ctx.data.clip_of(agent), info.up_axis,
                                                    info.meters_per_unit, cache)
        task.update(i + 1)
    task.done()


def retimed_spec(ctx: SolveContext, path: str) -> tuple[str, str] | None:
    """(clip layer, prim path) when the agent's only change of pose is its timing and its clip
    can be re-timed by a value clip (one spec's samples, in a layer on disk); None when it is
    baked instead (layered, ``bake_timing``, a clip split over specs or only in memory)."""
    if ctx.options.bake_timing or path not in ctx.time_maps or path in ctx.pose_edits:
        return None
    if any(path in layer.agents for layer in ctx.data.layers):
        return None
    clip = ctx.data.clip_of(ctx.data.agents[path])
    spec = clip.sample_spec
    if spec is None or clip.spec_times is None or Sdf.Layer.IsAnonymousLayerIdentifier(spec[0]):
        return None
    return spec


def output_frames(ctx: SolveContext, path: str, baked: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(stage times to author, fractional source frame at each) for one agent.

    ``baked``: the times its animation has when baked, even if it is re-timed by a value clip
    now (a pass that is about to give it a pose edit, which bakes it, asks for these)."""
    agent = ctx.data.agents[path]
    frames = np.arange(agent.frame_count, dtype=np.float64)
    time_map = ctx.time_maps.get(path)
    if time_map is None:
        times = ctx.out_times.get(path, agent.sample_times)
        return times, np.interp(times, agent.sample_times, frames)
    if not baked and retimed_spec(ctx, path):
        # A re-timed clip plays each source frame at its time on the map: those are its samples.
        return np.asarray(time_map, dtype=np.float64), frames
    times = ctx.out_times.get(path)
    if times is None:
        # A baked warped clip is authored on the shot's whole frames.
        times = np.arange(np.ceil(time_map[0] - 1e-9), np.floor(time_map[-1] + 1e-9) + 1.0)
    return times, np.interp(times, time_map, frames)


def compose_edits(ctx: SolveContext) -> None:
    """Turns edited paths, time maps and pose edits into what the writer authors.

    The pose is the source sampled at the (warped) source frame of each output time, then
    modified by the pose edits in order (layering); the edited path carries the whole body
    by one rigid ground motion per output time (the prepended xform op).
    """
    up = ctx.data.info.up_axis
    touched = sorted(set(ctx.paths) | set(ctx.time_maps) | set(ctx.pose_edits))
    for path in touched:
        agent, traj = ctx.data.agents[path], ctx.trajectories[path]
        times, frames = output_frames(ctx, path)
        edit = writer.AgentEdit()
        clip = ctx.data.clip_of(agent)
        spec = retimed_spec(ctx, path)
        if spec:
            # Only the timing changed: the source clip plays on the time map, nothing is baked.
            edit.retimed = writer.RetimedClip(layer=spec[0], prim_path=spec[1], joints=list(clip.joints),
                                              stage_times=ctx.time_maps[path], clip_times=clip.spec_times)
        elif path in ctx.time_maps or path in ctx.pose_edits:
            pose = animation.sample_pose(clip, frames)
            for fn in ctx.pose_edits.get(path, []):
                pose = fn(pose, times, frames)
            edit.animation = writer.BakedAnimation(
                joints=pose.joints, times=times, translations=pose.translations,
                rotations=pose.rotations, scales=pose.scales)
        edited = ctx.paths.get(path)
        if edited is not None:
            # Untimed agents are written at their own frames: nothing to interpolate.
            whole = len(frames) == len(traj.ground) and np.array_equal(frames, np.arange(len(frames)))
            at = (lambda values: values) if whole else (lambda values: animation.interp_frames(values, frames))
            motion = trajectory.ground_motion(at(traj.ground), at(traj.heading), at(edited.ground),
                                              at(edited.heading), up)
            # A path moved by less than a nanometre (numerical noise of a solve that had nothing
            # to do) is not an edit: the agent is not written.
            still = 1e-9 / ctx.data.info.meters_per_unit
            if (np.abs(edited.ground - traj.ground).max(initial=0.0) > still
                    or np.abs(edited.heading - traj.heading).max(initial=0.0) > 1e-9):
                edit.times = times
                parent = agent.agent_parent_to_world
                if parent.shape[0] > 1:  # a moving parent, sampled per source frame
                    agent_view = _with_parent(agent, animation.interp_frames(parent, frames))
                else:
                    agent_view = agent
                edit.xform_op = trajectory.agent_xform_op(agent_view, motion)
        if edit.animation is not None or edit.retimed is not None or edit.xform_op is not None:
            ctx.edits[path] = edit


def measure_plausibility(ctx: SolveContext) -> None:
    """Per edited agent, and for the shot (``stats["plausibility"]``), the figures of
    :func:`metrics.plausibility_of`: the facing and walking direction of the edited body against
    its source, path length, time warp and foot skate. They come from the same motions the edits
    layer authors, by numpy forward kinematics of the hip and the feet (the composed stage plays
    the same, so FK on it gives the same figures); layered poses are left out."""
    info = ctx.data.info
    up, chains, figures = info.up_axis, {}, []
    for path in sorted(ctx.edits):
        if path not in ctx.paths and path not in ctx.time_maps:
            continue
        agent, traj = ctx.data.agents[path], ctx.trajectories[path]
        clip = ctx.data.clip_of(agent)
        hip = metrics.default_facing_joint(agent.joints)
        feet = metrics.default_foot_joints(agent.joints)
        joints = [hip] + feet
        key = (agent.clip_key, tuple(agent.joints))
        if key not in chains:
            chains[key] = np.stack([trajectory.joint_skel_space(agent, clip, j) for j in joints], axis=1)
        source = chains[key] @ agent.skel_to_world[:, None]               # (F, 1 + feet, 4, 4)
        times, frames = output_frames(ctx, path)
        edited = animation.interp_frames(source, frames)
        moved = ctx.paths.get(path)
        if moved is not None:
            edited = edited @ trajectory.ground_motion(
                animation.interp_frames(traj.ground, frames), animation.interp_frames(traj.heading, frames),
                animation.interp_frames(moved.ground, frames), animation.interp_frames(moved.heading, frames),
                up)[:, None]
        seconds = 1.0 / info.time_codes_per_second
        skate = [float("nan"), float("nan")]
        if feet:
            units = (up, info.meters_per_unit, info.time_codes_per_second)
            before = metrics.foot_skate_of_positions(source[:, 1:, 3, :3], agent.sample_times, *units)
            mask = before.contact if len(times) == len(agent.sample_times) else None
            skate = [before.mean, metrics.foot_skate_of_positions(edited[:, 1:, 3, :3], times, *units,
                                                                  contact=mask).mean]
        locked = ctx.report.agents.get(path, {})
        if "footSkateUnlocked" in locked:  # foot locking measured the legs as the layer plays them
            skate = [locked["footSkateSource"], locked["footSkateEdited"]]
        p = metrics.plausibility_of(path, agent.sample_times * seconds, source[:, 0], times * seconds, edited[:, 0],
                                    up, info.meters_per_unit, *skate, edited_frames=frames)
        figures.append(p)
        entry = ctx.report.agent(path)
        if np.isfinite(skate).all():
            # Mean foot speed while in contact (stage units per second), over the source's contacts.
            entry.setdefault("footSkateSource", skate[0])
            entry.setdefault("footSkateEdited", skate[1])
        entry["plausibility"] = {
            "maxFacingRate": p.max_facing_rate, "sourceMaxFacingRate": p.source_max_facing_rate,
            "maxExtraFacingRate": p.max_extra_facing_rate, "spinFrames": p.spin_frames,
            "maxDirectionDeviation": p.max_direction_deviation,
            "maxTurnedDirectionDeviation": p.max_turned_deviation, "maxEditTurn": p.max_edit_turn,
            "reverses": p.reverses, "lengthRatio": p.length_ratio,
            "timeWarp": list(p.time_warp), "footSkateRatio": p.foot_skate_ratio,
            # Source frames where the largest extra turn and direction change happen (previews mark them).
            "worstTurnFrame": int(round(frames[max(p.worst_turn_frame, 0)])),
            "worstDirectionFrame": int(round(frames[p.worst_direction_frame])) if p.worst_direction_frame >= 0 else -1}
    if figures:
        ctx.report.stats["plausibility"] = metrics.worst_plausibility(figures)


def _with_parent(agent, parent_to_world):
    import dataclasses
    return dataclasses.replace(agent, agent_parent_to_world=parent_to_world)


def inspect(ctx: SolveContext) -> None:
    """After every pass: the report figures no pass measured, and the guides."""
    crowd = inspection.from_context(ctx)
    remaining = inspection.complete_report(ctx, crowd)
    guides.build(ctx, crowd, remaining)


def content_hash(stage: Usd.Stage) -> str:
    """SHA-256 over the content of every layer the input uses, in identifier order."""
    session = stage.GetSessionLayer()
    digests = []
    for layer in stage.GetUsedLayers():
        if layer == session:
            continue
        h = hashlib.sha256()
        if layer.realPath and os.path.isfile(layer.realPath):
            h.update(os.path.basename(layer.realPath).encode())
            with open(layer.realPath, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        else:
            h.update(layer.ExportToString().encode())
        digests.append(h.hexdigest())
    # Anonymous identifiers change from run to run: order by content, not by name.
    return hashlib.sha256("".join(sorted(digests)).encode()).hexdigest()


def input_layers(stage: Usd.Stage) -> list[str]:
    """The input's layer identifiers, root first; anonymous (in-memory) layers are left out."""
    root = stage.GetRootLayer().identifier
    others = sorted(l.identifier for l in stage.GetUsedLayers()
                    if l != stage.GetSessionLayer() and not l.anonymous and l.identifier != root)
    return [root] + others


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
    layer: Sdf.Layer
    report: Report
    data: StageData


def solve(stage_or_path, output: str | None = None, composed: str | None = None,
          guides: bool = True, collisions: bool | None = None, progress: Progress | None = None,
          report_json: str | None = None, bake_timing: bool = False, **overrides) -> SolveResult:
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
      overrides: MocapSolveSettings values by their Python names (``max_iterations=...``).

    Raises:
      MocapEditError: bad input, naming the prim and property; an output path that names
        the input, a layer it uses, another output or a folder. Nothing is written.
    """
    progress = progress or Silent()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if isinstance(stage_or_path, Usd.Stage):
        stage, input_name = stage_or_path, stage_or_path.GetRootLayer().identifier
    else:
        stage, input_name = reader.open_stage(str(stage_or_path)), str(stage_or_path)
    if (composed or report_json) and not output:
        raise MocapEditError("a composed stage or a report needs an output path for the edits layer (-o)")
    input_file = stage.GetRootLayer().realPath if isinstance(stage_or_path, Usd.Stage) else input_name
    if composed and not input_file:
        raise MocapEditError("a composed stage sub-layers the input file, but this stage is in memory; "
                             "save it first or leave out the composed stage")
    outputs.check_outputs([outputs.Output(output, "edits layer"),
                           outputs.Output(composed, "composed stage"),
                           outputs.Output(report_json, "report", kind="text")],
                          outputs.input_files(stage))

    data = reader.read_stage(stage, progress)
    for key, value in overrides.items():
        if not hasattr(data.settings, key):
            raise MocapEditError(f"unknown solve setting '{key}'")
        setattr(data.settings, key, value)
    limits.check_settings(data)
    limits.check_constraint_times(data)
    timings["read"] = time.perf_counter() - t0

    report = Report(input=input_name, output=output)
    ctx = SolveContext(data=data, options=SolveOptions(guides=guides, collisions=collisions,
                                                       overrides=overrides, bake_timing=bake_timing),
                       report=report, progress=progress)
    t = time.perf_counter()
    extract_trajectories(ctx)
    timings["trajectories"] = time.perf_counter() - t
    load_passes()
    for _, name, fn in list(PASSES):
        t = time.perf_counter()
        fn(ctx)
        timings[name] = time.perf_counter() - t
    t = time.perf_counter()
    compose_edits(ctx)
    timings["compose"] = time.perf_counter() - t
    t = time.perf_counter()
    inspect(ctx)
    timings["inspect"] = time.perf_counter() - t
    t = time.perf_counter()
    measure_plausibility(ctx)
    timings["plausibility"] = time.perf_counter() - t

    constraint_count = sum(len(x) for x in (data.position_constraints, data.relative_constraints,
                                            data.time_constraints, data.sync_constraints))
    # The passes' own run-wide figures (collisionIterations, ...) are kept beside these.
    report.stats.update({"agents": len(data.agents), "editedAgents": len(ctx.edits), "clips": len(data.clips),
                         "constraints": constraint_count, "groups": len(data.groups),
                         "avoidRegions": len(data.avoid_regions), "animationLayers": len(data.layers)})
    for path, traj in ctx.trajectories.items():
        entry = report.agent(path)
        entry.setdefault("frames", int(len(traj.ground)))
        entry.setdefault("edited", path in ctx.edits)
        if traj.projected_hip:
            entry.setdefault("trajectoryJoint", data.agents[path].joints[traj.joint])

    t = time.perf_counter()
    provenance = {"inputs": Vt.StringArray(input_layers(stage)), "contentHash": content_hash(stage),
                  "options": options_text(guides, collisions, bake_timing, **overrides)}
    layer = writer.build_layer(writer.LayerContent(
        info=data.info, agents=data.agents, edits=ctx.edits, guides=ctx.guides,
        provenance=provenance, stats=report.stats, report=report.to_layer_dict(),
        anchor=os.path.dirname(os.path.abspath(output)) if output else None))
    # The layer holds the edits now: their arrays (10,000 moved agents: 250 MB of transforms)
    # go before USD's exporter allocates its own buffers.
    for part in (ctx.edits, ctx.guides, ctx.paths, ctx.time_maps, ctx.pose_edits, ctx.trajectories):
        part.clear()
    if output:
        timings["write"] = time.perf_counter() - t
        timings["total"] = time.perf_counter() - t0
        report.timings = dict(timings)
        with outputs.Writes() as w:
            w.add(output, writer.export_layer(layer))
            if composed:
                w.add(composed, writer.export_layer(writer.composed_layer(
                    composed, output, input_file, data.info, stage.GetRootLayer().defaultPrim or None)))
            if report_json:
                w.add(report_json, outputs.write_text(report.to_json() + "\n"))
    timings["write"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    report.timings = timings
    return SolveResult(layer=layer, report=report, data=data)
