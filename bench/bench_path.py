"""Path editing: the two-step ARAP solve (mocapedit.solve.path_edit, _solver.path_edit_*).

Figures, each next to the same two-step solve written with scipy.sparse (``path_peer``:
real unknowns, hard constraints as Lagrange rows, SuperLU on the KKT system of the
normal equations), measured in the same run on the same terms:

- one agent, 1,000 frames, three hard constraints, full setup and solve (DESIGN.md: under
  0.5 ms): the pass's own path (``ComponentProblem``), split into the solver calls
  (``path_edit_precompute``, ``path_edit_solve`` and freeing the factor) and the Python
  around them, and the C++ calls alone;
- a re-solve after a dragged handle (under 50 us): ``PathEditor.move`` against the peer's
  solve with its factorization kept, and the ``path_edit_solve`` call alone;
- 20,000 frames: time, and accuracy where the exact answer is known (handles a
  similarity meets: step 1 must return that similarity) and against a QR reference on a
  bend; with the condition number of step 1's normal matrix;
- a group of 100 agents x 500 frames turned by one edit (under 50 ms), and a relay of 78
  agents x 500 frames tied by hard relative constraints (under 50 ms), each split as the
  single path is;
- the example stages of ``example_stages/stages_path.py``, solved through ``solve``: the
  path pass's time and, per edited agent, the foot skate (``measure.foot_skate``, m/s,
  measured over the source's contact frames) before and after, and the length ratio.

Times are the best of many runs (solves: 500 or 2,000 runs; groups and relays: 41, whose
median is recorded too; their peers 3 to 30). The shared two-core machine this was
developed on runs the same code in two speed modes, for spells of milliseconds to seconds:
2,000 re-solves in blocks of 250 took at best 39 us in every block, with block medians of
either 40 or 60-65 us. A best of few runs can fall entirely in the slow mode.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from path_peer import PeerProblem  # noqa: E402

from mocapedit import _solver
from mocapedit.solve import path_edit  # noqa: E402
from mocapedit.solve.path_editor import PathEditor  # noqa: E402

FPS = 24.0
STEP, SWAY = 1.4 / FPS, 0.03   # metres per frame, sway amplitude


def _walk(frames, origin=(0.0, 0.0), heading=np.pi / 2):
    f = np.arange(frames, dtype=np.float64)
    along, across = f * STEP, SWAY * np.sin(2 * np.pi * f / FPS)
    d = np.array([np.cos(heading), np.sin(heading)])
    n = np.array([-d[1], d[0]])
    return np.asarray(origin) + along[:, None] * d + across[:, None] * n


def _settings():
    # As the path pass sets them for a metre stage at 24 fps.
    return path_edit.Settings(min_baseline=0.01, rigid_min_extent=0.02, still=1e-5, group_step=12.0)


def _agent(path, rest, times=None):
    from mocapedit.geometry import trajectory
    return path_edit.AgentInput(path=path, rest=rest, source=rest, source_heading=trajectory.headings(rest, [], 1.0),
                                stationary=[], sample_times=np.arange(len(rest), dtype=np.float64)
                                if times is None else times)


class _SolverClock:
    """Seconds spent inside ``path_edit_precompute`` and ``path_edit_solve`` (and in freeing
    the factorization): what the C++ solve costs, against the Python that builds the
    problem around it and reads the results."""

    def __init__(self):
        self.seconds = 0.0

    def __enter__(self):
        self._saved = _solver.path_edit_precompute, _solver.path_edit_solve

        def timed(fn):
            def call(*args, **kwargs):
                t = time.perf_counter()
                try:
                    return fn(*args, **kwargs)
                finally:
                    self.seconds += time.perf_counter() - t
            return call
        _solver.path_edit_precompute, _solver.path_edit_solve = map(timed, self._saved)
        return self

    def __exit__(self, *exc):
        _solver.path_edit_precompute, _solver.path_edit_solve = self._saved

    def free(self, problem) -> None:
        """Drops the last reference to a problem, timing it with the solver (the factor's
        destructor is most of it)."""
        t = time.perf_counter()
        problem.data = None
        self.seconds += time.perf_counter() - t


def _setup_and_solve(build, repeat: int) -> dict:
    """Best wall time of ``build().solve()`` over ``repeat`` runs, and of the two parts of a
    run: the solver calls, and the Python around them (each its best over the runs); and
    the median wall time."""
    total = python = solver = float("inf")
    times = []
    with _SolverClock() as clock:
        for _ in range(repeat):
            clock.seconds = 0.0
            t = time.perf_counter()
            problem = build()
            problem.solve()
            clock.free(problem)
            elapsed = time.perf_counter() - t
            times.append(elapsed)
            total, python, solver = min(total, elapsed), min(python, elapsed - clock.seconds), min(solver, clock.seconds)
    return {"seconds": total, "pythonSeconds": python, "solverSeconds": solver,
            "medianSeconds": float(np.median(times))}


def _peer(problem: path_edit.ComponentProblem) -> PeerProblem:
    return PeerProblem(problem.rest, problem.triangles, problem.triangle_weights, problem.edges,
                       problem.edge_weights, problem.handle_vertex, problem.handle_weight, problem.link_vertex,
                       problem.link_weight)


def _peer_solve(problem, peer):
    return peer.solve(problem.handle_positions(), problem._link_offsets(None))


def _single(ctx, frames=1000):
    rest = _walk(frames)
    handles = [0, frames // 2, frames - 1]
    pos = rest[handles].copy()
    pos[1] += [1.0, 0.0]   # the middle dragged 1 m sideways
    hs = [path_edit.Handle("a", f, p, np.inf, f"h{f}") for f, p in zip(handles, pos)]

    agent = _agent("a", rest)

    def build():
        return path_edit.ComponentProblem([agent], hs, [], [], _settings())

    def cpp_only():
        tri, edg = _solver.chain_terms(rest, 0, frames, 0.01)
        d = _solver.path_edit_precompute(rest=rest, triangles=tri, edges=edg, handles=np.array(handles),
                                         handle_weights=np.full(3, np.inf))
        return _solver.path_edit_solve(d, pos, np.zeros((0, 2)))

    problem = path_edit.ComponentProblem([_agent("a", rest)], hs, [], [], _settings())
    result = problem.solve()

    def peer():
        p = _peer(problem)
        return p, _peer_solve(problem, p)

    build().solve()
    split = _setup_and_solve(build, repeat=500)
    setup = split["seconds"]
    setup_cpp = ctx.best_of(cpp_only, repeat=50)
    setup_peer = ctx.best_of(peer, repeat=5)
    peer_problem, peer_ground = peer()
    ground = result.agents["a"].ground

    editor = PathEditor(rest, handles, pos)
    moves = iter(pos[1] + np.linspace([0.5, 0.0], [1.5, 0.0], 2000))
    resolve = ctx.best_of(lambda: editor.move(1, next(moves)), repeat=2000)
    moved = editor.ground.copy()
    raw = ctx.best_of(lambda: _solver.path_edit_solve(editor.problem.data, editor._positions, editor._links),
                      repeat=2000)
    hp = problem.handle_positions()
    resolve_peer = ctx.best_of(lambda: peer_problem.solve(hp), repeat=30)
    return {
        "frames": frames, "constraints": 3, "solver": result.solver,
        "setupSolveSeconds": setup, "setupSolvePythonSeconds": split["pythonSeconds"],
        "setupSolveSolverSeconds": split["solverSeconds"], "setupSolveCppSeconds": setup_cpp,
        "peerSetupSolveSeconds": setup_peer,
        "setupSolveSpeedupVsPeer": round(setup_peer / setup, 1), "setupSolveTarget": 0.5e-3,
        "maxDifferenceVsPeer": float(np.abs(ground - peer_ground).max()),
        "lengthRatio": float(np.linalg.norm(np.diff(ground, axis=0), axis=1).sum() /
                             np.linalg.norm(np.diff(rest, axis=0), axis=1).sum()),
        "resolveSeconds": resolve, "resolveSolverSeconds": raw, "peerResolveSeconds": resolve_peer,
        "resolveMaxDifferenceVsFullSolve": float(np.abs(moved - path_edit.ComponentProblem(
            [agent], [path_edit.Handle("a", f, p, np.inf, "") for f, p in zip(handles, editor.positions)], [], [],
            _settings()).solve().agents["a"].ground).max()),
        "resolveSpeedupVsPeer": round(resolve_peer / resolve, 1), "resolveTarget": 50e-6,
    }


def _long(ctx, frames=20000):
    rest = _walk(frames)
    tri, edg = _solver.chain_terms(rest, 0, frames, 0.01)
    handles = np.array([0, frames // 3, frames - 1])
    z = rest[:, 0] + 1j * rest[:, 1]
    sim = 1.1 * np.exp(0.3j)
    exact = sim * z + (3.0 - 2.0j)
    similar = np.stack([exact[handles].real, exact[handles].imag], axis=1)
    bent = rest[handles].copy()
    bent[1] += [15.0, 0.0]
    out = {"frames": frames}
    for name, force_qr in (("ldlt", False), ("qr", True)):
        data = {}

        def run():
            data["d"] = _solver.path_edit_precompute(rest=rest, triangles=tri, edges=edg, handles=handles,
                                                     handle_weights=np.full(3, np.inf), force_qr=force_qr)
            data["sim"] = _solver.path_edit_solve(data["d"], similar, np.zeros((0, 2)))
        seconds = ctx.best_of(run, repeat=2)
        shape = np.asarray(data["sim"].shape)
        data["bent"] = _solver.path_edit_solve(data["d"], bent, np.zeros((0, 2)))
        out[name] = {"seconds": seconds, "solver": data["sim"].step1.solver,
                     "refinements": data["bent"].step1.refinements,
                     "similarityError": float(np.abs(shape[:, 0] + 1j * shape[:, 1] - exact).max()),
                     "bent": np.asarray(data["bent"].positions)}
        if name == "ldlt":
            out["conditionStep1"], out["conditionStep2"] = _solver.path_edit_condition(data["d"])
    ref = out["qr"].pop("bent")
    out["ldlt"]["bentDifferenceVsQR"] = float(np.abs(out["ldlt"].pop("bent") - ref).max())
    extent = float(np.ptp(rest, axis=0).max())
    out["extent"] = extent
    # The peer: the same solve through the normal equations, no refinement.
    peer = PeerProblem(rest, tri, np.ones(len(tri)), edg, np.ones(len(edg)), handles, np.full(3, np.inf))
    out["peerSeconds"] = ctx.best_of(lambda: PeerProblem(rest, tri, np.ones(len(tri)), edg, np.ones(len(edg)),
                                                         handles, np.full(3, np.inf)).solve(similar), repeat=1)
    peer.solve(similar)
    out["peerSimilarityError"] = float(np.abs(peer.shape[:, 0] + 1j * peer.shape[:, 1] - exact).max())
    out["peerBentDifferenceVsQR"] = float(np.abs(peer.solve(bent) - ref).max())
    out["speedupVsPeer"] = round(out["peerSeconds"] / out["ldlt"]["seconds"], 1)
    # The same measure at 200 frames, for "as accurate as a short clip".
    short = _walk(200)
    st, se = _solver.chain_terms(short, 0, 200, 0.01)
    zs = short[:, 0] + 1j * short[:, 1]
    hs = np.array([0, 66, 199])
    ex = sim * zs + (3.0 - 2.0j)
    d = _solver.path_edit_precompute(rest=short, triangles=st, edges=se, handles=hs, handle_weights=np.full(3, np.inf))
    r = _solver.path_edit_solve(d, np.stack([ex[hs].real, ex[hs].imag], axis=1), np.zeros((0, 2)))
    sh = np.asarray(r.shape)
    out["similarityErrorRelative200"] = float(np.abs(sh[:, 0] + 1j * sh[:, 1] - ex).max() / np.ptp(short, axis=0).max())
    out["similarityErrorRelative"] = out["ldlt"]["similarityError"] / extent
    return out


def _formation(agents, frames, rows):
    """agents walking in a block (rows x cols, 1 m apart), one group, its front-left
    member turned 90 degrees left over the second half."""
    cols = agents // rows
    inputs = []
    for r in range(rows):
        for c in range(cols):
            inputs.append(_agent(f"m{r:03d}_{c:03d}", _walk(frames, (1.0 * c, -1.2 * r))))
    lead = inputs[0]
    half = frames // 2
    end = lead.rest[half] + np.array([STEP * (frames - 1 - half), 0.0])
    hs = [path_edit.Handle(lead.path, 0, lead.rest[0], np.inf, "start"),
          path_edit.Handle(lead.path, half, lead.rest[half], np.inf, "half"),
          path_edit.Handle(lead.path, frames - 1, end, np.inf, "turn")]
    group = path_edit.Group([a.path for a in inputs], 1.0, "/group")
    return inputs, hs, group


def _relay(agents, frames):
    """Agents end to end, each handing over to the next at its last frame."""
    inputs, links = [], []
    leg = STEP * (frames - 1)
    for k in range(agents):
        inputs.append(_agent(f"r{k:03d}", _walk(frames, (0.4 * np.sin(0.7 * k), k * (leg + 0.3))),
                             np.arange(frames, dtype=np.float64) + k * (frames - 1)))
    for k in range(agents - 1):
        links.append(path_edit.Link(inputs[k].path, frames - 1, inputs[k + 1].path, 0, np.array([0.4, 0.0]),
                                    "world", np.inf, f"/handover{k}"))
    last = inputs[-1]
    hs = [path_edit.Handle(inputs[0].path, 0, inputs[0].rest[0], np.inf, "first"),
          path_edit.Handle(last.path, frames - 1, last.rest[-1] + [6.0, -4.0], np.inf, "last"),
          path_edit.Handle(inputs[agents // 2].path, frames // 2, inputs[agents // 2].rest[frames // 2] + [3.0, 0.0],
                           np.inf, "middle")]
    return inputs, hs, links


def _component(ctx, inputs, hs, links, groups, target):
    problem = path_edit.ComponentProblem(inputs, hs, links, groups, _settings())
    result = problem.solve()
    split = _setup_and_solve(lambda: path_edit.ComponentProblem(inputs, hs, links, groups, _settings()), repeat=41)
    seconds = split["seconds"]
    peer = _peer(problem)
    peer_seconds = ctx.best_of(lambda: _peer_solve(problem, _peer(problem)), repeat=3)
    # The peer solves the same (key-frame) problem: compare the solver's own vertices.
    ours = np.asarray(_solver.path_edit_solve(problem.data, problem.handle_positions(),
                                              problem._link_offsets({p: r.heading for p, r in result.agents.items()})
                                              ).positions)
    return {
        "agents": len(inputs), "frames": inputs[0].frames, "unknownVertices": len(problem.rest),
        "triangles": len(problem.triangles), "edges": len(problem.edges), "solver": result.solver,
        "seconds": seconds, "medianSeconds": split["medianSeconds"], "pythonSeconds": split["pythonSeconds"],
        "solverSeconds": split["solverSeconds"], "peerSeconds": peer_seconds,
        "speedupVsPeer": round(peer_seconds / seconds, 1),
        "target": target, "maxDifferenceVsPeer": float(np.abs(ours - _peer_solve(problem, peer)).max()),
        "hardResidual": float(max([np.linalg.norm(result.agents[h.agent].ground[h.frame] - h.position)
                                   for h in hs] + [0.0])),
    }


def _examples(ctx):
    import importlib.util

    from pxr import Usd

    from mocapedit.tools import measure
    from mocapedit.pipeline.processor import solve
    here = Path(__file__).resolve().parents[1] / "example_stages" / "stages_path.py"
    spec = importlib.util.spec_from_file_location("stages_path", here)
    stages = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stages)
    out = {}
    for name, build in sorted(stages.STAGES.items()):
        folder = ctx.workdir / "path_examples"
        build(folder)
        result = solve(str(folder / name), output=str(folder / f"{name}.edits.usda"),
                       composed=str(folder / f"{name}.edited.usda"))
        src, edited = Usd.Stage.Open(str(folder / name)), Usd.Stage.Open(str(folder / f"{name}.edited.usda"))
        agents = {}
        for path, fig in sorted(result.report.agents.items()):
            if not fig.get("edited"):
                continue
            before = measure.foot_skate(src, path)
            after = measure.foot_skate(edited, path, times=before.times, contact=before.contact)
            agents[path] = {"footSkateSource": round(before.mean, 4), "footSkateEdited": round(after.mean, 4),
                            "lengthRatio": round(fig["lengthRatio"], 4)}
        skate = [a["footSkateEdited"] - a["footSkateSource"] for a in agents.values()]
        out[name] = {"pathSeconds": round(result.report.timings["path"], 4),
                     "worstResidual": max([c["residual"] for c in result.report.constraints] + [0.0]),
                     "meanFootSkateIncrease": round(float(np.mean(skate)), 4),
                     "maxFootSkateIncrease": round(float(np.max(skate)), 4),
                     "agents": agents if len(agents) <= 6 else f"{len(agents)} edited"}
    return out


def run(ctx):
    out = {"single": _single(ctx)}
    out["long"] = _long(ctx, 5000 if ctx.quick else 20000)
    agents, frames = (20, 200) if ctx.quick else (100, 500)
    inputs, hs, group = _formation(agents, frames, rows=10)
    out["group"] = _component(ctx, inputs, hs, [], [group], 50e-3)
    relay, frames = (20, 200) if ctx.quick else (78, 500)
    inputs, hs, links = _relay(relay, frames)
    out["relay"] = _component(ctx, inputs, hs, links, [], 50e-3)
    out["examples"] = _examples(ctx)
    return out
