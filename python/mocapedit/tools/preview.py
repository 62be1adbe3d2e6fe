"""Top-down previews of a crowd: a PNG for people, an EXR for compositing.

A reader-side tool: it reads the input stage and the same stage with the edits layer
over it through :mod:`mocapedit.usd.reader` and :mod:`mocapedit.geometry.trajectory`, and solves
nothing. Constraint states and run notes come from the report the edits layer stores.

Coordinates: the view looks down the up axis. Its horizontal axis is world x; its
vertical axis is world y on a Z-up stage (y grows upwards in the image) and world z on a
Y-up stage (z grows downwards in the image, as seen from above with x to the right).
"World plan coordinates" below are these two world coordinates, (x, z) or (x, y).

The EXR is world-aligned: square pixels, pixel (i, j) (column, row from the top)
covering plan coordinates ``[i, i+1) x [j, j+1)`` after the mapping
``[a, b, 1] @ worldToPixel = [i, j, 1]`` stored in its header (row-vector convention,
as USD matrices). Channels, all 32-bit float:

- ``sourcePathDensity``: the number of agents whose source path crosses the pixel;
- ``editedPathDensity``: the same for the edited paths;
- ``displacement``: the largest distance (stage units) between an agent's edited and
  source position at the same shot time, over the edited paths crossing the pixel;
- ``overlapCount``: summed over the shot's time samples, the number of agent pairs
  whose collision capsules both cover the pixel.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
from dataclasses import dataclass, field

import numpy as np

from mocapedit.geometry import ground, trajectory
from mocapedit.inspect import inspection, overlaps
from mocapedit.solve import collisions
from mocapedit.usd import edits_format, outputs, reader, stage_io
from mocapedit.model import limits
from mocapedit.model.errors import MocapEditError
from mocapedit.inspect.inspection import Crowd, Remaining
from mocapedit.model.progress import Progress, Silent
from mocapedit.model.report import Report

DEFAULT_RESOLUTION = 1600
CHANNELS = ("sourcePathDensity", "editedPathDensity", "displacement", "overlapCount")


@dataclass
class Scene:
    """Everything a preview draws, in ground coordinates (see :mod:`mocapedit.geometry.ground`)."""
    title: str
    crowd: Crowd
    handles: list[tuple[np.ndarray, dict | None]] = field(default_factory=list)   # (ground (2,), entry)
    links: list[tuple[str, np.ndarray, dict | None]] = field(default_factory=list)  # (kind, 2x2 ground, entry)
    regions: list[tuple[str, np.ndarray, float]] = field(default_factory=list)   # (prim, Kx2 footprint, margin)
    remaining: Remaining | None = None
    # Agents whose edit spins or reverses them (from the report): (kind "spin" | "reverse", ground (2,), agent).
    implausible: list[tuple[str, np.ndarray, str]] = field(default_factory=list)
    overlap_rows: overlaps.Proximity | None = None    # every overlapping (pair, sample)
    overlap_times: np.ndarray | None = None
    report: Report | None = None
    edited: bool = False                              # an edits layer was found

    @property
    def up_axis(self) -> str:
        return self.crowd.info.up_axis


# ---- loading -------------------------------------------------------------------------------


def _trajectories(data, progress: Progress, name: str) -> dict:
    task = progress.task(name, len(data.agents), "agents")
    out = {}
    for i, (path, agent) in enumerate(data.agents.items()):
        out[path] = trajectory.extract(agent, data.clip_of(agent), data.info.up_axis, data.info.meters_per_unit)
        task.update(i + 1)
    task.done()
    return out


#: Width of the legend's column, in pixels at font scale 1 (its longest line, "collision
#: left (N pairs)", with its marker and the column's padding).
LEGEND_PIXELS = 230.0
#: The smallest PNG (width, height) its plot, legend column and labels fit in.
MIN_PNG = (200, 100)


def _font_scale(w: int, h: int) -> float:
    """How much the fonts and strokes of a w by h image are scaled from their sizes at 900 pixels."""
    return max(min(w, h) / 900.0, 0.6)


@contextlib.contextmanager
def _fixed_limits_widened():
    """Both plot limits are set on purpose and the equal aspect widens one of them
    (``adjustable="datalim"``): matplotlib's log line saying so is not for the user."""
    log = logging.getLogger("matplotlib.axes._base")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def _check_edits_match(stage_path: str, source_stage, edits_layer, progress: Progress) -> None:
    """Raises MocapEditError when ``edits_layer`` was solved for another shot (another root
    layer name and other content); notes when it was solved from this shot before it changed."""
    from pxr import Usd

    recorded = edits_format.content_hash(edits_layer)
    if not recorded or recorded == stage_io.content_hash(source_stage):
        return
    inputs = [str(x) for x in (edits_format.data(edits_layer) or {}).get(edits_format.INPUTS, [])]
    solved_for = inputs[0] if inputs else "another input"
    name = os.path.basename(edits_layer.realPath or edits_layer.identifier)
    # A composed stage sub-layers the input it was solved for: its hash is that layer's stage's.
    # Inputs recorded by where they are (a solve given an absolute path) are told apart by it
    # (seqA/shot.usda from seqB/shot.usda); a relative one only by its name (the solve ran
    # from a folder not recorded).
    def key(path: str) -> str:
        return os.path.realpath(path) if os.path.isabs(solved_for) else os.path.basename(path)

    used = {key(l.realPath or l.identifier): l for l in source_stage.GetUsedLayers()}
    if inputs and key(solved_for) not in used:
        raise MocapEditError(f"{name} was solved for {solved_for}, not {stage_path}; preview it over the "
                             f"shot it was solved for (or solve {stage_path} to get its own edits layer)")
    root = used.get(key(solved_for))
    if root is not None and root != source_stage.GetRootLayer() and \
            stage_io.content_hash(Usd.Stage.Open(root)) == recorded:
        return
    progress.message(f"note: {name} was solved from {solved_for} as it was then, and its content has "
                     f"changed since; the preview shows those edits over the shot as it is now (solve again "
                     f"to see what it gets now)")


def load(stage_path: str, edits_path: str | None = None, progress: Progress | None = None,
         sample_step: float | None = None) -> Scene:
    """Reads what a preview shows.

    Args:
      stage_path: the input stage, or a stage that already sub-layers an edits layer
        (then the source is that stage with the edits layer muted)
      edits_path: an edits layer to put over ``stage_path``
      sample_step: time codes between the samples checked for overlaps (default: the
        stage's MocapSolveSettings.sampleStep)
    """
    from pxr import Usd

    progress = progress or Silent()
    source_stage = reader.open_stage(stage_path)
    edits_layer, edited_stage = None, None
    # A composed stage sub-layers its edits layer: the source is the stage without it.
    own = edits_format.edits_layer(source_stage)
    own = own.identifier if own is not None else None   # muting it may release the layer
    if edits_path:
        if not os.path.exists(edits_path):
            raise MocapEditError(f"{edits_path}: no such file")
        given = reader.open_layer(edits_path)
        if edits_format.content_hash(given) is None:
            raise MocapEditError(f"{edits_path}: not an edits layer written by `mocapedit solve` "
                                 "(no customLayerData mocapedit)")
        if own == given.identifier:
            edits_path = None   # the stage's own: as without --edits
    if edits_path:
        if own is not None:
            source_stage.MuteLayer(own)
        edited_stage = reader.open_stage(stage_path)
        if own is not None:
            edited_stage.MuteLayer(own)
        edited_stage.GetSessionLayer().subLayerPaths.append(os.path.abspath(edits_path))
        edits_layer = given
    else:
        edits_layer = edits_format.edits_layer(source_stage)
        if edits_layer is not None:
            edited_stage = source_stage
            source_stage = Usd.Stage.Open(source_stage.GetRootLayer())
            source_stage.MuteLayer(edits_layer.identifier)

    if edits_layer is not None:
        _check_edits_match(stage_path, source_stage, edits_layer, progress)
    progress.message(f"reading {os.path.basename(stage_path)}")
    source = reader.read_stage(source_stage, progress)
    too_many = sample_step and limits.sample_step_problem(source, float(sample_step))
    if too_many:
        raise MocapEditError(f"--step: {too_many}")
    source_traj = _trajectories(source, progress, "source paths")
    edited = edited_traj = None
    if edited_stage is not None:
        edited = reader.read_stage(edited_stage, progress)
        edited_traj = _trajectories(edited, progress, "edited paths")
    crowd = inspection.from_stages(source, source_traj, edited, edited_traj)
    if sample_step:
        crowd.sample_step = float(sample_step)

    report = None
    if edits_layer is not None:
        stored = edits_format.stored_report(edits_layer)
        if stored is not None:
            report = Report.from_dict(stored)
    entries = report.constraints if report else []
    up = source.info.up_axis
    scene = Scene(title=os.path.basename(stage_path), crowd=crowd, report=report, edited=edited is not None)
    scene.handles = [(ground.to_ground(p, up), e) for p, e in inspection.handles(entries, source.position_constraints)]

    status = inspection.constraint_status(entries)
    index = crowd.index()
    for kind, constraints in (("relative", source.relative_constraints), ("sync", source.sync_constraints)):
        for c in constraints:
            ends = np.array([_edited_at_frame(crowd.agents[index[c.agent]], c.frame),
                             _edited_at_frame(crowd.agents[index[c.target]], c.target_frame)])
            scene.links.append((kind, ends, status.get(c.path)))
    scene.regions = [(r.path, region_footprint(r, up), float(r.margin)) for r in source.avoid_regions]

    scene.implausible = implausible_marks(report, crowd)
    times, found = crowd.proximity(0.0, progress)
    scene.overlap_rows, scene.overlap_times = found, times
    worst = overlaps.worst_per_pair(found)
    names = [a.path for a in crowd.agents]
    scene.remaining = Remaining([names[i] for i in worst.a], [names[i] for i in worst.b], times[worst.sample],
                                worst.clearance, crowd.contact_points(worst, times) if len(worst) else np.zeros((0, 2)))
    return scene


def implausible_marks(report: Report | None, crowd: Crowd) -> list[tuple[str, np.ndarray, str]]:
    """Where the report's plausibility figures say an edited agent spins (turns more than 15
    degrees per frame at 60 fps where its source does not) or walks back (over 90 degrees from
    its source direction): ``(kind, ground point on the edited path, agent)``, sorted by agent."""
    if report is None:
        return []
    index, out = crowd.index(), []
    for path in sorted(report.agents):
        p = report.agents[path].get("plausibility")
        if not p or path not in index:
            continue
        agent = crowd.agents[index[path]]
        if p.get("spinFrames", 0) > 0:
            out.append(("spin", _edited_at_frame(agent, p.get("worstTurnFrame", 0)), path))
        deviation = p.get("maxDirectionDeviation")   # reports written before "reverses" was
        if p.get("reverses", deviation is not None and np.isfinite(deviation) and deviation > 90.0):
            out.append(("reverse", _edited_at_frame(agent, p.get("worstDirectionFrame", 0)), path))
    return out


def _edited_at_frame(agent: inspection.AgentTracks, frame: int) -> np.ndarray:
    """Ground position of a source frame on the edited track. A re-timed clip is baked on
    shot frames, so the frame is then placed at its source time (an approximation)."""
    src, out = agent.source, agent.edited
    frame = int(np.clip(frame, 0, len(src.times) - 1))
    if len(out.times) == len(src.times):
        return out.ground[frame]
    return out.at(np.array([src.times[frame]]))[0]


def region_footprint(region, up_axis: str, segments: int = 96) -> np.ndarray:
    """#K by 2 ground polygon (counter-clockwise) of an avoid region, margin not included: the
    footprint the solve avoids (:func:`mocapedit.solve.collisions.region_footprint`), a circle
    drawn with ``segments`` sides."""
    return collisions.outline(collisions.region_footprint(region, up_axis), sides=segments)


def offset_polygon(poly: np.ndarray, distance: float) -> np.ndarray:
    """A counter-clockwise convex polygon pushed outwards by ``distance`` (mitred corners)."""
    if distance <= 0:
        return poly
    edges = np.roll(poly, -1, axis=0) - poly
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=-1)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    before = np.roll(normals, 1, axis=0)
    miter = (normals + before) / np.maximum(1.0 + np.sum(normals * before, axis=1, keepdims=True), 1e-6)
    return poly + distance * miter


# ---- the view: bounds and the world-to-pixel mapping -----------------------------------------


def plan(uv: np.ndarray, up_axis: str) -> np.ndarray:
    """Ground coordinates -> world plan coordinates ((x, z) on Y-up, (x, y) on Z-up)."""
    uv = np.asarray(uv, dtype=np.float64)
    return uv * (1.0, -1.0) if up_axis == "Y" else uv.copy()


def ground_from_plan(ab: np.ndarray, up_axis: str) -> np.ndarray:
    return plan(ab, up_axis)  # the flip is its own inverse


def scene_bounds(scene: Scene) -> np.ndarray:
    """2 by 2 ground box [[umin, vmin], [umax, vmax]] around everything drawn, padded."""
    pts = [np.concatenate([a.source.ground, a.edited.ground]) for a in scene.crowd.agents]
    pts += [h.reshape(1, 2) for h, _ in scene.handles]
    pts += [offset_polygon(poly, margin) for _, poly, margin in scene.regions]
    pts = np.concatenate(pts) if pts else np.zeros((1, 2))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    radius = max((a.radius for a in scene.crowd.agents), default=0.0)
    pad = max(0.05 * float((hi - lo).max()), 2.0 * radius, scene.crowd.info.metres(1.0))
    return np.array([lo - pad, hi + pad])


def bounds_from_plan(values: list[float], up_axis: str) -> np.ndarray:
    """``--bounds MINA MINB MAXA MAXB`` (world plan coordinates) -> ground box."""
    a0, b0, a1, b1 = (float(v) for v in values)
    if not (a1 > a0 and b1 > b0):
        raise MocapEditError(f"--bounds: the maximum must exceed the minimum on both axes, got {values}")
    corners = ground_from_plan(np.array([[a0, b0], [a1, b1]]), up_axis)
    return np.array([corners.min(axis=0), corners.max(axis=0)])


#: The longest side a preview may have: at 8192 x 8192 the four float channels of an EXR take 1 GiB.
MAX_RESOLUTION = 8192


def parse_resolution(text: str | int | None) -> tuple[int | None, int | None, int]:
    """'N' (the longer side) or 'WxH' -> (width or None, height or None, longer side)."""
    if text is None:
        return None, None, DEFAULT_RESOLUTION
    text = str(text).lower()
    try:
        w, h = (int(v) for v in text.split("x", 1)) if "x" in text else (None, None)
        longest = max(w, h) if w is not None else int(text)
        if (w is None or min(w, h) > 0) and 0 < longest <= MAX_RESOLUTION:
            return w, h, longest
        if longest > MAX_RESOLUTION:
            raise MocapEditError(f"--resolution: at most {MAX_RESOLUTION} pixels a side, got '{text}'")
    except ValueError:
        pass
    raise MocapEditError(f"--resolution: expected N or WxH (pixels), got '{text}'")


@dataclass
class Grid:
    """A world-aligned pixel grid over the ground: square pixels of ``pixel`` stage units,
    row 0 at the top of the view."""
    width: int
    height: int
    pixel: float
    u0: float                     # ground u of the left edge
    v1: float                     # ground v of the top edge
    up_axis: str

    @classmethod
    def fit(cls, box: np.ndarray, resolution, up_axis: str) -> "Grid":
        w, h, longest = parse_resolution(resolution)
        span = box[1] - box[0]
        if w is None:
            pixel = float(span.max()) / longest
            w, h = max(1, int(np.ceil(span[0] / pixel - 1e-9))), max(1, int(np.ceil(span[1] / pixel - 1e-9)))
        else:
            pixel = max(float(span[0]) / w, float(span[1]) / h)
        centre = box.mean(axis=0)
        return cls(w, h, pixel, float(centre[0] - 0.5 * w * pixel), float(centre[1] + 0.5 * h * pixel), up_axis)

    def to_pixel(self, uv: np.ndarray) -> np.ndarray:
        """(...,2) ground -> continuous (column, row)."""
        uv = np.asarray(uv, dtype=np.float64)
        return np.stack([(uv[..., 0] - self.u0) / self.pixel, (self.v1 - uv[..., 1]) / self.pixel], axis=-1)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Ground u of each column's centre (W,), v of each row's centre (H,)."""
        return (self.u0 + (np.arange(self.width) + 0.5) * self.pixel,
                self.v1 - (np.arange(self.height) + 0.5) * self.pixel)

    def world_to_pixel(self) -> np.ndarray:
        """3 by 3 matrix M with [a, b, 1] @ M = [column, row, 1] for world plan (a, b)."""
        s = 1.0 / self.pixel
        b_sign = s if self.up_axis == "Y" else -s     # Y-up: b = z = -v; Z-up: b = y = v
        return np.array([[s, 0.0, 0.0], [0.0, b_sign, 0.0], [-self.u0 * s, self.v1 * s, 1.0]])


# ---- the EXR channels -------------------------------------------------------------------------


def _along(track: inspection.Track, step: float):
    """Points (#K by 2) and shot times (#K) along a track, at most ``step`` apart."""
    g, t = track.ground, track.times
    if len(g) == 1:
        return g.copy(), t.copy()
    seg = np.linalg.norm(np.diff(g, axis=0), axis=1)
    n = np.maximum(np.ceil(seg / step).astype(np.int64), 1)
    k = np.repeat(np.arange(len(seg)), n)
    f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    pts = g[k] + f[:, None] * (g[k + 1] - g[k])
    times = t[k] + f * (t[k + 1] - t[k])
    return np.vstack([pts, g[-1:]]), np.concatenate([times, t[-1:]])


def _pixels(grid: Grid, uv: np.ndarray) -> np.ndarray:
    """Flat pixel index of each ground point, -1 outside the grid."""
    px = np.floor(grid.to_pixel(uv)).astype(np.int64)
    inside = (px[:, 0] >= 0) & (px[:, 0] < grid.width) & (px[:, 1] >= 0) & (px[:, 1] < grid.height)
    return np.where(inside, px[:, 1] * grid.width + px[:, 0], -1)


def rasterize(scene: Scene, grid: Grid, progress: Progress | None = None) -> dict[str, np.ndarray]:
    """The four EXR channels, each #H by #W float32 (row 0 at the top)."""
    progress = progress or Silent()
    n = grid.width * grid.height
    step = 0.5 * grid.pixel
    src_keys, out_keys = [], []
    displacement = np.zeros(n)
    agents = scene.crowd.agents
    task = progress.task("rasterize paths", len(agents), "agents")
    for i, a in enumerate(agents):
        pts, _ = _along(a.source, step)
        pix = np.unique(_pixels(grid, pts))
        src_keys.append(pix[pix >= 0])
        pts, times = _along(a.edited, step)
        pix = _pixels(grid, pts)
        ok = pix >= 0
        out_keys.append(np.unique(pix[ok]))
        if a.edited_flag and ok.any():
            d = np.linalg.norm(pts[ok] - a.source.at(times[ok]), axis=1)
            np.maximum.at(displacement, pix[ok], d)
        task.update(i + 1)
    task.done()
    channels = {
        "sourcePathDensity": np.bincount(np.concatenate(src_keys or [np.zeros(0, np.int64)]), minlength=n),
        "editedPathDensity": np.bincount(np.concatenate(out_keys or [np.zeros(0, np.int64)]), minlength=n),
        "displacement": displacement,
        "overlapCount": _overlap_count(scene, grid),
    }
    return {k: v.reshape(grid.height, grid.width).astype(np.float32) for k, v in channels.items()}


def _overlap_count(scene: Scene, grid: Grid) -> np.ndarray:
    count = np.zeros((grid.height, grid.width))
    rows, times = scene.overlap_rows, scene.overlap_times
    if rows is None or len(rows) == 0:
        return count.ravel()
    agents = scene.crowd.agents
    uc, vc = grid.centres()
    for s, ia, ib in zip(rows.sample, rows.a, rows.b):
        t = times[s:s + 1]
        pa, pb = agents[ia].edited.at(t)[0], agents[ib].edited.at(t)[0]
        ra, rb = agents[ia].radius, agents[ib].radius
        lo = np.maximum(pa - ra, pb - rb)
        hi = np.minimum(pa + ra, pb + rb)
        c0, r0 = np.floor(grid.to_pixel([lo[0], hi[1]])).astype(int)
        c1, r1 = np.floor(grid.to_pixel([hi[0], lo[1]])).astype(int)
        c0, r0 = max(c0, 0), max(r0, 0)
        c1, r1 = min(c1, grid.width - 1), min(r1, grid.height - 1)
        if c1 < c0 or r1 < r0:
            continue
        u, v = np.meshgrid(uc[c0:c1 + 1], vc[r0:r1 + 1])
        inside = (((u - pa[0]) ** 2 + (v - pa[1]) ** 2 <= ra * ra) &
                  ((u - pb[0]) ** 2 + (v - pb[1]) ** 2 <= rb * rb))
        if inside.any():
            count[r0:r1 + 1, c0:c1 + 1] += inside
        else:  # a lens smaller than a pixel still counts, where the two agents meet
            pix = _pixels(grid, (0.5 * (pa + pb))[None])[0]
            if pix >= 0:
                count.ravel()[pix] += 1
    return count.ravel()


def write_exr(scene: Scene, path: str, resolution=None, bounds: np.ndarray | None = None,
              progress: Progress | None = None) -> Grid:
    """Writes the world-aligned float image; returns its grid."""
    import OpenEXR

    up = scene.up_axis
    grid = Grid.fit(scene_bounds(scene) if bounds is None else bounds, resolution, up)
    channels = rasterize(scene, grid, progress)
    info = scene.crowd.info
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "mocapedit:worldToPixel": grid.world_to_pixel(),
        "mocapedit:pixelSize": float(grid.pixel),
        "mocapedit:planAxes": "x z" if up == "Y" else "x y",
        "mocapedit:upAxis": up,
        "mocapedit:metersPerUnit": float(info.meters_per_unit),
        "comments": (f"mocapedit top view of {scene.title}. [a, b, 1] @ mocapedit:worldToPixel = "
                     f"[column, row, 1] for world ({'x, z' if up == 'Y' else 'x, y'}); pixels are "
                     f"{grid.pixel:g} stage units square. Channels: path densities (agents per pixel), "
                     "displacement (stage units), overlap count (agent pairs x time samples)."),
    }
    outputs.save_with(path, lambda tmp: OpenEXR.File(header, channels).write(tmp))
    return grid


# ---- the PNG ---------------------------------------------------------------------------------

UNCHANGED = (0.42, 0.45, 0.55)
#: Up to this many agents, each path is labelled with the agent's name.
LABELLED_AGENTS = 40
#: Up to this many collisions, each is labelled with its shot time.
LABELLED_COLLISIONS = 20


def _nice_length(span_m: float) -> float:
    """A round length in metres (1, 2 or 5 times a power of ten) near a fifth of the view."""
    target = max(span_m / 5.0, 1e-6)
    power = 10.0 ** np.floor(np.log10(target))
    for k in (5.0, 2.0, 1.0):
        if k * power <= target:
            return k * power
    return power


def _metres_label(m: float) -> str:
    if m >= 1000:
        return f"{m / 1000:g} km"
    if m >= 1:
        return f"{m:g} m"
    return f"{m * 100:g} cm"


def write_png(scene: Scene, path: str, resolution=None, bounds: np.ndarray | None = None,
              progress: Progress | None = None) -> np.ndarray:
    """Draws the top view for people. Returns the 3 by 3 world-plan-to-pixel matrix, which
    the PNG also stores as JSON in its ``mocapedit:worldToPixel`` text chunk."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib import patches
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    from mocapedit.pipeline import guides as colors

    progress = progress or Silent()
    task = progress.task("draw", 5)
    up = scene.up_axis
    info = scene.crowd.info
    box = scene_bounds(scene) if bounds is None else bounds
    lo, hi = plan(box, up).min(axis=0), plan(box, up).max(axis=0)
    span = hi - lo
    w, h, longest = parse_resolution(resolution)
    # The plot keeps the view's aspect; a column on the right holds the legend.
    legend_frac, margin = 0.26, 0.07
    if w is None:
        aspect = span[1] / span[0]
        plot_w = longest * (1.0 - legend_frac - margin) if aspect <= 1.0 else None
        if plot_w is not None:
            w = longest
            h = int(round(plot_w * aspect / (1.0 - 2 * margin)))
            h = max(h, int(0.45 * w), MIN_PNG[1])
        else:
            h = longest
            plot_h = h * (1.0 - 2 * margin)
            w = int(round(plot_h / aspect / (1.0 - legend_frac - margin)))
            w = max(w, int(0.6 * h), MIN_PNG[0])
    if w < MIN_PNG[0] or h < MIN_PNG[1]:
        raise MocapEditError(f"--resolution: a PNG preview needs at least {MIN_PNG[0]} x {MIN_PNG[1]} pixels for "
                             f"its plot, legend and labels (this one would be {w} x {h}); ask for more, or write "
                             "an .exr, which has no legend")
    # The legend's text needs about LEGEND_PIXELS at the scale of the fonts below, whatever
    # the image's width: a narrow image gives its column a larger share.
    legend_frac = max(legend_frac, LEGEND_PIXELS * _font_scale(w, h) / w)
    dpi = 100.0
    fig = Figure(figsize=(w / dpi, h / dpi), dpi=dpi)
    # Draw on the canvas savefig uses, so the limits the aspect fixes at the draw below are
    # the ones saved (a narrow view has one axis widened, and the matrix must know it).
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    FigureCanvasAgg(fig)
    scale = _font_scale(w, h)                 # fonts and strokes follow the image size
    # The title block above the plot, laid out in pixels: the title's line, a gap, the
    # subtitle's line, a gap; the plot starts below it (or at the usual margin, if lower).
    pt = dpi / 72.0
    title_top = 0.25 * margin * h
    sub_top = title_top + 1.3 * 12 * scale * pt + 2.0
    top = max(margin * h, sub_top + 1.3 * 9 * scale * pt + 4.0) / h
    # Below it, the tick labels and the axis label (9 points each, and the ticks).
    bottom = max(margin * h, 2 * 1.4 * 9 * scale * pt + 18.0) / h
    ax = fig.add_axes((margin, bottom, 1.0 - legend_frac - margin, 1.0 - bottom - top))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    if up == "Y":
        ax.invert_yaxis()               # seen from above, z grows downwards
    unit = {1.0: "m", 0.01: "cm", 0.001: "mm"}.get(info.meters_per_unit, "stage units")
    ax.set_xlabel(f"x ({unit})", fontsize=9 * scale)
    ax.set_ylabel(f"{'z' if up == 'Y' else 'y'} ({unit})", fontsize=9 * scale)
    ax.tick_params(labelsize=8 * scale)
    ax.grid(True, color=(0.9, 0.9, 0.92), linewidth=0.6 * scale, zorder=0)
    ax.set_facecolor("white")

    agents = scene.crowd.agents
    legend = []
    for _, poly, margin_len in scene.regions:
        ab = plan(poly, up)
        ax.add_patch(patches.Polygon(ab, closed=True, facecolor=(0.9, 0.2, 0.15, 0.12),
                                     edgecolor=(0.8, 0.15, 0.1), hatch="//", linewidth=1.2 * scale, zorder=1))
        if margin_len > 0:
            ax.add_patch(patches.Polygon(plan(offset_polygon(poly, margin_len), up), closed=True, fill=False,
                                         edgecolor=(0.8, 0.15, 0.1), linestyle="--", linewidth=0.8 * scale,
                                         zorder=1))
    if scene.regions:
        legend.append(patches.Patch(facecolor=(0.9, 0.2, 0.15, 0.12), edgecolor=(0.8, 0.15, 0.1), hatch="//",
                                    label=f"avoid region ({len(scene.regions)})"))
    task.update(1)

    changed = [a for a in agents if a.edited_flag]
    same = [a for a in agents if not a.edited_flag]
    lw = 1.0 * scale
    if same:
        ax.add_collection(LineCollection([plan(a.source.ground, up) for a in same], colors=[UNCHANGED],
                                         linewidths=lw, zorder=2))
        legend.append(Line2D([], [], color=UNCHANGED, linewidth=lw, label=f"unchanged path ({len(same)})"))
    if changed:
        ax.add_collection(LineCollection([plan(a.source.ground, up) for a in changed], colors=[colors.SOURCE],
                                         linewidths=lw, linestyles=(0, (4, 2)), zorder=2))
        ax.add_collection(LineCollection([plan(a.edited.ground, up) for a in changed], colors=[colors.EDITED],
                                         linewidths=2.0 * lw, zorder=3))
        legend.append(Line2D([], [], color=colors.SOURCE, linewidth=lw, linestyle=(0, (4, 2)),
                             label="source path (edited agents)"))
        legend.append(Line2D([], [], color=colors.EDITED, linewidth=2.0 * lw, label=f"edited path ({len(changed)})"))
    if agents:
        starts = plan(np.array([a.edited.ground[0] for a in agents]), up)
        ax.scatter(starts[:, 0], starts[:, 1], s=9 * scale ** 2, color=(0.25, 0.25, 0.3), zorder=4, linewidths=0)
        legend.append(Line2D([], [], marker="o", linestyle="", color=(0.25, 0.25, 0.3),
                             markersize=3 * scale, label="start of each path"))
        # Which way each agent goes: an arrow head on the last step that moves.
        heads, dirs = [], []
        for a in agents:
            g = plan(a.edited.ground, up)
            step = np.diff(g, axis=0)
            moving = np.flatnonzero(np.linalg.norm(step, axis=1) > 1e-9)
            if len(moving):
                heads.append(g[moving[-1] + 1])
                dirs.append(step[moving[-1]] / np.linalg.norm(step[moving[-1]]))
        if heads:
            heads, dirs = np.array(heads), np.array(dirs)
            size = 9.0 * scale                  # arrow length in pixels, whatever the view's size
            ax.quiver(heads[:, 0], heads[:, 1], dirs[:, 0] * size, dirs[:, 1] * size, angles="xy",
                      scale_units="dots", scale=1.0, units="dots", width=1.3 * scale, headwidth=5,
                      headlength=6, headaxislength=5.5, pivot="tip", color=(0.25, 0.25, 0.3), zorder=4)
        if len(agents) <= LABELLED_AGENTS:
            for a in agents:
                end = plan(a.edited.ground[-1], up)
                ax.annotate(a.path.rsplit("/", 1)[-1], end, xytext=(4, 3), textcoords="offset points",
                            fontsize=7 * scale, color=(0.3, 0.3, 0.35), zorder=8)
    task.update(2)

    for kind, color, style in (("relative", colors.RELATIVE, "-"), ("sync", colors.SYNC, ":")):
        links = [(ends, e) for k, ends, e in scene.links if k == kind]
        if not links:
            continue
        segs = [plan(ends, up) for ends, _ in links]
        cols = [colors.status_color(e, color) if e is not None else color for _, e in links]
        ax.add_collection(LineCollection(segs, colors=cols, linewidths=1.4 * lw, linestyles=style, zorder=5))
        legend.append(Line2D([], [], color=color, linewidth=1.4 * lw, linestyle=style,
                             label=f"{kind} constraint link ({len(links)})"))
        unmet = sum(1 for _, e in links if e is not None and not e.get("met", True))
        if unmet:
            legend.append(Line2D([], [], color=colors.NOT_MET, linewidth=1.4 * lw, linestyle=style,
                                 label=f"{kind} link not met ({unmet})"))
    if scene.handles:
        pts = plan(np.array([p for p, _ in scene.handles]), up)
        states = [(colors.MET, "constraint met"), (colors.NOT_MET, "constraint not met"),
                  (colors.NOT_REPORTED, "constraint (not solved)")]
        cols = [colors.status_color(e) for _, e in scene.handles]
        ax.scatter(pts[:, 0], pts[:, 1], s=60 * scale ** 2, c=cols, edgecolors="black",
                   linewidths=0.8 * scale, zorder=6)
        for color, label in states:
            n = sum(1 for c in cols if c == color)
            if n:
                legend.append(Line2D([], [], marker="o", linestyle="", markerfacecolor=color,
                                     markeredgecolor="black", markersize=7 * scale, label=f"{label} ({n})"))
    task.update(3)

    remaining = scene.remaining
    if remaining is not None and len(remaining.a):
        pts = plan(remaining.ground, up)
        ax.scatter(pts[:, 0], pts[:, 1], s=110 * scale ** 2, marker="X", color=colors.COLLISION,
                   edgecolors="black", linewidths=0.6 * scale, zorder=7)
        n = len(remaining.a)
        legend.append(Line2D([], [], marker="X", linestyle="", markerfacecolor=colors.COLLISION,
                             markeredgecolor="black", markersize=9 * scale,
                             label=f"collision left ({n} pair{'s' if n != 1 else ''})"))
        if n <= LABELLED_COLLISIONS:
            for p, t in zip(pts, remaining.time):
                ax.annotate(f"t={t:g}", p, xytext=(7, -10), textcoords="offset points", fontsize=7.5 * scale,
                            color=(0.6, 0.0, 0.35), zorder=8)

    for kind, marker, label in (("spin", "*", "spins (over 15 deg/frame)"),
                                ("reverse", "v", "walks back against its edit")):
        marks = [g for k, g, _ in scene.implausible if k == kind]
        if marks:
            pts = plan(np.array(marks), up)
            ax.scatter(pts[:, 0], pts[:, 1], s=150 * scale ** 2, marker=marker, color=colors.NOT_MET,
                       edgecolors="black", linewidths=0.6 * scale, zorder=7)
            legend.append(Line2D([], [], marker=marker, linestyle="", markerfacecolor=colors.NOT_MET,
                                 markeredgecolor="black", markersize=10 * scale, label=f"{label} ({len(marks)})"))

    view_m = float(span[0]) * info.meters_per_unit
    bar_m = _nice_length(view_m)
    bar = AnchoredSizeBar(ax.transData, bar_m / info.meters_per_unit, _metres_label(bar_m), loc="lower left",
                          pad=0.6, borderpad=0.8, sep=4, frameon=True, size_vertical=0.0,
                          fontproperties={"size": 9 * scale}, color="black")
    bar.patch.set_alpha(0.8)
    ax.add_artist(bar)
    task.update(4)

    counts = (f"{len(agents)} agents, {len(changed)} edited" if scene.edited else
              f"{len(agents)} agents (no edits)")
    fig.suptitle(f"{scene.title}: top view", x=margin, ha="left", va="top", y=1.0 - title_top / h,
                 fontsize=12 * scale, fontweight="bold")
    fig.text(margin, 1.0 - sub_top / h, counts + f"; looking down {up}", va="top", fontsize=9 * scale,
             color=(0.3, 0.3, 0.3))
    fig.legend(handles=legend, loc="upper left", bbox_to_anchor=(1.0 - legend_frac + 0.015, 1.0 - top),
               fontsize=8.5 * scale, frameon=False, title="legend", title_fontsize=9.5 * scale,
               alignment="left")
    with _fixed_limits_widened():
        fig.canvas.draw()
        ax.apply_aspect()   # the base canvas does not draw: settle the equal-aspect limits savefig will use
    affine = ax.transData.get_affine().get_matrix()       # [xd, yd, 1] = A @ [a, b, 1], origin bottom left
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, fig.bbox.height], [0.0, 0.0, 1.0]])
    to_pixel = (flip @ affine).T                           # row-vector convention, row 0 at the top
    meta = {"mocapedit:worldToPixel": json.dumps(to_pixel.tolist()),
            "mocapedit:planAxes": "x z" if up == "Y" else "x y", "Software": "mocapedit"}
    with _fixed_limits_widened():
        outputs.save_with(path, lambda tmp: fig.savefig(tmp, format="png", dpi=dpi, metadata=meta))
    task.done()
    return to_pixel


def write(scene: Scene, path: str, resolution=None, bounds: np.ndarray | None = None,
          progress: Progress | None = None):
    """Writes a PNG or an EXR preview, by the file's extension."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".png":
        return write_png(scene, path, resolution, bounds, progress)
    if ext == ".exr":
        return write_exr(scene, path, resolution, bounds, progress)
    raise MocapEditError(f"{path}: the preview is written as .png or .exr, not '{ext or 'no extension'}'")
