"""Biovision Hierarchy (BVH) motion capture: parse it and turn it into joint-local transforms.

No USD here (``mocapedit.usd.bvh_usd`` writes the result); everything is numpy.

**Parsing.** :func:`read_header` reads the ``HIERARCHY`` section and the ``MOTION`` header
into a :class:`BvhSkeleton`; :func:`iter_frames` then streams the frame rows in chunks,
so a clip larger than memory is never read at once. :func:`load` reads a whole file.
Accepted: any number of channels from 0 to 6 per joint (positions and rotations in any
order within a joint, so any Euler order), ``End Site`` blocks, several ``ROOT``
hierarchies, Windows or old Mac line endings, ``Frame Time: .0083333`` without a leading
zero, joint names with spaces or any characters. Anything else is malformed and raises
:class:`~mocapedit.model.errors.MocapEditError` with the file name and line number
(``walk.bvh:12: ...``): a truncated file, a channel count that does not match its labels,
a frame row with too few or too many values, a value that is not a finite number, an
unknown keyword.

**Conversion.** :class:`Converter` turns channel values into joint-local translations and
quaternions ``(x, y, z, w)`` (the layout of ``Vt.QuatfArray``), vectorised over frames and
joints. BVH rotation channels are intrinsic Euler rotations applied in the order they are
listed (``Zrotation Xrotation Yrotation`` is ``Rz * Rx * Ry`` on column vectors); position
channels give the joint's translation either instead of its OFFSET (``absolute``, the
common reading) or added to it (``relative``, as some exporters write a hip-rooted rig;
``auto`` picks per joint from the data). Quaternions are made sign-continuous frame to
frame, across chunks, so a root spinning past 360 degrees interpolates without flips.
A ``--up Z`` import turns the Y-up BVH world about +X by 90 degrees at the roots.

Joint names map to USD joint path tokens (``Hips/Spine/Neck``) made of valid identifiers,
unique across the skeleton (:func:`joint_tokens`).
"""
from __future__ import annotations

import io
import math
import os
import re
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from mocapedit.geometry.kinematics import quat_multiply, quat_rotate
from mocapedit.model.errors import MocapEditError
from mocapedit.model.names import unique_identifier

#: Frames parsed per chunk when streaming.
CHUNK_FRAMES = 4096

#: Lengths of common BVH units, in metres (``--unit``). CMU's unit is 1/0.45 inch.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "inch": 0.0254, "ft": 0.3048,
         "cmu": 0.0254 / 0.45}

_CHANNELS = {"xposition": ("p", 0), "yposition": ("p", 1), "zposition": ("p", 2),
             "xrotation": ("r", 0), "yrotation": ("r", 1), "zrotation": ("r", 2)}

# The frame times (seconds) a capture can have: 10,000 down to 0.1 frames per second. Outside
# them the file is broken, and taking it at its word makes a clip of absurd timing.
FRAME_TIME_RANGE = (1e-4, 10.0)

# Frame rates that a rounded Frame Time stands for (1/fps printed to a few digits).
_COMMON_FPS = (24000 / 1001, 30000 / 1001, 60000 / 1001)


def _error(path: str, line: int | None, message: str) -> MocapEditError:
    where = f"{path}:{line}" if line is not None else path
    return MocapEditError(f"{where}: {message}")


@dataclass
class BvhSkeleton:
    """The HIERARCHY section and the MOTION header of a BVH file."""
    path: str                          # the file, for messages
    names: list[str]                   # (J,) joint names as written
    parents: np.ndarray                # (J,) parent joint index, -1 for a root; parents precede children
    offsets: np.ndarray                # (J,3) OFFSET of each joint, file units, in its parent's frame
    channels: list[tuple[str, ...]]    # (J,) channel labels of each joint, as written, in file order
    lines: list[int]                   # (J,) line of each joint's ROOT/JOINT keyword
    end_sites: list[tuple[int, np.ndarray]] = field(default_factory=list)  # (parent joint, (3,) offset)
    frame_count: int = 0               # Frames:
    frame_time: float = 0.0            # Frame Time:, seconds
    frames_line: int = 0               # line of 'Frames:'

    @property
    def joint_count(self) -> int:
        return len(self.names)

    @property
    def channel_count(self) -> int:
        return sum(len(c) for c in self.channels)

    @property
    def first_channel(self) -> np.ndarray:
        """(J,) column of each joint's first channel in a frame row."""
        counts = np.array([len(c) for c in self.channels], dtype=np.int64)
        return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)

    @property
    def fps(self) -> float:
        """Frames per second from Frame Time, snapped to the rate a rounded value stands for."""
        rate = 1.0 / self.frame_time
        for candidate in (round(rate),) + _COMMON_FPS:
            if candidate > 0 and abs(rate - candidate) <= 5e-4 * candidate:
                return float(candidate)
        return rate

    def find(self, name: str) -> int | None:
        """Index of a joint given by its BVH name or its USD token or joint path."""
        if name in self.names:
            return self.names.index(name)
        tokens = joint_tokens(self.names)
        paths = joint_paths(tokens, self.parents)
        for candidates in (tokens, paths):
            if name in candidates:
                return candidates.index(name)
        return None


@dataclass
class BvhMotion:
    """A whole BVH file: its skeleton and every frame's channel values."""
    skeleton: BvhSkeleton
    values: np.ndarray                 # (F,C) float64 channel values, file units and degrees


# ---- names ------------------------------------------------------------------------------

_WHOLE = re.compile(r"[0-9]+")


def joint_tokens(names: list[str]) -> list[str]:
    """Valid USD identifiers for BVH joint names, unique across the skeleton.

    Characters outside ``[A-Za-z0-9_]`` become ``_``, a leading digit gets a ``_`` in
    front, and a name already taken gets ``_2``, ``_3``, ... so that a joint can be
    named by its last path element alone.
    """
    taken: set[str] = set()
    return [unique_identifier(name.strip(), taken, "joint") for name in names]


def joint_paths(tokens: list[str], parents: np.ndarray) -> list[str]:
    """UsdSkel joint paths (``Hips/Spine``) from tokens and parent indices."""
    paths: list[str] = []
    for token, p in zip(tokens, parents):
        paths.append(token if p < 0 else f"{paths[p]}/{token}")
    return paths


# ---- parsing ------------------------------------------------------------------------------

class _Lines:
    """Lines of a text file with their 1-based numbers; blank lines are skipped."""

    def __init__(self, f: io.TextIOBase):
        self.f = f
        self.number = 0
        self.back: list[tuple[int, list[str]]] = []

    def push(self, number: int, tokens: list[str]) -> None:
        """Gives back the rest of a line, to be read next as a line of its own (a statement
        that another follows on the same line: '{ OFFSET 0 1 0 }')."""
        self.back.append((number, tokens))

    def next(self) -> tuple[int, list[str]] | None:
        if self.back:
            return self.back.pop()
        for line in self.f:
            self.number += 1
            tokens = line.split()
            if tokens:
                return self.number, tokens
        return None


def _open(path: str) -> io.TextIOBase:
    try:
        # Universal newlines: \n, \r\n and \r all end a line. Bytes that are not UTF-8
        # (a Latin-1 joint name) become U+FFFD rather than failing.
        return open(path, "r", encoding="utf-8", errors="replace", newline=None)
    except OSError as exc:
        raise MocapEditError(f"{path}: cannot be read: {exc.strerror or exc}") from None


def _floats(path: str, line: int, tokens: list[str], what: str) -> np.ndarray:
    try:
        values = np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise _error(path, line, f"{what}: '{bad}' is not a number") from None
    if not np.all(np.isfinite(values)):
        raise _error(path, line, f"{what} holds a value that is not a finite number")
    return values


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _parse_hierarchy(path: str, lines: _Lines) -> BvhSkeleton:
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray | None] = []
    channels: list[tuple[str, ...] | None] = []
    joint_lines: list[int] = []
    end_sites: list[tuple[int, np.ndarray]] = []

    first = lines.next()
    if first is None:
        raise _error(path, None, "empty file; a BVH file starts with HIERARCHY")
    number, tokens = first
    if tokens[0].lstrip("\ufeff").upper() != "HIERARCHY" or len(tokens) != 1:
        raise _error(path, number, f"expected HIERARCHY, found '{' '.join(tokens)[:40]}'")

    # Each open block: ("joint", index) or ("end", [offset or None, parent, line]).
    stack: list[tuple[str, object]] = []
    pending: tuple[str, object] | None = None   # a block whose '{' is still to come
    pending_line = 0

    def close_block(kind, data, at):
        if kind == "joint":
            if offsets[data] is None:
                raise _error(path, at, f"joint '{names[data]}' has no OFFSET")
            if channels[data] is None:
                channels[data] = ()
        else:
            offset, parent, _ = data
            if offset is None:
                raise _error(path, at, "End Site has no OFFSET")
            end_sites.append((parent, offset))

    while True:
        got = lines.next()
        if got is None:
            if pending is not None or stack:
                raise _error(path, lines.number + 1, "file ends inside the HIERARCHY section (truncated)")
            raise _error(path, lines.number + 1, "file ends before MOTION (truncated)")
        number, tokens = got
        key = tokens[0].upper()

        if pending is not None:
            if tokens[0] != "{":
                raise _error(path, number, f"expected '{{' to open the block started on line {pending_line}, "
                             f"found '{tokens[0]}'")
            stack.append(pending)
            pending = None
            tokens = tokens[1:]
            if not tokens:
                continue
            key = tokens[0].upper()

        if key in ("ROOT", "JOINT"):
            if key == "ROOT" and stack:
                raise _error(path, number, "ROOT inside another joint; use JOINT")
            if key == "JOINT" and (not stack or stack[-1][0] != "joint"):
                raise _error(path, number, "JOINT outside a ROOT hierarchy" if not stack else
                             "JOINT inside an End Site")
            opens = tokens[-1] == "{"
            name_tokens = tokens[1:-1] if opens else tokens[1:]
            if not name_tokens:
                raise _error(path, number, f"{tokens[0]} has no name")
            index = len(names)
            names.append(" ".join(name_tokens))
            parents.append(-1 if key == "ROOT" else int(stack[-1][1]))
            offsets.append(None)
            channels.append(None)
            joint_lines.append(number)
            block = ("joint", index)
            if opens:
                stack.append(block)
            else:
                pending, pending_line = block, number
        elif key == "END":
            if not stack or stack[-1][0] != "joint":
                raise _error(path, number, "End Site outside a joint")
            if len(tokens) > 3 and tokens[2] == "{":
                lines.push(number, tokens[3:])
                tokens = tokens[:3]
            if len(tokens) < 2 or tokens[1].upper() != "SITE" or len(tokens) > 3 or \
                    (len(tokens) == 3 and tokens[2] != "{"):
                raise _error(path, number, f"expected 'End Site', found '{' '.join(tokens)[:40]}'")
            block = ("end", [None, int(stack[-1][1]), number])
            if len(tokens) == 3:
                stack.append(block)
            else:
                pending, pending_line = block, number
        elif key == "OFFSET":
            if not stack:
                raise _error(path, number, "OFFSET outside a joint")
            if len(tokens) > 4 and not _is_float(tokens[4]):   # another statement follows
                lines.push(number, tokens[4:])
                tokens = tokens[:4]
            if len(tokens) != 4:
                raise _error(path, number, f"OFFSET needs 3 values, found {len(tokens) - 1}")
            value = _floats(path, number, tokens[1:], "OFFSET")
            kind, data = stack[-1]
            if kind == "joint":
                if offsets[data] is not None:
                    raise _error(path, number, f"second OFFSET for joint '{names[data]}'")
                offsets[data] = value
            else:
                if data[0] is not None:
                    raise _error(path, number, "second OFFSET in an End Site")
                data[0] = value
        elif key == "CHANNELS":
            if not stack or stack[-1][0] != "joint":
                raise _error(path, number, "CHANNELS outside a joint" if not stack else
                             "CHANNELS in an End Site")
            index = int(stack[-1][1])
            if channels[index] is not None:
                raise _error(path, number, f"second CHANNELS for joint '{names[index]}'")
            if len(tokens) < 2 or not _WHOLE.fullmatch(tokens[1]):
                raise _error(path, number, "CHANNELS needs a channel count")
            rest = tokens[2 + int(tokens[1]):]
            if rest and rest[0] in ("}", "{") or rest and rest[0].upper() in ("JOINT", "END"):
                lines.push(number, rest)   # another statement follows on the line
                tokens = tokens[:2 + int(tokens[1])]
            count, labels = int(tokens[1]), tokens[2:]
            if count != len(labels):
                raise _error(path, number, f"CHANNELS declares {count} channels but lists {len(labels)}")
            if count > 6:
                raise _error(path, number, f"CHANNELS declares {count} channels; a joint has at most 6")
            seen = set()
            for label in labels:
                kind = _CHANNELS.get(label.lower())
                if kind is None:
                    raise _error(path, number, f"unknown channel '{label}' (expected X/Y/Z position or "
                                 "rotation)")
                if kind in seen:
                    raise _error(path, number, f"channel '{label}' is listed twice")
                seen.add(kind)
            channels[index] = tuple(labels)
        elif key == "{":
            raise _error(path, number, "'{' without a ROOT, JOINT or End Site before it")
        elif key == "}":
            for t in tokens:
                if t != "}":
                    raise _error(path, number, f"unexpected '{t}' after '}}'")
                if not stack:
                    raise _error(path, number, "'}' without an open block")
                kind, data = stack.pop()
                close_block(kind, data, number)
        elif key == "MOTION":
            if stack:
                raise _error(path, number, "MOTION inside an open block: a '}' is missing")
            if not names:
                raise _error(path, number, "MOTION before any ROOT joint")
            if len(tokens) != 1:
                raise _error(path, number, "MOTION must stand alone on its line")
            break
        else:
            raise _error(path, number, f"unknown keyword '{tokens[0][:40]}'")

    return BvhSkeleton(path=path, names=names, parents=np.array(parents, dtype=np.int64),
                       offsets=np.array(offsets, dtype=np.float64).reshape(-1, 3),
                       channels=list(channels), lines=joint_lines, end_sites=end_sites)


_FRAMES = re.compile(r"^frames\s*:\s*(\S+)$", re.IGNORECASE)
_FRAME_TIME = re.compile(r"^frame\s+time\s*:\s*(\S+)$", re.IGNORECASE)


def _header_line(path: str, lines: _Lines, pattern: re.Pattern, what: str) -> tuple[int, str]:
    """The value of one MOTION header line (``Frames:`` or ``Frame Time:``) and its line number."""
    got = lines.next()
    if got is None:
        raise _error(path, lines.number + 1, f"file ends before '{what}:' (truncated)")
    number, tokens = got
    m = pattern.match(" ".join(tokens))
    if not m:
        raise _error(path, number, f"expected '{what}: <{'count' if what == 'Frames' else 'seconds'}>', "
                     f"found '{' '.join(tokens)[:40]}'")
    return number, m.group(1)


def _parse_motion_header(path: str, lines: _Lines, skeleton: BvhSkeleton) -> None:
    number, value = _header_line(path, lines, _FRAMES, "Frames")
    if not _WHOLE.fullmatch(value):
        raise _error(path, number, f"frame count '{value[:20]}' is not a whole number of frames (0 or more)")
    skeleton.frame_count = int(value)
    skeleton.frames_line = number
    number, value = _header_line(path, lines, _FRAME_TIME, "Frame Time")
    try:
        frame_time = float(value)
    except ValueError:
        raise _error(path, number, f"frame time '{value[:20]}' is not a number") from None
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise _error(path, number, f"frame time must be a positive number of seconds, got {value[:20]}")
    low, high = FRAME_TIME_RANGE
    if not low <= frame_time <= high:
        raise _error(path, number, f"frame time {value[:20]} s ({1.0 / frame_time:.3g} frames per second) is not a "
                     f"capture's: a frame lasts {low:g} to {high:g} s")
    skeleton.frame_time = frame_time


def read_header(path: str) -> BvhSkeleton:
    """The skeleton and MOTION header of a BVH file; frame rows are not read."""
    path = str(path)
    with _open(path) as f:
        lines = _Lines(f)
        skeleton = _parse_hierarchy(path, lines)
        _parse_motion_header(path, lines, skeleton)
    return skeleton


def _parse_rows(path: str, rows: list[tuple[int, str]], width: int) -> np.ndarray:
    """(n,width) values of frame rows given as (line number, text)."""
    flat: list[str] = []
    for number, text in rows:
        tokens = text.split()
        if len(tokens) != width:
            what = "too few" if len(tokens) < width else "too many"
            raise _error(path, number, f"frame row has {what} values: {len(tokens)} for the {width} channels "
                         "declared in HIERARCHY")
        flat.extend(tokens)
    try:
        values = np.array(flat, dtype=np.float64).reshape(len(rows), width)
    except ValueError:
        for number, text in rows:
            for token in text.split():
                if not _is_float(token):
                    raise _error(path, number, f"frame row value '{token[:20]}' is not a number") from None
        raise
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.nonzero(bad.any(axis=1))[0][0])
        col = int(np.nonzero(bad[row])[0][0])
        raise _error(path, rows[row][0], f"frame row value {col + 1} is '{rows[row][1].split()[col]}', not a "
                     "finite number")
    return values


def iter_frames(path: str, chunk_frames: int = CHUNK_FRAMES) -> Iterator[np.ndarray]:
    """Streams the frame rows as (n,C) float64 chunks of at most ``chunk_frames`` rows.

    Parses the header again on the way (a few milliseconds), then the rows; at most one
    chunk of text is held at a time. Raises on the first malformed row, on fewer rows than
    ``Frames:`` declares, and on more.
    """
    path = str(path)
    chunk_frames = max(1, int(chunk_frames))
    with _open(path) as f:
        lines = _Lines(f)
        head = _parse_hierarchy(path, lines)
        _parse_motion_header(path, lines, head)
        width, expected = head.channel_count, head.frame_count
        if width == 0 and expected > 0:
            raise _error(path, head.frames_line, "the HIERARCHY declares no channels, so no frame can hold "
                         "values")
        number, done = lines.number, 0
        rows: list[tuple[int, str]] = []
        for line in f:
            number += 1
            if line.isspace():
                continue
            if done + len(rows) == expected:
                raise _error(path, number, f"more frame rows than 'Frames: {expected}' declares")
            rows.append((number, line))
            if len(rows) == chunk_frames:
                yield _parse_rows(path, rows, width)
                done += len(rows)
                rows = []
        if rows:
            yield _parse_rows(path, rows, width)
            done += len(rows)
        if done < expected:
            raise _error(path, number + 1, f"file ends after {done} frame rows but 'Frames: {expected}' "
                         "declares more (truncated)")


def load(path: str, chunk_frames: int = CHUNK_FRAMES) -> BvhMotion:
    """Reads a whole BVH file (streamed in chunks, then joined)."""
    skeleton = read_header(path)
    chunks = list(iter_frames(path, chunk_frames))
    width = skeleton.channel_count
    values = np.concatenate(chunks) if chunks else np.zeros((0, width))
    return BvhMotion(skeleton=skeleton, values=values)


# ---- conversion -----------------------------------------------------------------------------

#: Y-up to Z-up: +90 degrees about X, (x, y, z) -> (x, -z, y).
Y_TO_Z = np.array([math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)])


def position_modes(skeleton: BvhSkeleton, values: np.ndarray | None, mode: str = "auto") -> list[str]:
    """How each joint's position channels combine with its OFFSET: "absolute" or "relative".

    ``absolute`` (the common reading, and bvhio's): the channels replace the OFFSET.
    ``relative``: they are added to it, as some exporters write a hip-rooted rig whose
    OFFSET holds the standing hip height and whose channels move about it. ``auto``
    decides per joint on the vertical (Y) channel, where the two readings differ by the
    height in the OFFSET however far the clip travels. A root with a body below it (legs)
    reads the way that puts the lowest point the body reaches over the frames nearest the
    ground (Y = 0): a clip that falls and lies, crawls or sits on the floor spends most of
    its frames low, whatever the reading. Any other joint reads ``relative`` when the median
    of its ``Yposition`` lies nearer zero than the OFFSET's Y. Joints without a
    ``Yposition`` channel read ``absolute``.
    """
    if mode not in ("auto", "absolute", "relative"):
        raise ValueError(f"position mode must be auto, absolute or relative, not {mode!r}")
    if mode != "auto":
        return [mode] * skeleton.joint_count
    modes = []
    starts = skeleton.first_channel
    for j, labels in enumerate(skeleton.channels):
        cols = [starts[j] + k for k, lab in enumerate(labels) if lab.lower() == "yposition"]
        if not cols or values is None or not len(values):
            modes.append("absolute")
            continue
        median = float(np.median(values[:, cols[0]]))
        modes.append("relative" if abs(median) < abs(median - skeleton.offsets[j, 1]) else "absolute")
    if values is not None and len(values):
        for root in np.flatnonzero(skeleton.parents < 0):
            if modes[root] == "absolute" and "yposition" not in (lab.lower() for lab in skeleton.channels[root]):
                continue
            if _depth_below(skeleton, int(root)) >= GROUND_TEST_DEPTH * max(abs(skeleton.offsets[root, 1]), 1e-9):
                modes[root] = _nearest_ground(skeleton, values, modes, int(root))
    return modes


#: A root whose body reaches below it by at least this share of the height in its OFFSET
#: (a humanoid's legs: about all of it) is read the way that keeps that body on the ground.
GROUND_TEST_DEPTH = 0.5
#: Frames of the first chunk the ground test poses, at most.
GROUND_TEST_FRAMES = 240


def _depth_below(skeleton: BvhSkeleton, root: int) -> float:
    """How far the rest pose reaches below a root along Y (file units, from the OFFSETs)."""
    y = np.zeros(skeleton.joint_count)
    below = 0.0
    for j in range(skeleton.joint_count):
        p = int(skeleton.parents[j])
        if j == root:
            y[j] = 0.0
        elif p >= 0:
            y[j] = y[p] + skeleton.offsets[j, 1]
            if _root_of(skeleton, j) == root:
                below = max(below, -y[j])
    return below


def _root_of(skeleton: BvhSkeleton, j: int) -> int:
    while int(skeleton.parents[j]) >= 0:
        j = int(skeleton.parents[j])
    return j


def _nearest_ground(skeleton: BvhSkeleton, values: np.ndarray, modes: list[str], root: int) -> str:
    """The reading of the root's position channels that puts the lowest point its body reaches
    over (a sample of) the frames nearest Y = 0."""
    from mocapedit.geometry.kinematics import compose_trs, skel_space
    sample = values[::max(1, len(values) // GROUND_TEST_FRAMES)]
    body = [j for j in range(skeleton.joint_count) if _root_of(skeleton, j) == root]
    lowest = {}
    for reading in ("absolute", "relative"):
        trial = list(modes)
        trial[root] = reading
        converter = Converter(skeleton, modes=trial)
        translations, rotations = converter(sample)
        y = skel_space(compose_trs(translations, rotations), converter.pose.parents)[..., 3, 1]
        lowest[reading] = abs(float(y[:, [converter.pose.names.index(skeleton.names[j]) for j in body]].min()))
    return "relative" if lowest["relative"] < lowest["absolute"] else "absolute"


@dataclass
class SkeletonPose:
    """The rest pose of an imported skeleton, in stage units, in USD joint order."""
    names: list[str]              # (J,) BVH joint names ("<parent> End Site" for end sites)
    joints: list[str]             # (J,) USD joint paths
    parents: np.ndarray           # (J,) parent index, -1 for a root
    rest_translations: np.ndarray  # (J,3) joint-local rest translation
    rest_rotations: np.ndarray    # (J,4) joint-local rest rotation (identity but at Z-up roots)
    bind_transforms: np.ndarray   # (J,4,4) skeleton-space rest matrices (row-vector convention)

    @property
    def rest_transforms(self) -> np.ndarray:
        """(J,4,4) joint-local rest matrices (row-vector convention)."""
        from mocapedit.geometry.kinematics import compose_trs
        return compose_trs(self.rest_translations, self.rest_rotations)

    def height(self, translations: np.ndarray, rotations: np.ndarray, up_axis: str) -> float:
        """From the lowest to the highest joint along up, stage units, of one pose given as
        (J,3) joint-local translations and (J,4) rotations (what the Converter gives)."""
        from mocapedit.geometry.kinematics import compose_trs, skel_space
        skel = skel_space(compose_trs(translations, rotations), self.parents)
        return float(np.ptp(skel[:, 3, 2 if up_axis == "Z" else 1]))


class Converter:
    """Turns BVH channel values into joint-local USD transforms, chunk after chunk.

    Args:
      skeleton: the parsed header.
      scale: stage units per BVH length unit.
      up_axis: "Y" keeps the BVH's Y-up world; "Z" turns it to Z-up at the roots.
      modes: per joint "absolute" or "relative" (see :func:`position_modes`).
      end_sites: also output each End Site as a joint that follows its parent.

    Calling it with an (n,C) chunk returns ``(translations (n,J,3), rotations (n,J,4))``
    float64 in USD joint order. Rotations continue the sign of the previous chunk's last
    frame, so feed the chunks of one clip in order to one converter.
    """

    def __init__(self, skeleton: BvhSkeleton, scale: float = 1.0, up_axis: str = "Y",
                 modes: list[str] | None = None, end_sites: bool = False):
        if up_axis not in ("Y", "Z"):
            raise ValueError(f"up axis must be Y or Z, not {up_axis!r}")
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"scale must be a positive number, got {scale}")
        self.skeleton, self.scale, self.up_axis = skeleton, float(scale), up_axis
        modes = modes or ["absolute"] * skeleton.joint_count
        j_count = skeleton.joint_count
        starts = skeleton.first_channel

        # Rotation channels: up to three per joint, (column, axis); missing ones are zero angles.
        self._rot_cols = np.zeros((j_count, 3), dtype=np.int64)
        self._rot_axes = np.zeros((j_count, 3), dtype=np.int64)
        self._rot_used = np.zeros((j_count, 3), dtype=bool)
        pos_j, pos_axis, pos_col, pos_base = [], [], [], []
        for j, labels in enumerate(skeleton.channels):
            k = 0
            for i, label in enumerate(labels):
                kind, axis = _CHANNELS[label.lower()]
                col = int(starts[j] + i)
                if kind == "r":
                    self._rot_cols[j, k], self._rot_axes[j, k], self._rot_used[j, k] = col, axis, True
                    k += 1
                else:
                    pos_j.append(j)
                    pos_axis.append(axis)
                    pos_col.append(col)
                    pos_base.append(skeleton.offsets[j, axis] if modes[j] == "relative" else 0.0)
        self._pos = (np.array(pos_j, dtype=np.int64), np.array(pos_axis, dtype=np.int64),
                     np.array(pos_col, dtype=np.int64), np.array(pos_base, dtype=np.float64))
        self._roots = np.nonzero(skeleton.parents < 0)[0]
        self._end_parents = np.array([p for p, _ in skeleton.end_sites] if end_sites else [], dtype=np.int64)
        self._end_offsets = np.array([o for _, o in skeleton.end_sites] if end_sites else [],
                                     dtype=np.float64).reshape(-1, 3)
        self._last = None          # (J,4) last output quaternion of the previous chunk
        self.pose = self._rest_pose(end_sites)

    @property
    def joint_count(self) -> int:
        return len(self.pose.joints)

    def _rest_pose(self, end_sites: bool) -> SkeletonPose:
        sk = self.skeleton
        tokens = joint_tokens(sk.names + [f"{sk.names[p]}_end" for p in self._end_parents])
        parents = np.concatenate([sk.parents, self._end_parents]).astype(np.int64)
        translations = np.concatenate([sk.offsets, self._end_offsets]) * self.scale
        rotations = np.zeros((len(parents), 4))
        rotations[:, 3] = 1.0
        if self.up_axis == "Z":
            translations[self._roots] = quat_rotate(Y_TO_Z, translations[self._roots])
            rotations[self._roots] = Y_TO_Z
        from mocapedit.geometry.kinematics import compose_trs, skel_space
        bind = skel_space(compose_trs(translations, rotations), parents)
        names = sk.names + [f"{sk.names[p]} End Site" for p in self._end_parents]
        return SkeletonPose(names=names, joints=joint_paths(tokens, parents), parents=parents,
                            rest_translations=translations, rest_rotations=rotations, bind_transforms=bind)

    def __call__(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        values = np.asarray(values, dtype=np.float64)
        n, j_count = values.shape[0], self.skeleton.joint_count
        total = self.joint_count

        translations = np.broadcast_to(self.pose.rest_translations, (n, total, 3)).copy()
        if self.up_axis == "Z":  # positions below are in the file's frame: undo the root turn first
            translations[:, self._roots] = self.skeleton.offsets[self._roots] * self.scale
        pj, pa, pc, pb = self._pos
        if pj.size:
            translations[:, pj, pa] = (values[:, pc] + pb) * self.scale

        half = np.radians(np.where(self._rot_used, values[:, self._rot_cols], 0.0)) * 0.5  # (n,J,3)
        s, c = np.sin(half), np.cos(half)
        rot = None
        rows = np.arange(j_count)
        for k in range(3):
            q = np.zeros((n, j_count, 4))
            q[:, rows, self._rot_axes[:, k]] = s[:, :, k]
            q[..., 3] = c[:, :, k]
            rot = q if rot is None else quat_multiply(rot, q)
        rotations = np.zeros((n, total, 4))
        rotations[..., 3] = 1.0
        rotations[:, :j_count] = rot

        if self.up_axis == "Z":
            roots = self._roots
            translations[:, roots] = quat_rotate(Y_TO_Z, translations[:, roots])
            rotations[:, roots] = quat_multiply(np.broadcast_to(Y_TO_Z, rotations[:, roots].shape), rotations[:, roots])

        rotations = self._continuous(rotations)
        return translations, rotations

    def _continuous(self, q: np.ndarray) -> np.ndarray:
        """Flips signs so each quaternion lies in the hemisphere of the previous frame's."""
        if not len(q):
            return q
        if self._last is None:
            # Start in the w >= 0 hemisphere.
            first = np.where(q[0, :, 3:] < 0, -1.0, 1.0)
        else:
            first = np.where(np.sum(q[0] * self._last, axis=-1, keepdims=True) < 0, -1.0, 1.0)
        steps = np.where(np.sum(q[1:] * q[:-1], axis=-1, keepdims=True) < 0, -1.0, 1.0)
        signs = np.cumprod(np.concatenate([first[None], steps]), axis=0)
        q = q * signs
        self._last = q[-1].copy()
        return q


def convert(motion: BvhMotion, scale: float = 1.0, up_axis: str = "Y", position_mode: str = "auto",
            end_sites: bool = False) -> tuple[SkeletonPose, np.ndarray, np.ndarray]:
    """A whole clip at once: (rest pose, translations (F,J,3), rotations (F,J,4))."""
    modes = position_modes(motion.skeleton, motion.values, position_mode)
    conv = Converter(motion.skeleton, scale=scale, up_axis=up_axis, modes=modes, end_sites=end_sites)
    t, r = conv(motion.values)
    return conv.pose, t, r


def find_files(directory: str) -> list[str]:
    """The .bvh files of a directory (not recursive), sorted by name."""
    return sorted(os.path.join(directory, n) for n in os.listdir(directory)
                  if n.lower().endswith(".bvh") and os.path.isfile(os.path.join(directory, n)))


__all__ = ["BvhSkeleton", "BvhMotion", "SkeletonPose", "Converter", "read_header", "iter_frames", "load",
           "convert", "position_modes", "joint_tokens", "joint_paths", "find_files", "UNITS", "CHUNK_FRAMES"]
