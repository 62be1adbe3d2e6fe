"""A street of walkers, some of them on the phone: an additive upper-body layer that eases
in and out, applied to several agents by one MocapAnimationLayer prim.

- ``clips/street_walk.usda``: the procedural walk every agent plays (120 frames, 24 fps);
- ``clips/phone_call.usda``: the phone-call gesture (the ``Spine`` subtree only, 96 frames,
  a seamless 4 s loop), made by :func:`mocapedit.data.gestures.phone_call`;
- ``/World/Layers/PhoneCall``: added on agents 0, 2 and 5 from ``Spine`` down, as a delta
  from the rest pose, easing in over frames 12-30 and out over frames 84-102;
- ``/World/Layers/LateCall``: the same clip on agents 3 and 6, a second later in the
  gesture loop (``timeOffset``), easing in over frames 40-58 and staying on.

The others just walk: ``mocapedit solve`` writes only the five layered agents.
"""
from __future__ import annotations

from pathlib import Path

from pxr import Sdf, Usd

from mocapedit.data import examples, gestures, walker
from mocapedit.usd import schema

FPS = 24.0
FRAMES = 120


def build_street(out: Path) -> None:
    out = Path(out)
    walk = walker.walk(frames=FRAMES, fps=FPS, name="street_walk")
    phone = gestures.phone_call(frames=96, fps=FPS, period=4.0)
    agents = []
    for i in range(8):
        lane = i % 2  # lane 0 walks towards +Z, lane 1 back towards -Z
        x = -4.07 if lane == 0 else 4.04  # the two sidewalks of a street
        z = -8.1 + 2.45 * (i // 2) if lane == 0 else 9.9 - 2.45 * (i // 2)
        agents.append(examples.AgentSpec(f"agent_{i:04d}", walk, (x + 0.13 * (i % 3), 0.0, z),
                                         0.0 if lane == 0 else 180.0, time_offset=float(3 * (i % 4))))
    path = out / "layering_street.usda"
    stage = examples.build_crowd_stage(path, agents, up_axis="Y", meters_per_unit=1.0, fps=FPS,
                                       clips_dir=out / "clips")
    examples.write_clip_layer(phone, out / "clips" / "phone_call.usda")
    clip = stage.DefinePrim("/World/Clips/PhoneCall")
    clip.GetReferences().AddReference("./clips/phone_call.usda", examples.CLIP_ANIMATION_PATH)

    def layer(name, members, weights, time_offset=0.0):
        prim = schema.AnimationLayer.Define(stage, f"/World/Layers/{name}")
        prim.CreateAgentsRel().SetTargets([Sdf.Path(f"/World/Crowd/agent_{i:04d}") for i in members])
        prim.CreateAnimationRel().SetTargets([clip.GetPath()])
        prim.CreateJointAttr(gestures.UPPER_BODY_ROOT)
        prim.CreateModeAttr("additive")
        prim.CreateReferencePoseAttr("restPose")
        prim.CreateTimeOffsetAttr(time_offset)
        weight = prim.CreateWeightAttr()
        for t, w in weights:
            weight.Set(w, Usd.TimeCode(t))

    layer("PhoneCall", (0, 2, 5), ((12.0, 0.0), (30.0, 1.0), (84.0, 1.0), (102.0, 0.0)))
    layer("LateCall", (3, 6), ((40.0, 0.0), (58.0, 1.0)), time_offset=FPS)
    stage.GetRootLayer().Save()


STAGES = {"layering_street.usda": build_street}
