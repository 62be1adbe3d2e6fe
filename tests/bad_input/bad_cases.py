"""The bad inputs, one small generated file per case, and what the error must name.

Each case writes its input into an empty folder and gives the command line to run on it.
Shot cases are a root layer ``shot.usda`` (the snippet below, over ``base.usda``: two toy
agents of 24 frames, Z-up, centimetres, 24 fps); BVH cases are one ``clip.bvh``. The
``needle`` is a regular expression the error message must match: the prim and property,
or the file and line.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

SHOT_HEADER = """#usda 1.0
(
    subLayers = [@base.usda@]
    upAxis = "Z"
    metersPerUnit = 0.01
    timeCodesPerSecond = 24
    startTimeCode = 0
    endTimeCode = 23
)
"""


@dataclass
class Case:
    id: str
    needle: str                                   # regular expression the message must match
    make: Callable[[Path], list[str]]             # writes the input into a folder; the argv
    outputs: tuple[str, ...] = ("out.usda",)      # must not exist afterwards
    tags: set = field(default_factory=set)


CASES: list[Case] = []


def _indent(text: str, by: int) -> str:
    return "\n".join((" " * by + line) if line.strip() else line for line in text.strip("\n").splitlines())


def agent_over(body: str, agent: str = "agent0") -> str:
    return f'over "World"\n{{\n    over "{agent}"\n    {{\n{_indent(body, 8)}\n    }}\n}}\n'


def anim_over(body: str, meta: str = "", agent: str = "agent0") -> str:
    inner = f'over "Skel"\n{{\n    over "Anim"{(" (" + meta + ")") if meta else ""}\n    {{\n{_indent(body, 8)}\n    }}\n}}'
    return agent_over(inner, agent)


def prim(type_name: str, name: str, body: str, meta: str = "") -> str:
    return f'def {type_name} "{name}"{(" (" + meta + ")") if meta else ""}\n{{\n{_indent(body, 4)}\n}}\n'


def shot(id: str, snippet: str, needle: str, args: tuple[str, ...] = (), header: str = SHOT_HEADER,
         base: Callable[[Path], None] | None = None, outputs: tuple[str, ...] = ("out.usda",),
         command: str = "solve") -> None:
    """A shot case: ``mocapedit <command> shot.usda -o out.usda <args>``."""
    def make(folder: Path) -> list[str]:
        from bad_base import write_base
        (base or write_base)(folder)
        (folder / "shot.usda").write_text(header + "\n" + snippet)
        extra = [str(folder / a) if a.endswith((".usda", ".json")) else a for a in args]
        return [command, str(folder / "shot.usda"), "-o", str(folder / outputs[0]), *extra]
    CASES.append(Case(id, needle, make, outputs))


# A constraint's own lines, for the cases that vary one property.
PIN = "rel agent = </World/agent0>\nuniform int frame = 5\nuniform point3d position = (30, 0, 0)"
REL = ("rel agent = </World/agent0>\nuniform int frame = 5\nrel target = </World/agent1>\n"
       "uniform int targetFrame = 5\nuniform vector3d offset = (0, -50, 0)")
TIME = "rel agent = </World/agent0>\nuniform int frame = 5\nuniform double time = 8"
SYNC = ("rel agent = </World/agent0>\nuniform int frame = 5\nrel target = </World/agent1>\n"
        "uniform int targetFrame = 5\nuniform double offset = 2")
GROUP = "rel members = [</World/agent0>, </World/agent1>]\nuniform double stiffness = 1"
REGION = "uniform token shape = \"circle\"\nuniform double radius = 20"
NOD = prim("SkelAnimation", "Nod", 'uniform token[] joints = ["Root/Hips"]\n'
           "quatf[] rotations.timeSamples = {0: [(1, 0, 0, 0)], 23: [(0.9239, 0, 0.3827, 0)]}\n"
           "float3[] translations = [(0, 0, 90)]\nhalf3[] scales = [(1, 1, 1)]")
LAYER = "rel agents = </World/agent0>\nrel animation = </Nod>\nuniform token mode = \"additive\""
SETTINGS = "uniform bool collisionAvoidance = true"
INACTIVE_AGENT1 = agent_over("", "agent1").replace('over "agent1"', 'over "agent1" (active = false)')


def replace(lines: str, prop: str, new: str | None) -> str:
    """The lines of a prim with the line authoring ``prop`` replaced (None: removed)."""
    out = []
    done = False
    for line in lines.splitlines():
        words = line.replace("=", " ").split()
        if prop in words[:3] or prop + ".timeSamples" in words[:3]:
            done = True
            if new is not None:
                out.append(new)
        else:
            out.append(line)
    if not done and new is not None:
        out.append(new)
    return "\n".join(out)


def prop_cases(kind: str, name: str, lines: str, variants: dict[str, tuple[str, str | None, str]],
               extra: str = "") -> None:
    """One shot case per variant: ``id: (property, new line or None, needle)``."""
    for vid, (prop, new, needle) in variants.items():
        shot(f"{name.lower()}-{vid}", extra + prim(kind, name, replace(lines, prop, new)), needle)


# ---- agents (MocapAgentAPI) and their skeletons and clips ------------------------------------
A0 = r"</World/agent0>\."
for vid, (line, needle) in {
    "radius-negative": ("uniform float mocap:collisionRadius = -1", A0 + r"mocap:collisionRadius"),
    "radius-zero": ("uniform float mocap:collisionRadius = 0", A0 + r"mocap:collisionRadius"),
    "radius-nan": ("uniform float mocap:collisionRadius = nan", A0 + r"mocap:collisionRadius: .*finite"),
    "radius-inf": ("uniform float mocap:collisionRadius = inf", A0 + r"mocap:collisionRadius: .*finite"),
    "radius-string": ('uniform string mocap:collisionRadius = "wide"', A0 + r"mocap:collisionRadius: .*string"),
    "height-negative": ("uniform float mocap:collisionHeight = -180", A0 + r"mocap:collisionHeight"),
    "height-nan": ("uniform float mocap:collisionHeight = nan", A0 + r"mocap:collisionHeight: .*finite"),
    "height-inf": ("uniform float mocap:collisionHeight = -inf", A0 + r"mocap:collisionHeight: .*finite"),
    "height-sampled": ("float mocap:collisionHeight.timeSamples = {0: 180}", A0 + r"mocap:collisionHeight: .*time samples"),
    "collide-string": ('uniform string mocap:collide = "yes"', A0 + r"mocap:collide: .*string"),
    "collide-int": ("uniform int mocap:collide = 1", A0 + r"mocap:collide: .*int"),
    "rootjoint-missing": ('uniform token mocap:rootJoint = "Nope"', A0 + r"mocap:rootJoint: joint 'Nope'"),
    "rootjoint-double": ("uniform double mocap:rootJoint = 1", A0 + r"mocap:rootJoint: .*double"),
    "hipjoint-missing": ('uniform token mocap:hipJoint = "Pelvis"', A0 + r"mocap:hipJoint: joint 'Pelvis'"),
    "source-missing": ("rel mocap:animationSource = </World/Nowhere>", A0 + r"mocap:animationSource: .*does not exist"),
    "source-wrong-type": ("rel mocap:animationSource = </World>", A0 + r"mocap:animationSource: .*not a SkelAnimation"),
    "source-inactive": ("rel mocap:animationSource = </World/agent1/Skel/Anim>", A0 + r"mocap:animationSource: .*inactive"),
    "pathcurve-missing": ("rel mocap:pathCurve = </Curves/none>", A0 + r"mocap:pathCurve: .*does not exist"),
    "pathcurve-wrong-type": ("rel mocap:pathCurve = </World>", A0 + r"mocap:pathCurve: .*not a curve"),
    "skeleton-wrong-type": ("rel skel:skeleton = </World>", A0 + r"skel:skeleton: .*not a Skeleton"),
}.items():
    snippet = agent_over(line)
    if vid == "source-inactive":  # agent1's clip switched off
        snippet = snippet.replace('\n}\n', '\n    over "agent1"\n    {\n        over "Skel"\n        {\n'
                                  '            over "Anim" (active = false)\n            {\n            }\n'
                                  '        }\n    }\n}\n')
    shot(f"agent-{vid}", snippet, needle)

shot("agent-pathcurve-one-point", agent_over("rel mocap:pathCurve = </Curves/c>") +
     'def Scope "Curves"\n{\n' + _indent(prim("BasisCurves", "c", 'uniform token type = "linear"\n'
                                             "point3f[] points = [(0, 0, 0)]\nint[] curveVertexCounts = [1]"), 4) + "\n}\n",
     r"</Curves/c>\.points: path curve needs at least two points")
# All points in one place: as a linear curve it had no length; as a cubic B-spline its
# evaluation's rounding gave it a direction (the agent walked off at 45 degrees).
for _basis in ("bspline", "catmullRom"):
    shot(f"agent-pathcurve-cubic-{_basis}-coincident", agent_over("rel mocap:pathCurve = </Curves/c>") +
         'def Scope "Curves"\n{\n' + _indent(prim("BasisCurves", "c", f'uniform token type = "cubic"\n'
                                                 f'uniform token basis = "{_basis}"\n'
                                                 "point3f[] points = [(1, 0, 1), (1, 0, 1), (1, 0, 1), (1, 0, 1)]\n"
                                                 "int[] curveVertexCounts = [4]"), 4) + "\n}\n",
         r"</Curves/c>\.points: .*path curve has no length")
shot("agent-pathcurve-inactive", agent_over("rel mocap:pathCurve = </Curves/c>") +
     'def Scope "Curves"\n{\n' + _indent(prim("BasisCurves", "c", 'uniform token type = "linear"\n'
                                             "point3f[] points = [(0, 0, 0), (100, 0, 0)]", 'active = false'), 4) + "\n}\n",
     A0 + r"mocap:pathCurve: .*inactive")
shot("agent-pathcurve-nan-points", agent_over("rel mocap:pathCurve = </Curves/c>") +
     'def Scope "Curves"\n{\n' + _indent(prim("BasisCurves", "c", 'uniform token type = "linear"\n'
                                             "point3f[] points = [(0, 0, 0), (nan, 0, 0)]"), 4) + "\n}\n",
     r"</Curves/c>\.points: .*finite")
shot("agent-pathcurve-nurbs-knots", agent_over("rel mocap:pathCurve = </Curves/c>") +
     'def Scope "Curves"\n{\n' + _indent(prim("NurbsCurves", "c", "point3f[] points = [(0, 0, 0), (50, 0, 0), "
                                             "(100, 0, 0), (150, 0, 0)]\nint[] curveVertexCounts = [4]\n"
                                             "int[] order = [4]\ndouble[] knots = [0, 1, 2]"), 4) + "\n}\n",
     r"</Curves/c>.*knots")
shot("agent-no-skeleton", 'def SkelRoot "Lonely" (prepend apiSchemas = ["MocapAgentAPI"])\n{\n}\n',
     r"</Lonely>\.apiSchemas: agent has no skeleton")
shot("agent-no-animation", 'def SkelRoot "Lonely" (prepend apiSchemas = ["MocapAgentAPI"])\n{\n'
     '    def Skeleton "Skel"\n    {\n        uniform token[] joints = ["Root"]\n    }\n}\n',
     r"</Lonely>\.mocap:animationSource: agent has no animation")
# A second skeleton under an agent (a prop's, a cloth rig's) and nothing saying which is the body.
shot("agent-several-skeletons", agent_over('def Skeleton "Prop"\n{\n    uniform token[] joints = ["stick"]\n}'),
     r"</World/agent0>\.skel:skeleton: agent has several skeletons \(</World/agent0/Skel>, </World/agent0/Prop>\)")
# The skeleton's own binding set to nothing blocks the one its SkelRoot inherits: UsdSkel plays
# the rest pose, so there is no clip to edit.
shot("agent-animation-blocked", agent_over('rel skel:animationSource = </World/agent0/Skel/Anim>\n'
                                           'over "Skel"\n{\n    rel skel:animationSource = None\n}'),
     r"</World/agent0/Skel>\.skel:animationSource: .*set to none")
shot("skeleton-no-joints", agent_over('over "Skel"\n{\n    uniform token[] joints = []\n}'),
     r"</World/agent0/Skel>\.joints: skeleton has no joints")
shot("skeleton-bad-hierarchy", agent_over('over "Skel"\n{\n    uniform token[] joints = ["Root/Hips", "Root", '
                                          '"Root/Hips/LeftFoot", "Root/Hips/RightFoot"]\n}'),
     r"</World/agent0/Skel>\.joints: invalid joint hierarchy")
shot("skeleton-rest-count", agent_over('over "Skel"\n{\n    uniform matrix4d[] restTransforms = '
                                       '[((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1))]\n}'),
     r"</World/agent0/Skel>\.restTransforms: restTransforms has 1 entries for 4 joints")
shot("clip-no-joints", anim_over("uniform token[] joints = []"), r"</World/agent0/Skel/Anim>\.joints")
shot("clip-no-shared-joint", anim_over('uniform token[] joints = ["A", "B", "C", "D"]'),
     r"</World/agent0/Skel/Anim>\.joints: animation shares no joint")
shot("clip-short-translations", anim_over("float3[] translations.timeSamples = {3: [(0, 0, 0)]}"),
     r"</World/agent0/Skel/Anim>\.translations: at time \d+ holds 1 values for 4 joints")
shot("clip-nan-rotations", anim_over("quatf[] rotations.timeSamples = {4: [(nan, 0, 0, 0), (1, 0, 0, 0), "
                                     "(1, 0, 0, 0), (1, 0, 0, 0)]}"),
     r"</World/agent0/Skel/Anim>\.rotations: holds non-finite values")
shot("curve-basis-unknown", agent_over("rel mocap:pathCurve = </Curves/path>") +
     'def "Curves"\n{\n    def BasisCurves "path"\n    {\n        uniform token type = "cubic"\n'
     '        uniform token basis = "bogus"\n        point3f[] points = [(0, 0, 0), (50, 0, 0), (100, 0, 0), '
     '(150, 0, 0)]\n        int[] curveVertexCounts = [4]\n    }\n}\n',
     r"</Curves/path>\.basis: basis 'bogus' is not supported")
shot("clip-inf-translations", anim_over("float3[] translations.timeSamples = {4: [(inf, 0, 0), (0, 0, 90), "
                                        "(10, 0, -90), (-10, 0, -90)]}"),
     r"</World/agent0/Skel/Anim>\.translations: holds non-finite values")
shot("clip-value-clip-missing", anim_over("", 'clips = {\n    dictionary default = {\n'
                                            '        asset[] assetPaths = [@anim_clip.usda@]\n'
                                            '        string primPath = "/Anim"\n'
                                            '        double2[] active = [(0, 0)]\n'
                                            '        double2[] times = [(0, 0), (23, 23)]\n    }\n}'),
     r"</World/agent0/Skel/Anim>\.clips: value clip set 'default' plays @anim_clip\.usda@, which cannot be opened")
shot("clip-no-scales", "", r"</World/agent0/Skel/Anim>\.scales: has no value",
     base=lambda folder: __import__("bad_base").write_base(folder, no_scales=True))
shot("clip-no-samples", "", r"</World/agent0/Skel/Anim>\.translations: clip has no samples",
     base=lambda folder: __import__("bad_base").write_base(folder, no_samples=True))

# ---- composition: layers, references, stage metadata --------------------------------------
shot("layer-missing-sublayer", "", r"shot\.usda.*does not compose.*sublayer @missing\.usda@",
     header=SHOT_HEADER.replace("[@base.usda@]", "[@base.usda@, @missing.usda@]"))
shot("layer-missing-clip-reference", agent_over('over "Skel"\n{\n    over "Anim" (prepend references = '
                                                '@walk_clip.usda@</Anim>)\n    {\n    }\n}'),
     r"does not compose.*walk_clip\.usda.*</World/agent0/Skel/Anim>")
shot("layer-missing-clip-two-agents", """over "World"
{
    over "agent0"
    {
        over "Skel" (prepend references = @walk_clip.usda@</Skel>)
        {
        }
    }
    over "agent1"
    {
        over "Skel" (prepend references = @walk_clip.usda@</Skel>)
        {
        }
    }
}
""", r"does not compose: Could not open asset @.*walk_clip\.usda@ for reference introduced by @.*shot\.usda@ at 2 "
     r"prims \(</World/agent0/Skel>, </World/agent1/Skel>\)$")
shot("layer-up-axis", "", r"base\.usda: sublayer says upAxis = Z, but the root layer .*shot\.usda says upAxis = Y",
     header=SHOT_HEADER.replace('upAxis = "Z"', 'upAxis = "Y"'))
shot("layer-meters-per-unit", "", r"base\.usda: sublayer says metersPerUnit = 0\.01.*root layer.*says metersPerUnit = 1",
     header=SHOT_HEADER.replace("metersPerUnit = 0.01", "metersPerUnit = 1"))


def _base_at_30_fps(folder: Path) -> None:
    from bad_base import _base_text
    (folder / "base.usda").write_text(_base_text().replace("timeCodesPerSecond = 24", "timeCodesPerSecond = 30"))


# A root layer that authors another rate than its sublayer's is fine (USD rescales the sublayer);
# one that authors none counts time at USD's default 24 a second, which the sublayer did not mean.
shot("layer-time-codes", "", r"base\.usda: sublayer says timeCodesPerSecond = 30.*root layer.*does not author "
     r"timeCodesPerSecond", header=SHOT_HEADER.replace("    timeCodesPerSecond = 24\n", ""), base=_base_at_30_fps)
shot("layer-unauthored-up-axis", "", r"base\.usda: sublayer says upAxis = Z.*does not author upAxis",
     header=SHOT_HEADER.replace('    upAxis = "Z"\n', ""))
shot("layer-shot-range-inverted", "", r"shot\.usda: endTimeCode -50 is before startTimeCode 0",
     header=SHOT_HEADER.replace("endTimeCode = 23", "endTimeCode = -50"))
shot("layer-not-usd", "", r"shot\.usda: cannot be read as a USD stage", header="this is not usd\n")
# A text layer that breaks off: USD's parser says where (file, line and column).
shot("layer-syntax", 'def Xform "Broken" (\n', r"shot\.usda: cannot be read as a USD stage: .*shot\.usda:\d+:\d+: Expected")


def _broken_base(folder: Path) -> None:
    from bad_base import write_base
    write_base(folder)
    (folder / "base.usda").write_text((folder / "base.usda").read_text() + 'def "x" (\n')


shot("layer-sublayer-syntax", "", r"shot\.usda: .*base\.usda:\d+:\d+: ", base=_broken_base)


def _broken_clip(folder: Path) -> None:
    from bad_base import write_base
    write_base(folder)
    (folder / "broken.usda").write_text('#usda 1.0\ndef Skeleton "Skel"\n{\n    float3[] x = [(1, 2\n}\n')


# A clip file two agents reference does not parse: one line (it spanned two, each naming USD's
# parser rule), the file, line and column, and both prims.
shot("clip-does-not-parse", 'def "More"\n{\n' + "".join(
    f'    def SkelRoot "{n}" (\n        prepend references = @broken.usda@</Skel>\n    )\n    {{\n    }}\n'
    for n in ("a", "b")) + "}\n",
    r"broken\.usda@ for reference introduced by @.*shot\.usda@ at 2 prims \(</More/a>, </More/b>\) "
    r"\(.*broken\.usda:\d+:\d+: parse error", base=_broken_clip)
shot("settings-two-prims", prim("MocapSolveSettings", "S1", SETTINGS) + prim("MocapSolveSettings", "S2", SETTINGS),
     r"more than one MocapSolveSettings prim: </S1>, </S2>")

# ---- stationary tags (MocapStationaryAPI) -------------------------------------------------
ST = r"</World/agent0/Skel/Anim>\.stationary:pause:frames: "
for vid, (line, needle) in {
    "reversed": ("uniform int2 stationary:pause:frames = (10, 5)", ST + r"stationary range \[10, 5\] is reversed"),
    "outside": ("uniform int2 stationary:pause:frames = (10, 40)", ST + r"stationary range \[10, 40\] is outside"),
    "negative": ("uniform int2 stationary:pause:frames = (-3, 5)", ST + r"stationary range \[-3, 5\] is outside"),
    "missing": ("", ST + r"stationary tag has no frame range"),
    "string": ('uniform string stationary:pause:frames = "10-20"', ST + r"is authored as string"),
    "double2": ("uniform double2 stationary:pause:frames = (2.5, 7)", ST + r"is authored as double2"),
    "sampled": ("int2 stationary:pause:frames.timeSamples = {0: (2, 7)}", ST + r"is authored only as time samples"),
}.items():
    shot(f"stationary-{vid}", anim_over(line, 'prepend apiSchemas = ["MocapStationaryAPI:pause"]'), needle)
# A clip's tag on the agent or its skeleton was silently read as nothing.
for _where, _body in (("agent", 'over "World"\n{\n    over "agent0" (prepend apiSchemas = ["MocapStationaryAPI:pause"])\n'
                                '    {\n        uniform int2 stationary:pause:frames = (2, 7)\n    }\n}\n'),
                      ("skeleton", agent_over('over "Skel" (prepend apiSchemas = ["MocapFootContactAPI:l"])\n{\n'
                                              '    uniform token footContact:l:joint = "LeftFoot"\n}'))):
    shot(f"tag-on-the-{_where}", _body, r"apiSchemas: has Mocap(Stationary|FootContact)API:\w+ applied, .*apply it "
         r"to the agent's SkelAnimation </World/agent0/Skel/Anim>")

# ---- constraints: what all four kinds share, then each kind's own -------------------------------
SHARED = {
    "no-agent": ("agent", None, r"agent: has no target"),
    "agent-as-attribute": ("agent", 'uniform string agent = "/World/agent0"',
                           r"agent: is authored as an attribute; it is a relationship"),
    "agent-missing": ("agent", "rel agent = </World/agent9>", r"agent: targets </World/agent9>, which does not exist"),
    "agent-not-agent": ("agent", "rel agent = </World>", r"agent: .*not an agent \(no MocapAgentAPI\)"),
    "agent-two": ("agent", "rel agent = [</World/agent0>, </World/agent1>]", r"agent: has 2 targets"),
    "frame-outside": ("frame", "uniform int frame = 24", r"frame: frame 24 is outside the clip"),
    "frame-negative": ("frame", "uniform int frame = -1", r"frame: frame -1 is outside the clip"),
    "frame-string": ("frame", 'uniform string frame = "ten"', r"frame: is authored as string 'ten'"),
    "frame-double": ("frame", "uniform double frame = 10.7", r"frame: is authored as double 10\.7"),
    "frame-sampled": ("frame", "int frame.timeSamples = {0: 10}", r"frame: is authored only as time samples"),
    "strength": ("strength", 'uniform token strength = "firm"', r"strength: strength must be 'hard' or 'soft'"),
    "strength-int": ("strength", "uniform int strength = 1", r"strength: is authored as int"),
    "weight-negative": ("weight", "uniform double weight = -1", r"weight: weight must be a finite non-negative"),
    "weight-nan": ("weight", "uniform double weight = nan", r"weight: must be a finite number"),
    "weight-inf": ("weight", "uniform double weight = inf", r"weight: must be a finite number"),
    "weight-string": ("weight", 'uniform string weight = "heavy"', r"weight: is authored as string"),
}
OWN = {
    ("MocapPositionConstraint", "Pin", PIN): {
        "position-nan": ("position", "uniform point3d position = (nan, 0, 0)", r"position: must be a finite number"),
        "position-inf": ("position", "uniform point3d position = (0, inf, 0)", r"position: must be a finite number"),
        "position-string": ("position", 'uniform string position = "here"', r"position: is authored as string"),
        "position-double": ("position", "uniform double position = 3", r"position: is authored as double"),
        "position-sampled": ("position", "point3d position.timeSamples = {0: (1, 2, 3)}", r"position: .*time samples"),
        "position-unknown-type": ("position", "uniform point2d position = (1, 2)",
                                  r"position: is authored with a type USD does not know; the schema's type is point3d"),
        "position-far": ("position", "uniform point3d position = (1e300, 0, 0)",
                         r"position: .* lies more than 1e\+08 m .* from the stage origin"),
    },
    ("MocapRelativeConstraint", "Rel", REL): {
        "no-target": ("target", None, r"target: has no target"),
        "target-missing": ("target", "rel target = </World/agent7>", r"target: .*does not exist"),
        "target-itself": ("target", "rel target = </World/agent0>", r"target.*itself"),
        "target-not-agent": ("target", "rel target = </World/agent1/Skel>", r"target: .*not an agent"),
        "targetframe-outside": ("targetFrame", "uniform int targetFrame = 30", r"targetFrame: frame 30 is outside"),
        "targetframe-string": ("targetFrame", 'uniform string targetFrame = "5"', r"targetFrame: is authored as string"),
        "targetframe-double": ("targetFrame", "uniform double targetFrame = 4.5", r"targetFrame: is authored as double"),
        "offset-nan": ("offset", "uniform vector3d offset = (nan, 0, 0)", r"offset: must be a finite number"),
        "offset-float": ("offset", "uniform float offset = 2", r"offset: is authored as float"),
        "offset-far": ("offset", "uniform vector3d offset = (0, 0, -2e20)", r"offset: .* lies more than 1e\+08 m"),
        "no-offset": ("offset", None, r"offset: has no offset; author the agent's root position"),
        "target-as-attribute": ("target", 'uniform string target = "/World/agent1"',
                                r"target: is authored as an attribute; it is a relationship"),
        "space": ("space", 'uniform token space = "local"', r"space: space must be 'world' or 'target'"),
    },
    ("MocapTimeConstraint", "Beat", TIME): {
        "no-time": ("time", None, r"time: has no time"),
        "time-nan": ("time", "uniform double time = nan", r"time: must be a finite number"),
        "time-inf": ("time", "uniform double time = inf", r"time: must be a finite number"),
        "time-huge": ("time", "uniform double time = 1e308", r"time"),
        "time-string": ("time", 'uniform string time = "noon"', r"time: is authored as string"),
        "time-sampled": ("time", "double time.timeSamples = {0: 8}", r"time: .*time samples"),
    },
    ("MocapSyncConstraint", "Sync", SYNC): {
        "no-target": ("target", None, r"target: has no target"),
        "target-missing": ("target", "rel target = </Nobody>", r"target: .*does not exist"),
        "target-itself": ("target", "rel target = </World/agent0>", r"target: targets its own agent"),
        "offset-nan": ("offset", "uniform double offset = nan", r"offset: must be a finite number"),
        "offset-string": ("offset", 'uniform string offset = "2"', r"offset: is authored as string"),
        "targetframe-outside": ("targetFrame", "uniform int targetFrame = -4", r"targetFrame: frame -4 is outside"),
    },
}
for (kind, name, lines), own in OWN.items():
    prop_cases(kind, name, lines, {vid: (prop, new, rf"</{name}>\." + needle)
                                   for vid, (prop, new, needle) in {**SHARED, **own}.items()})

P = r"</Pin>\."
shot("pin-agent-inactive", prim("MocapPositionConstraint", "Pin", PIN) +
     agent_over("", "agent0").replace('over "agent0"', 'over "agent0" (active = false)'),
     P + r"agent: targets </World/agent0>, which is inactive")
shot("pin-contradiction", prim("MocapPositionConstraint", "Pin", PIN) +
     prim("MocapPositionConstraint", "Pin2", replace(PIN, "position", "uniform point3d position = (90, 40, 0)")),
     r"</Pin>.*</Pin2>.*frame 5")
shot("beat-two-times", prim("MocapTimeConstraint", "Beat", TIME) +
     prim("MocapTimeConstraint", "Beat2", replace(TIME, "time", "uniform double time = 12")),
     r"</Beat>\.time: hard time constraints </Beat>, </Beat2> put frame 5")
shot("beat-backwards", prim("MocapTimeConstraint", "Beat", TIME) +
     prim("MocapTimeConstraint", "Beat2", "rel agent = </World/agent0>\nuniform int frame = 15\nuniform double time = 2"),
     r"</Beat>\.time: hard constraints </Beat>, </Beat2> would make time run backwards")
shot("sync-time-conflict", prim("MocapSyncConstraint", "Sync", SYNC) +
     prim("MocapTimeConstraint", "T0", TIME) +
     prim("MocapTimeConstraint", "T1", "rel agent = </World/agent1>\nuniform int frame = 5\nuniform double time = 20"),
     r"</Sync>\.offset: hard time and sync constraints </Sync>, </T0>, </T1> fix the same frame's time twice")
shot("sync-cycle", prim("MocapSyncConstraint", "Sync", SYNC) +
     prim("MocapSyncConstraint", "Sync2", SYNC.replace("agent0", "agentX").replace("agent1", "agent0")
          .replace("agentX", "agent1")),
     r"</Sync>\.offset: hard sync constraints </Sync>, </Sync2> form a cycle")

# ---- groups -------------------------------------------------------------------------------
G = r"</Team>\."
prop_cases("MocapAgentGroup", "Team", GROUP, {
    "one-member": ("members", "rel members = </World/agent0>", G + r"members: a group needs at least two members"),
    "no-members": ("members", None, G + r"members: a group needs at least two members, got 0"),
    "member-missing": ("members", "rel members = [</World/agent0>, </Ghost>]", G + r"members: member </Ghost> does not exist"),
    "member-not-agent": ("members", "rel members = [</World/agent0>, </World>]", G + r"members: .*not an agent"),
    "stiffness-zero": ("stiffness", "uniform double stiffness = 0", G + r"stiffness: stiffness must be positive"),
    "stiffness-negative": ("stiffness", "uniform double stiffness = -1", G + r"stiffness: stiffness must be positive"),
    "stiffness-nan": ("stiffness", "uniform double stiffness = nan", G + r"stiffness: must be a finite number"),
    "stiffness-inf": ("stiffness", "uniform double stiffness = inf", G + r"stiffness: must be a finite number"),
    "stiffness-string": ("stiffness", 'uniform string stiffness = "stiff"', G + r"stiffness: is authored as string"),
})
shot("team-member-inactive", prim("MocapAgentGroup", "Team", GROUP) + INACTIVE_AGENT1,
     G + r"members: member </World/agent1> is inactive")

# ---- avoid regions ----------------------------------------------------------------------------
AR = r"</Fountain>\."
prop_cases("MocapAvoidRegion", "Fountain", REGION, {
    "shape": ("shape", 'uniform token shape = "triangle"', AR + r"shape: shape must be 'circle' or 'box'"),
    "radius-zero": ("radius", "uniform double radius = 0", AR + r"radius: radius must be positive"),
    "radius-negative": ("radius", "uniform double radius = -5", AR + r"radius: radius must be positive"),
    "radius-nan": ("radius", "uniform double radius = nan", AR + r"radius: must be a finite number"),
    "radius-inf": ("radius", "uniform double radius = inf", AR + r"radius: must be a finite number"),
    "radius-huge": ("radius", "uniform double radius = 1e12", AR + r"radius: 1e\+12 stage units is more than 1e\+08 m"),
    "margin-huge": ("margin", "uniform double margin = 1e30", AR + r"margin: 1e\+30 stage units is more than 1e\+08 m"),
    "radius-string": ("radius", 'uniform string radius = "big"', AR + r"radius: is authored as string"),
    "size-negative": ("shape", 'uniform token shape = "box"\nuniform double3 size = (10, -1, 10)', AR + r"size: size must be positive"),
    "size-nan": ("shape", 'uniform token shape = "box"\nuniform double3 size = (10, nan, 10)', AR + r"size: must be a finite number"),
    "size-scalar": ("shape", 'uniform token shape = "box"\nuniform double size = 10', AR + r"size: is authored as double"),
    "margin-negative": ("radius", "uniform double radius = 20\nuniform double margin = -1", AR + r"margin: margin must not be negative"),
    "margin-nan": ("radius", "uniform double radius = 20\nuniform double margin = nan", AR + r"margin: must be a finite number"),
    "agents-missing": ("radius", "uniform double radius = 20\nrel agents = </Nobody>", AR + r"agents: targets </Nobody>, which does not exist"),
    "geometry-missing": ("radius", "rel geometry = </Nothing>", AR + r"geometry: targets </Nothing>, which does not exist"),
})
shot("fountain-geometry-empty", prim("MocapAvoidRegion", "Fountain", "rel geometry = </Stone>") +
     prim("Mesh", "Stone", "point3f[] points = []"), AR + r"geometry: geometry </Stone> has an empty bound")
shot("fountain-geometry-inactive", prim("MocapAvoidRegion", "Fountain", "rel geometry = </Stone>") +
     prim("Cube", "Stone", "double size = 50", "active = false"), AR + r"geometry: targets </Stone>, which is inactive")
shot("fountain-geometry-typeless", prim("MocapAvoidRegion", "Fountain", "rel geometry = </Thing>") + 'def "Thing"\n{\n}\n',
     AR + r"geometry: targets </Thing>, which is not a UsdGeom prim")

# Two walkers timed to meet at the crossroads, where neither can step aside: one must wait.
CROSSROADS_HEADER = SHOT_HEADER.replace('"Z"', '"Y"').replace("0.01", "1").replace("23", "119")
CUES = "".join(prim("MocapTimeConstraint", f"Cue{k}", f"rel agent = </World/Crowd/agent_000{k}>\n"
                    "uniform int frame = 60\nuniform double time = 60") for k in range(2))
shot("time-constraints-leave-no-room-to-wait", CUES,
     r"</Cue0>: agents </World/Crowd/agent_0000> \(frame 6[01]\) and </World/Crowd/agent_0001> \(frame 6[01]\) "
     r"still overlap.*</Cue1>", header=CROSSROADS_HEADER,
     base=lambda folder: __import__("conftest").write_crossroads(folder / "base.usda"))

# ---- animation layers --------------------------------------------------------------------------
L = r"</Nodding>\."
prop_cases("MocapAnimationLayer", "Nodding", LAYER, {
    "no-animation": ("animation", None, L + r"animation: has no animation"),
    "animation-missing": ("animation", "rel animation = </Shake>", L + r"animation: targets </Shake>, which does not exist"),
    "animation-wrong-type": ("animation", "rel animation = </World/agent0/Skel>", L + r"animation: .*not a SkelAnimation"),
    "animation-two": ("animation", "rel animation = [</Nod>, </World/agent0/Skel/Anim>]",
                      L + r"animation: targets 2 animations \(</Nod>, </World/agent0/Skel/Anim>\); a layer plays one"),
    "agents-missing": ("agents", "rel agents = </World/agent5>", L + r"agents: targets </World/agent5>, which does not exist"),
    "mode": ("mode", 'uniform token mode = "multiply"', L + r"mode: must be one of blend, additive, got 'multiply'"),
    "wrap": ("mode", 'uniform token wrap = "bounce"', L + r"wrap: must be one of loop, clamp"),
    "reference-pose": ("mode", 'uniform token referencePose = "lastFrame"', L + r"referencePose: must be one of firstFrame, restPose"),
    "weight-above-one": ("mode", "double weight = 1.5", L + r"weight: weight must be within \[0, 1\], got 1\.5"),
    "weight-negative": ("mode", "double weight = -0.1", L + r"weight: weight must be within \[0, 1\]"),
    "weight-sample-nan": ("mode", "double weight.timeSamples = {0: 0, 10: nan}", L + r"weight: weight must be within \[0, 1\], got nan at time 10"),
    "weight-string": ("mode", 'string weight = "full"', L + r"weight: is authored as string"),
    "time-offset-nan": ("mode", "uniform double timeOffset = nan", L + r"timeOffset: must be a finite number"),
    "joint-missing": ("mode", 'uniform token joint = "Tail"', L + r"joint: joint 'Tail' is not in the skeleton"),
    "joint-int": ("mode", "uniform int joint = 3", L + r"joint: is authored as int"),
}, extra=NOD)
shot("nodding-other-rig", prim("SkelAnimation", "Alien", 'uniform token[] joints = ["Tentacle"]\n'
                               "quatf[] rotations.timeSamples = {0: [(1, 0, 0, 0)]}") +
     prim("MocapAnimationLayer", "Nodding", LAYER.replace("</Nod>", "</Alien>")),
     L + r"animation: layer clip </Alien> shares no joint")
shot("nodding-other-rig-before-collisions",
     prim("SkelAnimation", "Alien", 'uniform token[] joints = ["Tentacle"]\nquatf[] rotations.timeSamples = {0: [(1, 0, 0, 0)]}') +
     prim("MocapAnimationLayer", "Nodding", LAYER.replace("</Nod>", "</Alien>")) +
     prim("MocapSolveSettings", "Settings", SETTINGS + "\nuniform int maxIterations = 1000"),
     L + r"animation: layer clip </Alien> shares no joint", args=("--collisions",))
shot("nodding-animation-inactive", NOD.replace('def SkelAnimation "Nod"', 'def SkelAnimation "Nod" (active = false)') +
     prim("MocapAnimationLayer", "Nodding", LAYER), L + r"animation: targets </Nod>, which is inactive")
shot("nodding-agent-inactive", NOD + prim("MocapAnimationLayer", "Nodding", LAYER.replace("agent0", "agent1")) +
     INACTIVE_AGENT1, L + r"agents: targets </World/agent1>, which is inactive")
shot("fountain-agent-inactive", prim("MocapAvoidRegion", "Fountain", REGION + "\nrel agents = </World/agent1>") +
     INACTIVE_AGENT1, AR + r"agents: targets </World/agent1>, which is inactive")
shot("rel-target-inactive", prim("MocapRelativeConstraint", "Rel", REL) + INACTIVE_AGENT1,
     r"</Rel>\.target: targets </World/agent1>, which is inactive")
shot("sync-target-inactive", prim("MocapSyncConstraint", "Sync", SYNC) + INACTIVE_AGENT1,
     r"</Sync>\.target: targets </World/agent1>, which is inactive")
shot("nodding-clip-no-samples", prim("SkelAnimation", "Empty", 'uniform token[] joints = ["Root/Hips"]') +
     prim("MocapAnimationLayer", "Nodding", LAYER.replace("</Nod>", "</Empty>")),
     L + r"animation: animation </Empty> cannot be layered: .*clip has no samples")
shot("nodding-clip-nan", prim("SkelAnimation", "Bad", 'uniform token[] joints = ["Root/Hips"]\n'
                              "quatf[] rotations.timeSamples = {0: [(nan, 0, 0, 0)]}") +
     prim("MocapAnimationLayer", "Nodding", LAYER.replace("</Nod>", "</Bad>")),
     L + r"animation: .*rotations: holds non-finite values")

# ---- solve settings -------------------------------------------------------------------------------
SS = r"</Settings>\."
prop_cases("MocapSolveSettings", "Settings", SETTINGS, {
    "iterations-negative": ("maxIterations", "uniform int maxIterations = -1", SS + r"maxIterations: must not be negative"),
    "iterations-double": ("maxIterations", "uniform double maxIterations = 2.5", SS + r"maxIterations: is authored as double"),
    "iterations-huge": ("maxIterations", "uniform int maxIterations = 2000000000", SS + r"maxIterations"),
    "step-zero": ("sampleStep", "uniform double sampleStep = 0", SS + r"sampleStep: must be positive"),
    "step-negative": ("sampleStep", "uniform double sampleStep = -1", SS + r"sampleStep: must be positive"),
    "step-nan": ("sampleStep", "uniform double sampleStep = nan", SS + r"sampleStep: must be a finite number"),
    "step-tiny": ("sampleStep", "uniform double sampleStep = 1e-7", SS + r"sampleStep"),
    "margin-negative": ("margin", "uniform double margin = -2", SS + r"margin: must not be negative"),
    "margin-inf": ("margin", "uniform double margin = inf", SS + r"margin: must be a finite number"),
    "margin-huge": ("margin", "uniform double margin = 1e30", SS + r"margin: 1e\+30 stage units is more than 10 m"),
    "margin-unknown-type": ("margin", "uniform point2d margin = (1, 2)",
                            SS + r"margin: is authored with a type USD does not know; the schema's type is double"),
    "wait-huge": ("maxWait", "uniform double maxWait = 1e8", SS + r"maxWait: 1e\+08 s is more than the 3600 s"),
    "strategy": ("collisionStrategy", 'uniform token collisionStrategy = "shove"', SS + r"collisionStrategy: must be one of"),
    "min-interval-zero": ("minTimeInterval", "uniform double minTimeInterval = 0", SS + r"minTimeInterval: must be in \(0, 1\]"),
    "min-interval-above-one": ("minTimeInterval", "uniform double minTimeInterval = 2", SS + r"minTimeInterval: must be in \(0, 1\]"),
    "min-interval-nan": ("minTimeInterval", "uniform double minTimeInterval = nan", SS + r"minTimeInterval: must be a finite number"),
    "avoidance-string": ("collisionAvoidance", 'uniform string collisionAvoidance = "on"', SS + r"collisionAvoidance: is authored as string"),
    "match-speed-int": ("matchSpeed", "uniform int matchSpeed = 1", SS + r"matchSpeed: is authored as int"),
}, extra=prim("MocapTimeConstraint", "Beat", TIME))

# ---- output paths ------------------------------------------------------------------------------------
shot("output-is-input", "", r"edits layer .*shot\.usda: names a file the input uses", outputs=("shot.usda",))
shot("output-composed-is-input", "", r"composed stage .*shot\.usda: names a file the input uses",
     args=("--composed", "shot.usda"))
shot("output-composed-is-base", "", r"composed stage .*base\.usda: names a file the input uses",
     args=("--composed", "base.usda"))
shot("output-report-is-input", "", r"report .*shot\.usda: names a file the input uses", args=("--report", "shot.usda"))
shot("output-composed-is-output", "", r"composed stage .*out\.usda: edits layer names the same file",
     args=("--composed", "out.usda"))
shot("output-txt", "", r"edits layer .*out\.txt: a USD layer is written as", outputs=("out.txt",))
shot("output-usdz", "", r"edits layer .*out\.usdz: USD cannot write a \.usdz", outputs=("out.usdz",))
shot("output-missing-folder", "", r"folder .*missing does not exist", outputs=("missing/../out.usda",))
shot("output-folder-is-a-file", "", r"base\.usda is a file, not a folder", outputs=("base.usda/out.usda",))
shot("output-existing-folder", "", r"edits layer .*sub: is a folder", outputs=("sub",),
     base=lambda folder: (__import__("bad_base").write_base(folder), (folder / "sub").mkdir()))
shot("detect-output-is-input", "", r"-o .*shot\.usda: names a file the input uses", outputs=("shot.usda",),
     command="detect-stationary")
shot("contacts-release-below-entry", "", r"release-height 0\.06 is below height 0\.1: .*raise release-height to 0\.1",
     args=("--height", "0.1"), command="detect-contacts")


# ---- BVH files broken at each section ---------------------------------------------------------------
GOOD_BVH = (Path(__file__).parent / "good.bvh").read_text()


def bvh(id: str, text: str, needle: str, args: tuple[str, ...] = (), name: str = "clip.bvh",
        output: str = "clip.usda") -> None:
    """A BVH case: ``mocapedit import-bvh clip.bvh -o clip.usda <args>``; the needle names file:line."""
    def make(folder: Path) -> list[str]:
        (folder / name).write_text(text)
        return ["import-bvh", str(folder / name), "-o", str(folder / output), *args]
    CASES.append(Case(f"bvh-{id}", needle, make, (output,)))


def bvh_line(line: int, new: str | None) -> str:
    """GOOD_BVH with its line ``line`` (1-based) replaced (None: the file cut before it)."""
    lines = GOOD_BVH.splitlines()
    if new is None:
        return "\n".join(lines[:line - 1]) + "\n"
    lines[line - 1] = new
    return "\n".join(lines) + "\n"


F = r"clip\.bvh:"
for vid, (line, new, needle) in {
    "no-hierarchy": (1, "HIERARCHIE", F + r"1: expected HIERARCHY"),
    "root-no-name": (2, "ROOT", F + r"2: ROOT has no name"),
    "no-brace": (3, "OFFSET 0 90 0", F + r"3: expected '\{' to open the block started on line 2"),
    "offset-two": (4, "  OFFSET 0 90", F + r"4: OFFSET needs 3 values"),
    "offset-text": (4, "  OFFSET 0 ninety 0", F + r"4: .*'ninety' is not a number"),
    "offset-nan": (4, "  OFFSET 0 nan 0", F + r"4: .*not a finite number"),
    "channels-count": (5, "  CHANNELS 5 Xposition Yposition Zposition Zrotation Xrotation Yrotation", F + r"5: CHANNELS declares 5"),
    "channels-unknown": (9, "    CHANNELS 3 Zrotation Xrotation Wrotation", F + r"9: unknown channel 'Wrotation'"),
    "channels-twice": (9, "    CHANNELS 3 Zrotation Zrotation Yrotation", F + r"9: channel 'Zrotation' is listed twice"),
    "channels-seven": (9, "    CHANNELS 7 Zrotation Xrotation Yrotation Xposition Yposition Zposition Zrotation", F + r"9: CHANNELS declares 7"),
    "joint-no-name": (6, "  JOINT", F + r"6: JOINT has no name"),
    "unknown-keyword": (6, "  BONE Spine", F + r"6: unknown keyword 'BONE'"),
    "extra-close": (15, "}\n}", F + r"16: '\}' without an open block"),
    "truncated-hierarchy": (12, None, F + r"12: file ends inside the HIERARCHY"),
    "no-motion": (16, None, F + r"16: file ends before MOTION"),
    "motion-inside-block": (15, "MOTION", F + r"15: MOTION inside an open block"),
    "frames-text": (17, "Frames: two", F + r"17: frame count 'two' is not a whole number"),
    "frames-missing": (17, "Frame Time: 0.0333333", F + r"17: expected 'Frames: <count>'"),
    "frames-zero": (17, "Frames: 0", F + r"17: 'Frames: 0': the clip has no frames"),
    "frame-time-zero": (18, "Frame Time: 0", F + r"18: frame time must be"),
    "frame-time-negative": (18, "Frame Time: -0.03", F + r"18: frame time must be"),
    "frame-time-nan": (18, "Frame Time: nan", F + r"18: frame time must be"),
    "frame-time-huge": (18, "Frame Time: 1e300", F + r"18: frame time"),
    "frame-time-tiny": (18, "Frame Time: 1e-300", F + r"18: frame time"),
    "frame-time-text": (18, "Frame Time: fast", F + r"18: frame time 'fast' is not a number"),
    "row-short": (19, "0 90 0 0 0 0 0 0", F + r"19: frame row has"),
    "row-text": (20, "1 90 0 0 five 0 0 0 0", F + r"20: .*'five' is not a number"),
    "row-nan": (20, "1 90 0 0 nan 0 0 0 0", F + r"20: .*(finite|number)"),
    "rows-more": (20, "1 90 0 0 5 0 0 0 0\n2 90 0 0 5 0 0 0 0", F + r"21: more frame rows than 'Frames: 2'"),
    "rows-fewer": (20, None, F + r"20: file ends after 1 frame rows"),
}.items():
    bvh(vid, bvh_line(line, new), needle)
bvh("empty", "", r"clip\.bvh: empty file")
bvh("scale-inf", GOOD_BVH, r"--scale must be stage units per BVH unit, a finite number above 0, got inf",
    args=("--scale", "inf"))
bvh("unit-huge", GOOD_BVH, r"--unit 1e\+300 is outside", args=("--unit", "1e300"))
bvh("meters-per-unit-inf", GOOD_BVH, r"--meters-per-unit must be the stage unit in metres", args=("--meters-per-unit", "inf"))
bvh("meters-per-unit-tiny", GOOD_BVH, r"--meters-per-unit 1e-300 is outside", args=("--meters-per-unit", "1e-300"))
bvh("root-joint-missing", GOOD_BVH, r"clip\.bvh: root joint 'Pelvis' is not a joint", args=("--root-joint", "Pelvis"))
bvh("output-is-input", GOOD_BVH, r"-o .*clip\.bvh: ", output="clip.bvh")
bvh("missing-file", GOOD_BVH, r"nothere\.bvh: no such file", name="nothere.bvh")
CASES[-1] = Case(CASES[-1].id, CASES[-1].needle,
                 lambda folder: ["import-bvh", str(folder / "nothere.bvh"), "-o", str(folder / "clip.usda")],
                 ("clip.usda",))


# ---- other commands ---------------------------------------------------------------------------------
def command(id: str, needle: str, argv: Callable[[Path], list[str]], outputs: tuple[str, ...] = ("out.usda",)):
    def make(folder: Path) -> list[str]:
        from bad_base import write_base
        write_base(folder)
        (folder / "shot.usda").write_text(SHOT_HEADER)
        return argv(folder)
    CASES.append(Case(id, needle, make, outputs))


command("report-no-report", r"shot\.usda: holds no mocapedit report", lambda f: ["report", str(f / "shot.usda")])
command("report-syntax", r"broken\.usda: cannot be read as a USD layer: .*broken\.usda:\d+:\d+: Expected",
        lambda f: ((f / "broken.usda").write_text('#usda 1.0\ndef Xform "World" {\n  def Xform "a" (\n'),
                   ["report", str(f / "broken.usda")])[1])
command("solve-input-folder", r"case: is a folder; give the shot's stage file",
        lambda f: ["solve", str(f), "-o", str(f / "out.usda")])
command("report-folder", r"case: is a folder", lambda f: ["report", str(f)])


def _bvhs(folder: Path, *names: str) -> list[str]:
    for name in names:
        (folder / name).write_text(GOOD_BVH)
    return [str(folder / name) for name in names]


command("import-several-into-a-layer", r"-o .*two\.usda: 2 clips are written into a folder",
        lambda f: ["import-bvh", *_bvhs(f, "a.bvh", "b.bvh"), "-o", str(f / "two.usda")], outputs=("two.usda",))
command("import-one-into-a-bvh", r"-o .*out\.bvh: a clip is written as a USD layer",
        lambda f: ["import-bvh", *_bvhs(f, "a.bvh"), "-o", str(f / "out.bvh")], outputs=("out.bvh",))
command("import-one-onto-a-text-file", r"-o .*notes\.txt: a clip is written as a USD layer",
        lambda f: ((f / "notes.txt").write_text("keep me"),
                   ["import-bvh", *_bvhs(f, "a.bvh"), "-o", str(f / "notes.txt")])[1], outputs=())
command("report-missing-file", r"gone\.usda: no such file", lambda f: ["report", str(f / "gone.usda")])
command("detect-max-speed-negative", r"max-speed", lambda f: ["detect-stationary", str(f / "shot.usda"), "-o",
                                                              str(f / "out.usda"), "--max-speed", "-1"])
command("detect-window-nan", r"window", lambda f: ["detect-stationary", str(f / "shot.usda"), "-o",
                                                   str(f / "out.usda"), "--window", "nan"])
command("detect-root-joint-missing", r"Nope", lambda f: ["detect-stationary", str(f / "shot.usda"), "-o",
                                                         str(f / "out.usda"), "--root-joint", "Nope"])
command("detect-animation-missing", r"/Nowhere", lambda f: ["detect-stationary", str(f / "shot.usda"), "-o",
                                                            str(f / "out.usda"), "--animation", "/Nowhere"])
command("solve-missing-input", r"gone\.usda: no such file", lambda f: ["solve", str(f / "gone.usda"), "-o",
                                                                       str(f / "out.usda")])



def preview(id: str, needle: str, *args: str, output: str = "out.png") -> None:
    command(f"preview-{id}", needle, lambda f: ["preview", str(f / "shot.usda"), "-o", str(f / output), *args],
            outputs=(output,))


preview("resolution-zero", r"--resolution: expected N or WxH", "--resolution", "0")
preview("resolution-huge", r"--resolution: at most 8192 pixels a side", "--resolution", "100000")
preview("resolution-huge-height", r"--resolution: at most 8192 pixels a side", "--resolution", "64x90000")
preview("bounds-inverted", r"--bounds: the maximum must exceed the minimum", "--bounds", "5", "5", "1", "1")
preview("step-zero", r"--step must be positive", "--step", "0")
preview("step-nan", r"--step must be positive", "--step", "nan")
preview("step-tiny", r"--step: 1e-09 time codes between samples asks for .* use at least", "--step", "1e-9")
preview("edits-missing", r"nothere\.usda: no such file", "--edits", "nothere.usda")
preview("output-jpg", r"out\.jpg: this file is written as \.png or \.exr", output="out.jpg")

IDS = [c.id for c in CASES]
assert len(IDS) == len(set(IDS)), sorted(i for i in IDS if IDS.count(i) > 1)
