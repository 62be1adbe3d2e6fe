"""Measures of a composed stage: foot skate and plausibility of agents, evaluated by UsdSkel FK.

Stage in, figures out: :mod:`mocapedit.usd.evaluate` computes the joints' world positions on the
composed stage, :mod:`mocapedit.inspect.metrics` measures them. An edited stage (the input with
the edits layer on top) is thus judged by what plain UsdSkel plays.
"""
from __future__ import annotations

from typing import Iterable, Sequence, Union

import numpy as np

from mocapedit.inspect import metrics
from mocapedit.inspect.metrics import FootSkate, Plausibility
from mocapedit.usd import evaluate

__all__ = ["foot_skate", "plausibility", "shot_plausibility"]


def foot_skate(stage, agent_path, times: Iterable | None = None,
               foot_joints: Sequence[Union[int, str]] | None = None,
               contact_height: float | None = None,
               contact: np.ndarray | None = None) -> FootSkate:
    """Foot skate: mean horizontal foot speed while the foot is in contact with the ground.

    Evaluated by forward kinematics on the composed ``stage`` (a ``Usd.Stage``). A foot is in
    contact at a sample when it is within ``contact_height`` (default 2 cm in stage units, from
    ``metersPerUnit``) above its lowest height over the clip and the sample lies within the clip's
    sample range. The speed of a foot over an interval between consecutive samples that are both in
    contact is its horizontal (ground-plane) displacement over the interval's duration in seconds
    (``timeCodesPerSecond``).

    ``times``: time codes (default: the animation's authored samples as composed). ``foot_joints``:
    joint indices, full joint paths or unique joint names (default: joints named like a foot, toe
    or ankle, but not an end site). ``contact``: a (T, feet) boolean mask to use instead of the
    height test, typically ``source.contact`` from the source stage, so that an edited stage is
    measured over the frames where the source feet were planted (pass ``times=source.times``).
    """
    feet = evaluate.foot_positions(stage, agent_path, times, foot_joints)
    return metrics.foot_skate_of_positions(feet.positions, feet.times, *evaluate.stage_units(stage),
                                           feet.joints, feet.in_clip, contact_height, contact)


def plausibility(source_stage, edited_stage, agent_path, joint: Union[int, str, None] = None,
                 foot_joints=None) -> Plausibility:
    """Plausibility of one agent: its edited motion on ``edited_stage`` (the input with the edits
    layer on top) against its source on ``source_stage``, both by UsdSkel FK at their own composed
    samples. An agent whose animation re-times its clip by a value clip (time edits, locked legs:
    :func:`~mocapedit.usd.evaluate.played_frames`) is paired with its source by the frame it plays
    at each time, and its feet are measured against the source played on that timing at the
    shot's whole frames, per second of the shot, as the solve's report measures them; others pair
    by frame. Foot skate is measured
    over the source's planted samples, less those where the edited foot is lifted more than 2 cm
    above the source's (a step, :func:`~mocapedit.inspect.metrics.on_ground`). ``joint``: the
    facing joint (default :func:`~mocapedit.model.names.default_facing_joint`)."""
    ts, ms = evaluate.joint_world_matrices(source_stage, agent_path, None, joint)
    te, me = evaluate.joint_world_matrices(edited_stage, agent_path, None, joint)
    feet_s = evaluate.foot_positions(source_stage, agent_path, None, foot_joints)
    source, edited = evaluate.stage_units(source_stage), evaluate.stage_units(edited_stage)
    frames = evaluate.played_frames(edited_stage, agent_path, te)
    # The times the feet are measured at, and the source frame each plays.
    tf, ff = te, frames
    # A value clip that plays the clip on its own samples (legs locked on an agent that keeps its
    # timing: the rotations baked on the same samples) is measured there, as an agent without one.
    own = frames is not None and len(frames) == len(feet_s.times) and np.allclose(
        frames, np.arange(len(frames)), rtol=0.0, atol=1e-6) and np.allclose(te, feet_s.times, rtol=0.0, atol=1e-6)
    if frames is not None and len(te) > 1 and not own:
        # A re-timed agent's composed samples mix its value clip's own (the source samples
        # through the new timing) with the frames its pose edits are baked on, each attribute
        # interpolated between its own: a 60 fps clip under legs locked on a 30 fps shot's frames
        # moved its planted feet by a centimetre between frames, which the skate counted at
        # +3 cm/s. Its feet are judged at the shot's whole frames, as the solve's report judges them.
        whole = np.arange(np.ceil(te[0] - 1e-9), np.floor(te[-1] + 1e-9) + 1.0)
        if len(whole) > 1:
            tf, ff = whole, evaluate.played_frames(edited_stage, agent_path, whole)
    played = feet_s
    if ff is not None and len(feet_s.times) > 1:
        # The source's feet as the edited timing plays them: by FK on the source stage at the
        # times that play those (fractional) frames, between two of its samples where the timing
        # falls, its joints interpolated as USD interpolates the value clip's. (Interpolating the
        # foot positions instead differs by centimetres where a foot swings fast, and a walk only
        # delayed seemed to slide its planted feet 0.5 cm/s more.)
        at = np.interp(ff, np.arange(len(feet_s.times), dtype=np.float64), feet_s.times)
        fk = evaluate.foot_positions(source_stage, agent_path, at, list(feet_s.joints))
        played = evaluate.FootSamples(tf, fk.positions, feet_s.joints, np.ones(len(tf), dtype=bool))
    # What plays in the shot (the source stage's start and end time codes), as the solve's report
    # measures it.
    start, end = evaluate.shot_range(source_stage)
    skate_s = metrics.foot_skate_of_positions(played.positions, played.times, *source, played.joints, played.in_clip)
    planted = skate_s.contact & metrics.in_shot(played.times, start, end)[:, None]
    skate_s = metrics.foot_skate_of_positions(played.positions, played.times, *source, played.joints, played.in_clip,
                                              contact=planted)
    if len(skate_s.times) == len(tf):
        # Over the source's contacts, less where the edited foot is lifted (a step).
        feet_e = evaluate.foot_positions(edited_stage, agent_path, tf, foot_joints)
        contact = metrics.on_ground(skate_s.contact, played.positions, feet_e.positions, source.up_axis,
                                    source.meters_per_unit)
        skate_e = metrics.foot_skate_of_positions(feet_e.positions, feet_e.times, *edited, feet_e.joints,
                                                  feet_e.in_clip, contact=contact)
    else:
        skate_e = foot_skate(edited_stage, agent_path, foot_joints=foot_joints)
    # The edited samples in the shot, against the source frames they play.
    keep = metrics.in_shot(te, start, end)
    paired = frames if frames is not None else (np.arange(len(te), dtype=np.float64) if len(te) == len(ts) else None)
    if not keep.all() and paired is not None:
        first, stop = metrics.shot_window(keep, paired, len(ts))
        ts, ms, te, me, frames = ts[first:stop], ms[first:stop], te[keep], me[keep], paired[keep] - first
    return metrics.plausibility_of(str(agent_path), ts / source.time_codes_per_second, ms,
                                   te / edited.time_codes_per_second, me, source.up_axis,
                                   source.meters_per_unit, skate_s.mean, skate_e.mean, edited_frames=frames)


def shot_plausibility(source_stage, edited_stage, agent_paths: Iterable, joint=None,
                      foot_joints=None) -> list[Plausibility]:
    """:func:`plausibility` of each agent, in the order given."""
    return [plausibility(source_stage, edited_stage, p, joint, foot_joints) for p in agent_paths]
