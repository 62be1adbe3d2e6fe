"""The solve context: what the passes of a solve read and produce, field by field.

A pass reads the stage data, the options and what earlier passes produced, and adds its own
results under the fields below (agent path -> result); the processor turns the results into
what the writer authors. Nothing here is a function stored as data: a pose edit is an object
with an ``apply`` method (:class:`PoseEdit`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Protocol

import numpy as np

from mocapedit.geometry import animation, contacts, ground, trajectory
from mocapedit.model.data import StageData
from mocapedit.model.progress import Progress
from mocapedit.model.report import Report
from mocapedit.usd import stage_io, writer


@dataclass
class EditedPath:
    """An agent's edited ground path, one row per source frame."""
    ground: np.ndarray            # (F,2) stage units, on the ground plane
    heading: np.ndarray           # (F,) radians, counter-clockwise about up


class PoseEdit(Protocol):
    """A change of an agent's pose (layering, locked legs), applied in order to the time-warped
    source pose."""

    def apply(self, pose: animation.Pose, out_times: np.ndarray, src_frames: np.ndarray) -> animation.Pose:
        """The edited pose. ``out_times``: (T,) stage times of the pose's rows; ``src_frames``:
        (T,) the fractional source frame each row plays."""
        ...


class ComponentPool(Protocol):
    """Somewhere else to solve a shot's independent parts (Dask workers, see
    :class:`mocapedit.pipeline.batch.DaskComponents`). The path pass hands it up to ``chunks`` runs of
    consecutive path components, foot locking as many runs of edited agents, and each merges the
    results in order, so the shot's bytes are the same as when its own process does the work."""

    chunks: int

    def map(self, fn: Callable, items: list) -> Iterable:
        """``fn(item)`` for each item, run elsewhere, yielded in the order of ``items``."""
        ...


def consecutive_runs(work: list[float], count: int) -> list[slice]:
    """At most ``count`` runs of consecutive items of about equal total ``work`` (one per item),
    as slices, in order, covering every item."""
    total = np.cumsum(work, dtype=np.float64)
    cut = np.searchsorted(total, total[-1] * np.arange(1, count) / count, side="right")
    bounds = [0] + sorted({int(b) for b in cut if 0 < b < len(work)}) + [len(work)]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


@dataclass
class SolveOptions:
    guides: bool = True
    collisions: bool | None = None     # None: follow MocapSolveSettings.collisionAvoidance
    overrides: dict = field(default_factory=dict)  # settings overrides by python field name
    # Bake time-only edits into SkelAnimation samples instead of re-timing the source clip
    # with value clips (the two play the same motion; the baked form is the reference).
    bake_timing: bool = False
    # Where the path pass solves its components and foot locking locks the agents; None: this
    # process. Not an option of the result: the edits layer is the same either way and does not
    # record it.
    components: ComponentPool | None = None


@dataclass
class SolveContext:
    """The state of one solve, shared by its passes."""
    data: StageData
    options: SolveOptions
    report: Report
    progress: Progress
    #: The source ground path of every agent, extracted before the passes run.
    trajectories: dict[str, trajectory.Trajectory] = field(default_factory=dict)
    #: Spatial edits: the edited ground path per source frame.
    paths: dict[str, EditedPath] = field(default_factory=dict)
    #: Time edits: the shot time at which each source frame plays, (F,) increasing.
    time_maps: dict[str, np.ndarray] = field(default_factory=dict)
    #: Pose edits (layering, foot locking), applied in order to the time-warped source pose.
    pose_edits: dict[str, list[PoseEdit]] = field(default_factory=dict)
    #: Output times chosen by a pass for an agent (else whole shot frames for a time map,
    #: the clip's own samples otherwise).
    out_times: dict[str, np.ndarray] = field(default_factory=dict)
    #: What the writer authors, per edited agent (filled after the passes).
    edits: dict[str, writer.AgentEdit] = field(default_factory=dict)
    #: Guide geometry the passes and the inspection add.
    guides: list = field(default_factory=list)
    #: Foot contacts of the source clips (:meth:`source_contacts`), by clip and placement.
    contacts_cache: dict = field(default_factory=dict)
    #: Whether the moved agents' paths pivot on their feet already (the stance pass; collision
    #: avoidance runs it before its last solve, so that the solve clears what it moves).
    pivoted: bool = False

    def source_contacts(self, path: str) -> list[list[tuple[int, int]]]:
        """Per leg of the agent (``agent.legs``), the inclusive frame ranges of its foot contacts
        on its source clip: the artist's (``agent.foot_contacts``), else detected. Agents that
        play one clip the same way share them."""
        return self._contacts(path)[0]

    def contacts_note(self, path: str) -> str | None:
        """Why a leg of the agent has no contacts detected (:func:`contacts.raised_note`), or None."""
        return self._contacts(path)[1]

    def _contacts(self, path: str) -> tuple[list[list[tuple[int, int]]], str | None]:
        agent = self.data.agents[path]
        place = agent.skel_to_world
        # A static placement's translation and turn about up change neither the contacts nor the
        # skate: what matters is how it maps the skeleton to height (its up column) and its scale.
        up = ground.up_index(self.data.info.up_axis)
        placement = (np.round(place[0, :3, up], 12).tobytes(), round(float(np.linalg.norm(place[0, 0, :3])), 12)) \
            if place.shape[0] == 1 else place.tobytes()
        key = (agent.clip_key, tuple(agent.joints), tuple(leg.joints for leg in agent.legs),
               tuple(agent.foot_contacts or ()), placement)
        hit = self.contacts_cache.get(key)
        if hit is None:
            if agent.foot_contacts is not None:   # the artist's, as authored
                hit = (contacts.leg_ranges(agent.foot_contacts, agent.legs, agent.frame_count), None)
            else:
                clip = self.data.clip_of(agent)
                raised = contacts.raised_legs(agent, clip, self.data.info)
                hit = (contacts.detect_agent(agent, clip, self.data.info, raised=raised),
                       contacts.raised_note(agent, raised))
            self.contacts_cache[key] = hit
        return hit

    def touched(self) -> list[str]:
        """The agents some pass edited (path, time or pose), sorted. A path a solve gave back
        unchanged (an agent of a collision or group solve that nothing moved) is no edit."""
        return sorted({p for p in self.paths if self.moved(p)} | set(self.time_maps) | set(self.pose_edits))

    def moved(self, path: str) -> bool:
        """Whether the agent's edited path differs from its source: by more than a nanometre
        (numerical noise of a solve that had nothing to do) or 1e-9 radians of heading."""
        edited = self.paths.get(path)
        if edited is None:
            return False
        source = self.trajectories[path]
        still = 1e-9 / self.data.info.meters_per_unit
        return bool(np.abs(edited.ground - source.ground).max(initial=0.0) > still
                    or np.abs(edited.heading - source.heading).max(initial=0.0) > 1e-9)

    def retimed_spec(self, path: str) -> tuple[str, str] | None:
        """(clip layer, prim path) when the agent's only change of pose is its timing and its clip
        can be re-timed by a value clip (one spec's samples, in a layer on disk); None when it is
        baked instead (layered, ``bake_timing``, a clip split over specs or only in memory)."""
        if path not in self.time_maps or path in self.pose_edits:
            return None
        return self.clip_spec(path)

    def rotations_spec(self, path: str) -> tuple[str, str] | None:
        """(clip layer, prim path) when the agent's pose edits change only joint rotations
        (locked legs, their lowering carried by the agent's transform) and its clip can be
        re-timed by a value clip: the writer then bakes the rotations alone over the re-timed
        source. None otherwise."""
        edits = self.pose_edits.get(path)
        if not edits or any(getattr(e, "CHANNELS", None) != ("rotations",) for e in edits):
            return None
        return self.clip_spec(path)

    def clip_spec(self, path: str) -> tuple[str, str] | None:
        """(clip layer, prim path) of the agent's clip when a value clip can re-time it: its
        samples in one spec of a layer on disk, no animation layer over it, no ``bake_timing``."""
        if self.options.bake_timing or any(path in layer.agents for layer in self.data.layers):
            return None
        clip = self.data.clip_of(self.data.agents[path])
        spec = clip.sample_spec
        if spec is None or clip.spec_times is None or stage_io.is_anonymous(spec[0]):
            return None
        return spec

    def output_frames(self, path: str, baked: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(stage times to author, fractional source frame at each) for one agent.

        ``baked``: the times its animation has when baked, even if it is re-timed by a value clip
        now (a pass that is about to give it a pose edit, which bakes it, asks for these)."""
        agent = self.data.agents[path]
        frames = np.arange(agent.frame_count, dtype=np.float64)
        time_map = self.time_maps.get(path)
        if time_map is None:
            times = self.out_times.get(path, agent.sample_times)
            return times, np.interp(times, agent.sample_times, frames)
        if not baked and self.retimed_spec(path):
            # A re-timed clip plays each source frame at its time on the map: those are its samples.
            return np.asarray(time_map, dtype=np.float64), frames
        times = self.out_times.get(path)
        if times is None:
            # A baked warped clip is authored on the shot's whole frames.
            times = np.arange(np.ceil(time_map[0] - 1e-9), np.floor(time_map[-1] + 1e-9) + 1.0)
        return times, np.interp(times, time_map, frames)

    def release(self) -> None:
        """Drops the per-agent results (the edits layer holds them once it is built)."""
        for part in (self.edits, self.guides, self.paths, self.time_maps, self.pose_edits, self.trajectories,
                     self.contacts_cache):
            part.clear()
