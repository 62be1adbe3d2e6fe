"""BVH files the tests write themselves: random rigs with any channel layout, and a walker
that walks, stands idle for a known range of frames, and walks on."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

AXES = "XYZ"


@dataclass
class Rig:
    names: list[str]
    parents: list[int]              # preorder: a parent precedes its children, depth-first
    offsets: np.ndarray             # (J,3)
    channels: list[list[str]]       # labels per joint, file order
    end_sites: dict[int, np.ndarray]  # leaf joint -> End Site offset


def write_bvh(path, rig: Rig, values: np.ndarray, frame_time: str = "0.0166667", newline: str = "\n",
              indent: str = "\t", digits: int = 6) -> None:
    """Writes ``values`` (F,C) for ``rig``; ``frame_time`` is written as given."""
    children = {j: [c for c, p in enumerate(rig.parents) if p == j] for j in range(len(rig.names))}
    out: list[str] = ["HIERARCHY"]

    def joint(j, depth):
        pad = indent * depth
        out.append(f"{pad}{'ROOT' if rig.parents[j] < 0 else 'JOINT'} {rig.names[j]}")
        out.append(pad + "{")
        out.append(pad + indent + "OFFSET " + " ".join(f"{v:.{digits}f}" for v in rig.offsets[j]))
        out.append(pad + indent + f"CHANNELS {len(rig.channels[j])} " + " ".join(rig.channels[j]))
        for c in children[j]:
            joint(c, depth + 1)
        if j in rig.end_sites:
            out.append(pad + indent + "End Site")
            out.append(pad + indent + "{")
            out.append(pad + indent * 2 + "OFFSET " + " ".join(f"{v:.{digits}f}" for v in rig.end_sites[j]))
            out.append(pad + indent + "}")
        out.append(pad + "}")

    for r in [j for j, p in enumerate(rig.parents) if p < 0]:
        joint(r, 0)
    out += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {frame_time}"]
    out += [" ".join(f"{v:.{digits}f}" for v in row) for row in values]
    with open(path, "w", newline="") as f:
        f.write(newline.join(out) + newline)


def random_rig(rng: np.random.Generator, joints: int, six_channel_share: float = 0.2,
               names: list[str] | None = None) -> Rig:
    """A random tree in depth-first order; every joint has 3 or 6 channels in a random order.

    Three-channel joints are rotations in any of the six Euler orders; six-channel joints
    put positions before, after or among the rotations.
    """
    parents = [-1]
    path = [0]
    for j in range(1, joints):
        # Attach to the previous joint or to one of its ancestors: keeps depth-first order.
        up = int(rng.integers(0, min(len(path), 3)))
        path = path[:len(path) - up]
        parents.append(path[-1])
        path.append(j)
    offsets = rng.uniform(-12.0, 12.0, (joints, 3))
    offsets[0] = rng.uniform(-5, 5, 3)
    channels = []
    for j in range(joints):
        rot = [f"{a}rotation" for a in rng.permutation(list(AXES))]
        if j == 0 or rng.random() < six_channel_share:
            pos = [f"{a}position" for a in rng.permutation(list(AXES))]
            layout = int(rng.integers(0, 3))
            labels = pos + rot if layout == 0 else rot + pos if layout == 1 else \
                list(rng.permutation(pos + rot))
        else:
            labels = rot
        channels.append([str(x) for x in labels])
    leaves = [j for j in range(joints) if j not in parents]
    end_sites = {j: rng.uniform(-6, 6, 3) for j in leaves}
    names = names or [f"joint{j}" for j in range(joints)]
    return Rig(names=names, parents=parents, offsets=offsets, channels=channels, end_sites=end_sites)


def random_motion(rng: np.random.Generator, rig: Rig, frames: int, spin_joints: tuple[int, ...] = (0,),
                  spin_degrees: float = 1000.0, travel: float = 200.0) -> np.ndarray:
    """(F,C) smooth random channel values; the spin joints turn past 360 degrees about Y."""
    t = np.linspace(0.0, 1.0, frames)
    cols = []
    for j, labels in enumerate(rig.channels):
        for k, label in enumerate(labels):
            phase, freq = rng.uniform(0, 2 * np.pi), rng.uniform(0.5, 3.0)
            if label.endswith("position"):
                axis = AXES.index(label[0])
                base = rig.offsets[j, axis]
                if rig.parents[j] < 0:
                    v = base + travel * t * rng.uniform(-1, 1) + 4.0 * np.sin(2 * np.pi * freq * t + phase)
                else:
                    v = base + 2.0 * np.sin(2 * np.pi * freq * t + phase)
            else:
                v = rng.uniform(20, 170) * np.sin(2 * np.pi * freq * t + phase)
                if j in spin_joints and label[0] == "Y":
                    # Written wrapped to [-180, 180), as exporters do: the values jump by 360.
                    v = (v * 0.1 + spin_degrees * t + 180.0) % 360.0 - 180.0
            cols.append(v)
    return np.stack(cols, axis=1) if cols else np.zeros((frames, 0))


# ---- a walker that stops ---------------------------------------------------------------------

def _humanoid() -> Rig:
    names, parents, offsets = [], [], []

    def add(name, parent, offset):
        names.append(name)
        parents.append(parent)
        offsets.append(offset)
        return len(names) - 1

    hips = add("Hips", -1, (0, 95, 0))
    spine = add("Spine", hips, (0, 10, 0))
    chest = add("Chest", spine, (0, 20, 0))
    neck = add("Neck", chest, (0, 22, 0))
    add("Head", neck, (0, 10, 0))
    for side, x in (("Left", 1), ("Right", -1)):
        sh = add(f"{side}Shoulder", chest, (x * 8, 18, 0))
        arm = add(f"{side}Arm", sh, (x * 12, 0, 0))
        add(f"{side}ForeArm", arm, (x * 27, 0, 0))
    for side, x in (("Left", 1), ("Right", -1)):
        up = add(f"{side}UpLeg", hips, (x * 9, -5, 0))
        leg = add(f"{side}Leg", up, (0, -43, 0))
        foot = add(f"{side}Foot", leg, (0, -42, 0))
        add(f"{side}Toe", foot, (0, -5, 12))
    channels = [["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"]]
    channels += [["Zrotation", "Xrotation", "Yrotation"]] * (len(names) - 1)
    leaves = [j for j in range(len(names)) if j not in parents]
    return Rig(names=names, parents=parents, offsets=np.array(offsets, dtype=np.float64),
               channels=[list(c) for c in channels], end_sites={j: np.array([0.0, 0.0, 5.0]) for j in leaves})


def walk_idle_walk(fps: float = 60.0, walk1: float = 2.5, idle: float = 3.0, walk2: float = 2.5,
                   ramp: float = 0.4, speed: float = 130.0, turn_degrees: float = 60.0
                   ) -> tuple[Rig, np.ndarray, tuple[int, int]]:
    """A humanoid (centimetres, Y-up) that walks, stands idle, and walks on after turning.

    Returns (rig, values (F,C), (first, last) frames of the idle section, where the root's
    ground speed is zero). The walk speeds up and slows down over ``ramp`` seconds, the
    hips bob and sway with the steps, and the idle keeps a slow breathing sway of a few
    millimetres, as captured idles do.
    """
    rig = _humanoid()
    total = walk1 + idle + walk2
    frames = int(round(total * fps)) + 1
    t = np.arange(frames) / fps
    # Ground speed profile: full speed, ramp down to 0 at walk1, still through idle, ramp up.
    s = np.ones(frames)
    s = np.where(t > walk1 - ramp, np.clip((walk1 - t) / ramp, 0, 1), s)
    s = np.where(t >= walk1 + idle, np.clip((t - walk1 - idle) / ramp, 0, 1), s)
    v = speed * 0.5 * (1 - np.cos(np.pi * s))                    # smooth ramps, cm/s
    # Heading: the first walk heads along +Z; the second turns gradually while walking.
    heading = np.radians(turn_degrees) * np.clip((t - walk1 - idle - ramp) / (walk2 - ramp), 0, 1)
    dist = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / fps)])
    dx = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] * np.sin(heading[1:]) + v[:-1] * np.sin(heading[:-1])) / fps)])
    dz = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] * np.cos(heading[1:]) + v[:-1] * np.cos(heading[:-1])) / fps)])
    step_phase = 2 * np.pi * dist / 70.0                       # one stride every 70 cm
    amp = v / speed
    breathe = 0.3 * np.sin(2 * np.pi * 0.4 * t)                # cm
    x = dx + 3.0 * amp * np.sin(step_phase) * np.cos(heading) + breathe
    z = dz - 3.0 * amp * np.sin(step_phase) * np.sin(heading)
    y = 95.0 + 2.0 * amp * np.cos(2 * step_phase) + 0.2 * breathe
    yaw = np.degrees(heading) + 4.0 * amp * np.sin(step_phase) + 0.8 * np.sin(2 * np.pi * 0.3 * t)
    cols = {("Hips", "Xposition"): x, ("Hips", "Yposition"): y, ("Hips", "Zposition"): z,
            ("Hips", "Yrotation"): yaw, ("Hips", "Zrotation"): 3.0 * amp * np.sin(step_phase),
            ("Hips", "Xrotation"): 2.0 * amp * np.cos(2 * step_phase)}
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        swing = sign * 30.0 * amp * np.sin(step_phase)
        cols[(f"{side}UpLeg", "Xrotation")] = swing
        cols[(f"{side}Leg", "Xrotation")] = 25.0 * amp * (1 + np.sin(step_phase + sign * np.pi / 2))
        cols[(f"{side}Arm", "Zrotation")] = sign * (-70.0 + 2.0 * np.sin(2 * np.pi * 0.4 * t))
        cols[(f"{side}Arm", "Xrotation")] = -sign * 20.0 * amp * np.sin(step_phase)
    values = np.zeros((frames, sum(len(c) for c in rig.channels)))
    col = 0
    for j, labels in enumerate(rig.channels):
        for label in labels:
            values[:, col] = cols.get((rig.names[j], label), 0.0)
            col += 1
    still = np.nonzero(v == 0)[0]
    return rig, values, (int(still[0]), int(still[-1]))


# ---- the procedural walker as a BVH file -------------------------------------------------------

EULER_ORDERS = ("ZXY", "XYZ", "YZX", "ZYX", "XZY", "YXZ")


def walker_rig(clip) -> tuple[Rig, np.ndarray]:
    """A mocapedit.data.walker clip as BVH: (rig, values (F,C)).

    Joints whose translation changes over the clip (the root and the hips) get six
    channels with absolute positions; the others three rotation channels, cycling
    through the six Euler orders. Angles come from scipy's intrinsic Euler conversion.
    """
    from scipy.spatial.transform import Rotation

    t = np.asarray(clip.translations, dtype=np.float64)
    q = np.asarray(clip.rotations, dtype=np.float64)
    names = [j.rsplit("/", 1)[-1] for j in clip.joints]
    channels, columns = [], []
    for j in range(clip.num_joints):
        order = EULER_ORDERS[(j + 1) % len(EULER_ORDERS)]   # the root: XYZ, clear of gimbal lock
        euler = Rotation.from_quat(q[:, j]).as_euler(order, degrees=True)
        rot = [f"{a}rotation" for a in order]
        if j == 0 or np.ptp(t[:, j], axis=0).max() > 1e-9:
            channels.append(["Xposition", "Yposition", "Zposition"] + rot)
            columns += [t[:, j, 0], t[:, j, 1], t[:, j, 2]]
        else:
            channels.append(rot)
        columns += [euler[:, 0], euler[:, 1], euler[:, 2]]
    rig = Rig(names=names, parents=[int(p) for p in clip.parents], offsets=t[0].copy(), channels=channels,
              end_sites={})
    return rig, np.stack(columns, axis=1)
