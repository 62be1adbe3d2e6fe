"""Write the example crowd stages of mocapedit.

    python example_stages/make_stages.py [--out DIR] [--clip-format usda|usdc]

Writes, into DIR (default: this folder):

- ``crowd_yup.usda``: six agents, Y-up, metres, 24 fps.
- ``crowd_zup_cm.usda``: six agents, Z-up, centimetres (metersPerUnit 0.01),
  30 fps.
- ``clips/``: the clip layers both stages reference (120 frames each).

In both stages agent_0000 and agent_0001 walk into each other (their paths
cross at the same frame), some agents start at other shot times through
reference layer offsets, and the walk-stop-walk clip carries a stationary tag
named ``pause``. The output is the same, byte for byte, on every run.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

try:
    import mocapedit  # noqa: F401
except ImportError:  # run from a source checkout without PYTHONPATH
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))

from mocapedit.data import examples, walker  # noqa: E402

HERE = Path(__file__).resolve().parent
FRAMES = 120


def _yup_stage(out: Path, clip_format: str) -> Path:
    fps, mpu = 24.0, 1.0
    kw = dict(frames=FRAMES, fps=fps, up="Y", meters_per_unit=mpu)
    walk = walker.walk(name="walk", **kw)
    run = walker.run(name="run", phase=0.25, **kw)
    idle = walker.idle(name="idle", **kw)
    turn = walker.turn(name="turn", turn_rate=35.0, phase=0.6, **kw)
    stop_go, pause = walker.walk_idle_walk(name="walk_idle_walk", stop_frame=40,
                                           idle_frames=30, **kw)
    # Heading 0 faces +Z; rotateY(90) faces +X. agent_0001 crosses agent_0000's
    # path 3.5 m ahead of it, both arriving at frame 60.
    agents = [
        examples.AgentSpec("agent_0000", walk, (0.0, 0.0, 0.0), 0.0),
        examples.AgentSpec("agent_0001", walk, (-3.5, 0.0, 3.5), 90.0),
        examples.AgentSpec("agent_0002", run, (-4.0, 0.0, -6.0), 5.0, time_offset=12.0),
        examples.AgentSpec("agent_0003", idle, (2.5, 0.0, 5.0), 200.0),
        examples.AgentSpec("agent_0004", stop_go, (2.0, 0.0, -1.0), -10.0, time_offset=6.0),
        examples.AgentSpec("agent_0005", turn, (-2.0, 0.0, -2.0), 180.0, time_offset=24.0),
    ]
    path = out / "crowd_yup.usda"
    examples.build_crowd_stage(path, agents, up_axis="Y", meters_per_unit=mpu, fps=fps,
                               clips_dir=out / "clips", clip_format=clip_format,
                               stationary={"walk_idle_walk": {"pause": pause}})
    return path


def _zup_cm_stage(out: Path, clip_format: str) -> Path:
    fps, mpu = 30.0, 0.01
    kw = dict(frames=FRAMES, fps=fps, up="Z", meters_per_unit=mpu)
    walk = walker.walk(name="walk_zup_cm", speed=1.3, **kw)
    run = walker.run(name="run_zup_cm", speed=3.2, phase=0.5, **kw)
    idle = walker.idle(name="idle_zup_cm", phase=0.3, **kw)
    stop_go, pause = walker.walk_idle_walk(name="walk_idle_walk_zup_cm", speed=1.3,
                                           stop_frame=45, idle_frames=36, **kw)
    # Heading 0 faces -Y; rotateZ(90) faces +X. agent_0001 crosses agent_0000's
    # path 260 cm ahead of it, both arriving at frame 60.
    agents = [
        examples.AgentSpec("agent_0000", walk, (0.0, 0.0, 0.0), 0.0),
        examples.AgentSpec("agent_0001", walk, (-260.0, -260.0, 0.0), 90.0),
        examples.AgentSpec("agent_0002", run, (400.0, 300.0, 0.0), -30.0, time_offset=15.0),
        examples.AgentSpec("agent_0003", idle, (-150.0, 200.0, 0.0), 150.0),
        examples.AgentSpec("agent_0004", idle, (-220.0, 230.0, 0.0), -120.0, time_offset=10.0),
        examples.AgentSpec("agent_0005", stop_go, (150.0, -80.0, 0.0), 20.0, time_offset=8.0),
    ]
    path = out / "crowd_zup_cm.usda"
    examples.build_crowd_stage(path, agents, up_axis="Z", meters_per_unit=mpu, fps=fps,
                               clips_dir=out / "clips", clip_format=clip_format,
                               stationary={"walk_idle_walk_zup_cm": {"pause": pause}})
    return path


def feature_stages() -> dict:
    """Stage builders of the feature modules ``stages_*.py`` beside this script.

    Each module exposes ``STAGES = {"name.usda": builder}``; ``builder(out_dir)`` writes that
    stage (and any clips under ``out_dir / "clips"``) deterministically.
    """
    import importlib.util
    builders = {}
    for path in sorted(HERE.glob("stages_*.py")):
        spec = importlib.util.spec_from_file_location(f"mocapedit_example_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        for name, builder in module.STAGES.items():
            if name in builders:
                raise ValueError(f"{path.name}: stage {name} is also built by another module")
            builders[name] = builder
    return builders


def make_stages(out: Path = HERE, clip_format: str = "usda") -> list[Path]:
    """Write every example stage and its clips into `out`; return the stage paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [_yup_stage(out, clip_format), _zup_cm_stage(out, clip_format)]
    for name, builder in sorted(feature_stages().items()):
        builder(out)
        paths.append(out / name)
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=HERE,
                        help="folder to write into (default: %(default)s)")
    parser.add_argument("--clip-format", choices=("usda", "usdc"), default="usda",
                        help="file format of the clip layers (default: %(default)s)")
    args = parser.parse_args(argv)
    for path in make_stages(args.out, args.clip_format):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
