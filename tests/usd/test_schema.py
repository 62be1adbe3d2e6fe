"""The mocapEdit schema: generated plugin, registration, fallbacks, docs, authoring API."""
from __future__ import annotations

import functools
import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import mocapedit
from mocapedit.usd import schema as S
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_USDA = ROOT / "schema" / "schema.usda"
PLUGIN_DIR = ROOT / "plugin" / "mocapEdit"

_spec = importlib.util.spec_from_file_location("mocapedit_schema_generate",
                                               ROOT / "schema" / "generate.py")
generate = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(generate)

UNIFORM, VARYING = Sdf.VariabilityUniform, Sdf.VariabilityVarying
NO_FALLBACK = object()

# The user contract, written out: per schema, each property's value type, variability,
# fallback and allowed tokens; relationships as "rel". A property added to schema.usda
# must be added here too, which is the point.
CONTRACT: dict[str, dict[str, object]] = {
    "MocapAgentAPI": {
        "mocap:animationSource": "rel",
        "mocap:rootJoint": ("token", UNIFORM, "", None),
        "mocap:hipJoint": ("token", UNIFORM, "", None),
        "mocap:collisionRadius": ("float", UNIFORM, NO_FALLBACK, None),
        "mocap:collisionHeight": ("float", UNIFORM, NO_FALLBACK, None),
        "mocap:collide": ("bool", UNIFORM, True, None),
        "mocap:pathCurve": "rel",
        "mocap:leftLegJoints": ("token[]", UNIFORM, NO_FALLBACK, None),
        "mocap:rightLegJoints": ("token[]", UNIFORM, NO_FALLBACK, None),
        "mocap:footLocking": ("bool", UNIFORM, True, None),
    },
    "MocapStationaryAPI": {
        "stationary:__INSTANCE_NAME__:frames": ("int2", UNIFORM, NO_FALLBACK, None),
    },
    "MocapFootContactAPI": {
        "footContact:__INSTANCE_NAME__:joint": ("token", UNIFORM, NO_FALLBACK, None),
        "footContact:__INSTANCE_NAME__:frames": ("int2", UNIFORM, NO_FALLBACK, None),
    },
    "MocapPositionConstraint": {
        "agent": "rel",
        "frame": ("int", UNIFORM, 0, None),
        "position": ("point3d", UNIFORM, (0.0, 0.0, 0.0), None),
        "strength": ("token", UNIFORM, "hard", ["hard", "soft"]),
        "weight": ("double", UNIFORM, 1.0, None),
    },
    "MocapRelativeConstraint": {
        "agent": "rel",
        "frame": ("int", UNIFORM, 0, None),
        "target": "rel",
        "targetFrame": ("int", UNIFORM, 0, None),
        "offset": ("vector3d", UNIFORM, NO_FALLBACK, None),
        "space": ("token", UNIFORM, "world", ["world", "target"]),
        "strength": ("token", UNIFORM, "hard", ["hard", "soft"]),
        "weight": ("double", UNIFORM, 1.0, None),
    },
    "MocapTimeConstraint": {
        "agent": "rel",
        "frame": ("int", UNIFORM, 0, None),
        "time": ("double", UNIFORM, NO_FALLBACK, None),
        "strength": ("token", UNIFORM, "hard", ["hard", "soft"]),
        "weight": ("double", UNIFORM, 1.0, None),
    },
    "MocapSyncConstraint": {
        "agent": "rel",
        "frame": ("int", UNIFORM, 0, None),
        "target": "rel",
        "targetFrame": ("int", UNIFORM, 0, None),
        "offset": ("double", UNIFORM, 0.0, None),
        "strength": ("token", UNIFORM, "hard", ["hard", "soft"]),
        "weight": ("double", UNIFORM, 1.0, None),
    },
    "MocapAgentGroup": {
        "members": "rel",
        "stiffness": ("double", UNIFORM, 1.0, None),
    },
    "MocapAvoidRegion": {
        "shape": ("token", UNIFORM, "circle", ["circle", "box"]),
        "radius": ("double", UNIFORM, 1.0, None),
        "size": ("double3", UNIFORM, (1.0, 1.0, 1.0), None),
        "margin": ("double", UNIFORM, 0.0, None),
        "agents": "rel",
        "geometry": "rel",
    },
    "MocapAnimationLayer": {
        "agents": "rel",
        "animation": "rel",
        "joint": ("token", UNIFORM, "", None),
        "mode": ("token", UNIFORM, "additive", ["blend", "additive"]),
        "weight": ("double", VARYING, 1.0, None),
        "timeOffset": ("double", UNIFORM, 0.0, None),
        "wrap": ("token", UNIFORM, "loop", ["loop", "clamp"]),
        "referencePose": ("token", UNIFORM, "firstFrame", ["firstFrame", "restPose"]),
    },
    "MocapSolveSettings": {
        "collisionAvoidance": ("bool", UNIFORM, False, None),
        "maxIterations": ("int", UNIFORM, 10, None),
        "sampleStep": ("double", UNIFORM, 1.0, None),
        "margin": ("double", UNIFORM, 0.0, None),
        "matchSpeed": ("bool", UNIFORM, False, None),
        "collisionStrategy": ("token", UNIFORM, "relinearize", ["relinearize", "accumulate"]),
        "minTimeInterval": ("double", UNIFORM, 0.1, None),
        "maxWait": ("double", UNIFORM, 3.0, None),
        "footLocking": ("bool", UNIFORM, True, None),
        "pivotOnFeet": ("bool", UNIFORM, True, None),
    },
}

API_KINDS = {"MocapAgentAPI": Usd.SchemaKind.SingleApplyAPI,
             "MocapStationaryAPI": Usd.SchemaKind.MultipleApplyAPI,
             "MocapFootContactAPI": Usd.SchemaKind.MultipleApplyAPI}
# Properties a schema gets from its base class rather than from schema.usda.
INHERITED = {"MocapAvoidRegion": {"proxyPrim", "purpose", "visibility", "xformOpOrder"}}


def close(a, b, tol=1e-9) -> bool:
    """Equal, with a tolerance for floats and float tuples (Gf vectors included)."""
    if isinstance(a, str) or isinstance(b, str) or isinstance(a, bool) or isinstance(b, bool):
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=tol, abs_tol=tol)
    a, b = list(a), list(b)
    return len(a) == len(b) and all(close(x, y, tol) for x, y in zip(a, b))


def definition(name: str) -> Usd.PrimDefinition:
    registry = Usd.SchemaRegistry()
    if name in API_KINDS:
        return registry.FindAppliedAPIPrimDefinition(name)
    return registry.FindConcretePrimDefinition(name)


@functools.cache
def source_layer() -> Sdf.Layer:
    layer = Sdf.Layer.OpenAsAnonymous(str(SCHEMA_USDA))
    assert layer, SCHEMA_USDA
    return layer


def schema_classes_in_source() -> dict[str, Sdf.PrimSpec]:
    return {spec.name: spec for spec in source_layer().rootPrims if spec.name != "GLOBAL"}


def fresh_stage() -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    return stage


def reopen(stage: Usd.Stage) -> Usd.Stage:
    layer = Sdf.Layer.CreateAnonymous(".usda")
    assert layer.ImportFromString(stage.GetRootLayer().ExportToString())
    return Usd.Stage.Open(layer)


# -- generated files ------------------------------------------------------------------

def test_committed_plugin_matches_regeneration():
    text = generate.diff(PLUGIN_DIR)
    assert text == "", "plugin/ is stale; run python schema/generate.py\n" + text


def test_check_reports_a_stale_plugin(tmp_path, capsys):
    out = tmp_path / "mocapEdit"
    shutil.copytree(PLUGIN_DIR, out)
    assert generate.main(["--check", "--out", str(out)]) == 0
    generated = out / "generatedSchema.usda"
    text = generated.read_text(encoding="utf-8")
    assert 'uniform int maxIterations = 10' in text
    generated.write_text(text.replace('uniform int maxIterations = 10',
                                      'uniform int maxIterations = 11'), encoding="utf-8")
    capsys.readouterr()
    assert generate.main(["--check", "--out", str(out)]) == 1
    report = capsys.readouterr().out
    assert "-    uniform int maxIterations = 11" in report
    assert "+    uniform int maxIterations = 10" in report
    # Regenerating repairs it, and gives the committed bytes.
    generate.main(["--out", str(out)])
    for name in generate.GENERATED_FILES:
        assert (out / name).read_bytes() == (PLUGIN_DIR / name).read_bytes()


def test_plugin_info_is_resource_only():
    text = (PLUGIN_DIR / "plugInfo.json").read_text(encoding="utf-8")
    assert "@PLUG_INFO_" not in text
    info = json.loads("".join(line for line in text.splitlines(keepends=True)
                              if not line.startswith("#")))
    (plugin,) = info["Plugins"]
    assert plugin["Name"] == "mocapEdit"
    assert plugin["Type"] == "resource"
    assert "LibraryPath" not in plugin
    assert plugin["Root"] == "." and plugin["ResourcePath"] == "."
    assert set(plugin["Info"]["Types"]) == set(CONTRACT)
    for type_name, entry in plugin["Info"]["Types"].items():
        assert entry["schemaIdentifier"] == type_name
        assert "alias" not in entry, f"{type_name}: set customData className in schema.usda"


def test_resource_plugin_info_substitution():
    template = """# comment from the generator
{
    "Plugins": [
        {
            "Info": {"Types": {}},
            "LibraryPath": "@PLUG_INFO_LIBRARY_PATH@",
            "Name": "mocapEdit",
            "ResourcePath": "@PLUG_INFO_RESOURCE_PATH@",
            "Root": "@PLUG_INFO_ROOT@",
            "Type": "resource"
        }
    ]
}
"""
    out = generate.resource_plugin_info(template)
    assert out.startswith(generate.PLUGINFO_HEADER)
    assert "comment from the generator" not in out and "@PLUG_INFO_" not in out
    (plugin,) = json.loads(out[len(generate.PLUGINFO_HEADER):])["Plugins"]
    assert plugin == {"Info": {"Types": {}}, "Name": "mocapEdit", "ResourcePath": ".",
                      "Root": ".", "Type": "resource"}
    with pytest.raises(generate.GenerateError, match="resource"):
        generate.resource_plugin_info(template.replace('"Type": "resource"',
                                                       '"Type": "library"'))


# -- registration ---------------------------------------------------------------------

def test_all_type_names_cover_the_schema_source():
    assert set(S.ALL_TYPE_NAMES) == set(schema_classes_in_source()) == set(CONTRACT)
    assert len(S.ALL_TYPE_NAMES) == len(set(S.ALL_TYPE_NAMES))
    assert all(name.startswith("Mocap") for name in S.ALL_TYPE_NAMES)


@pytest.mark.parametrize("name", sorted(CONTRACT))
def test_type_resolves_after_import(name):
    tf_type = Usd.SchemaRegistry.GetTypeFromSchemaTypeName(name)
    assert not tf_type.isUnknown, name
    assert tf_type.typeName == name
    kind = Usd.SchemaRegistry().GetSchemaKind(name)
    assert kind == API_KINDS.get(name, Usd.SchemaKind.ConcreteTyped)
    assert definition(name) is not None, name


def test_avoid_region_is_xformable():
    tf_type = Usd.SchemaRegistry.GetTypeFromSchemaTypeName("MocapAvoidRegion")
    assert tf_type.IsA(Usd.SchemaRegistry.GetTypeFromSchemaTypeName("Xformable"))
    stage = fresh_stage()
    region = S.AvoidRegion.Define(stage, "/Regions/pond")
    UsdGeom.XformCommonAPI(region.GetPrim()).SetTranslate(Gf.Vec3d(5, 0, -2))
    UsdGeom.XformCommonAPI(region.GetPrim()).SetScale(Gf.Vec3f(2, 1, 2))
    assert UsdGeom.Xformable(region.GetPrim())
    world = UsdGeom.Xformable(region.GetPrim()).ComputeLocalToWorldTransform(
        Usd.TimeCode.Default())
    assert close(world.ExtractTranslation(), (5, 0, -2))


def test_loads_in_a_fresh_process_from_the_plugin_path_alone(tmp_path):
    script = tmp_path / "probe.py"
    script.write_text(
        "import json, sys\n"
        "from pxr import Usd, Plug\n"
        "names = json.loads(sys.argv[1])\n"
        "plugin = Plug.Registry().GetPluginWithName('mocapEdit')\n"
        "stage = Usd.Stage.CreateInMemory()\n"
        "anim = stage.DefinePrim('/Anim', 'SkelAnimation')\n"
        "report = {'plugin': plugin is not None,\n"
        "          'mocapedit_imported': 'mocapedit' in sys.modules,\n"
        "          'unknown': [n for n in names if\n"
        "                      Usd.SchemaRegistry.GetTypeFromSchemaTypeName(n).isUnknown],\n"
        "          'stationary': anim.ApplyAPI('MocapStationaryAPI', 'pause')\n"
        "                        and anim.GetAttribute('stationary:pause:frames')\n"
        "                        .GetTypeName() == 'int2',\n"
        "          'fallback': stage.DefinePrim('/s', 'MocapSolveSettings')\n"
        "                      .GetAttribute('maxIterations').Get()}\n"
        "print(json.dumps(report))\n", encoding="utf-8")
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PXR_PLUGINPATH_NAME")}
    env["PXR_PLUGINPATH_NAME"] = str(PLUGIN_DIR)
    proc = subprocess.run([sys.executable, str(script), json.dumps(S.ALL_TYPE_NAMES)],
                          env=env, cwd=str(tmp_path), capture_output=True, text=True,
                          check=False, timeout=120)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report == {"plugin": True, "mocapedit_imported": False, "unknown": [],
                      "stationary": True, "fallback": 10}


def test_authoring_without_the_plugin_says_how_to_register(tmp_path):
    env = dict(os.environ, MOCAPEDIT_NO_PLUGIN="1",
               PYTHONPATH=os.pathsep.join([str(ROOT / "python"),
                                           os.environ.get("PYTHONPATH", "")]))
    env.pop("PXR_PLUGINPATH_NAME", None)
    code = ("from pxr import Usd\n"
            "from mocapedit.usd import schema\n"
            "try:\n"
            "    schema.PositionConstraint.Define(Usd.Stage.CreateInMemory(), '/c')\n"
            "except schema.SchemaNotRegisteredError as exc:\n"
            "    print('refused:', exc)\n")
    proc = subprocess.run([sys.executable, "-c", code], env=env, cwd=str(tmp_path),
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("refused:")
    assert "PXR_PLUGINPATH_NAME" in proc.stdout


# -- the contract: properties, fallbacks, docs ----------------------------------------

@pytest.mark.parametrize("name", sorted(CONTRACT))
def test_properties_match_the_contract(name):
    prim_def = definition(name)
    expected = CONTRACT[name]
    own = set(prim_def.GetPropertyNames()) - INHERITED.get(name, set())
    assert own == set(expected), name
    for prop, spec in expected.items():
        if spec == "rel":
            assert prim_def.GetRelationshipDefinition(prop), f"{name}.{prop}"
            continue
        type_name, variability, fallback, allowed = spec
        attr = prim_def.GetAttributeDefinition(prop)
        assert attr, f"{name}.{prop}"
        assert str(attr.GetTypeName()) == type_name, f"{name}.{prop}"
        assert attr.GetVariability() == variability, f"{name}.{prop}"
        value = attr.GetFallbackValue()
        if fallback is NO_FALLBACK:
            assert value is None, f"{name}.{prop} must have no fallback, has {value!r}"
        else:
            assert value is not None and close(value, fallback), f"{name}.{prop}: {value!r}"
        tokens = prim_def.GetPropertyMetadata(prop, "allowedTokens")
        assert (list(tokens) if tokens else None) == allowed, f"{name}.{prop}"


@pytest.mark.parametrize("cls", [c for c in S.ALL_SCHEMA_CLASSES
                                 if issubclass(c, S._Typed)], ids=lambda c: c.TYPE_NAME)
def test_concrete_type_defines_with_its_fallbacks(cls):
    stage = fresh_stage()
    prim = cls.Define(stage, f"/Edits/{cls.__name__}").GetPrim()
    assert prim.GetTypeName() == cls.TYPE_NAME and prim.IsA(cls.TYPE_NAME)
    for prop, spec in CONTRACT[cls.TYPE_NAME].items():
        if spec == "rel":
            assert prim.GetRelationship(prop).GetTargets() == []
            continue
        attr = prim.GetAttribute(prop)
        assert attr and not attr.HasAuthoredValue(), prop
        if spec[2] is NO_FALLBACK:
            assert attr.Get() is None, prop
        else:
            assert close(attr.Get(), spec[2]), (prop, attr.Get())
    # Nothing but the typed prim itself was authored.
    assert len(stage.GetRootLayer().GetPrimAtPath(prim.GetPath()).properties) == 0


def test_agent_api_fallbacks_and_unauthored_capsule():
    stage = fresh_stage()
    root = stage.DefinePrim("/Crowd/agent0", "SkelRoot")
    agent = S.AgentAPI.Apply(root)
    assert agent and root.HasAPI("MocapAgentAPI")
    assert agent.GetCollideAttr().Get() is True
    assert agent.GetRootJointAttr().Get() == "" and agent.GetHipJointAttr().Get() == ""
    # No fallback: the reader converts 0.3 m / 1.8 m with metersPerUnit.
    assert agent.GetCollisionRadiusAttr().Get() is None
    assert agent.GetCollisionHeightAttr().Get() is None
    assert agent.GetCollisionRadiusAttr().GetVariability() == Sdf.VariabilityUniform


def test_multiple_apply_stationary_frames():
    stage = fresh_stage()
    anim = stage.DefinePrim("/Clips/walk", "SkelAnimation")
    pause = S.StationaryAPI.Apply(anim, "pause")
    assert pause and pause.GetName() == "pause"
    attr = pause.CreateFramesAttr(Gf.Vec2i(30, 60))
    assert attr.GetName() == "stationary:pause:frames"
    assert attr.GetTypeName() == Sdf.ValueTypeNames.Int2
    assert attr.GetVariability() == Sdf.VariabilityUniform
    assert tuple(anim.GetAttribute("stationary:pause:frames").Get()) == (30, 60)

    idle = S.StationaryAPI.Apply(anim, "idle")
    idle.CreateFramesAttr((100, 120))
    assert [s.GetName() for s in S.StationaryAPI.GetAll(anim)] == ["pause", "idle"]
    assert anim.HasAPI("MocapStationaryAPI", "idle")
    assert list(anim.GetAppliedSchemas()) == ["MocapStationaryAPI:pause",
                                              "MocapStationaryAPI:idle"]

    got = S.StationaryAPI.Get(stage, "/Clips/walk.stationary:idle")
    assert got and tuple(got.GetFramesAttr().Get()) == (100, 120)
    assert tuple(S.StationaryAPI.Get(anim, "pause").GetFramesAttr().Get()) == (30, 60)
    assert S.StationaryAPI.IsStationaryAPIPath("/Clips/walk.stationary:idle")
    assert not S.StationaryAPI.IsStationaryAPIPath("/Clips/walk.stationary:idle:frames")
    assert not S.StationaryAPI.IsStationaryAPIPath("/Clips/walk")
    with pytest.raises(ValueError, match="stationary"):
        S.StationaryAPI.Get(stage, "/Clips/walk.frames")

    # The tag belongs on a clip.
    xform = stage.DefinePrim("/Clips/notAClip", "Xform")
    verdict = S.StationaryAPI.CanApply(xform, "pause")
    assert not verdict and "SkelAnimation" in verdict.whyNot
    assert S.StationaryAPI.CanApply(anim, "other")
    with pytest.raises(ValueError, match="instance name"):
        S.StationaryAPI.Apply(anim, "")


def test_docs_everywhere():
    for name, spec in schema_classes_in_source().items():
        assert spec.documentation.strip(), name
        assert definition(name).GetDocumentation().strip(), f"{name}: registry doc"
        for prop in spec.properties:
            assert prop.documentation.strip(), f"{name}.{prop.name}"
            registered = prop.name
            prefix = {"MocapStationaryAPI": "stationary", "MocapFootContactAPI": "footContact"}.get(name)
            if prefix:
                registered = Usd.SchemaRegistry.MakeMultipleApplyNameTemplate(prefix, prop.name)
            assert definition(name).GetPropertyDocumentation(registered).strip(), \
                f"{name}.{prop.name}: registry doc"


# Every attribute doc names its unit or says it has none (modes with allowedTokens are
# exempt: their values are the documentation).
UNIT_WORDS = ("stage units", "time code", "dimensionless", "no units", "frame",
              "joint path", "a count", "seconds")


def test_attribute_docs_state_units():
    for name, spec in schema_classes_in_source().items():
        for prop in spec.properties:
            if not isinstance(prop, Sdf.AttributeSpec) or prop.allowedTokens:
                continue
            doc = " ".join(prop.documentation.split())
            assert any(word in doc for word in UNIT_WORDS), f"{name}.{prop.name}: {doc}"


# -- the authoring API ----------------------------------------------------------------

def accessor_suffix(prop_name: str) -> str:
    base = prop_name.split(":")[-1]
    return base[:1].upper() + base[1:]


@pytest.mark.parametrize("cls", S.ALL_SCHEMA_CLASSES, ids=lambda c: c.SCHEMA_NAME)
def test_every_property_has_get_and_create(cls):
    expected = set()
    for prop, spec in CONTRACT[cls.SCHEMA_NAME].items():
        kind = "Rel" if spec == "rel" else "Attr"
        suffix = accessor_suffix(prop)
        expected |= {f"Get{suffix}{kind}", f"Create{suffix}{kind}"}
    accessors = {n for n in dir(cls) if n.startswith(("Get", "Create"))
                 and n.endswith(("Attr", "Rel"))}
    assert accessors == expected
    for n in accessors:
        assert getattr(cls, n).__name__ == n


def test_all_type_names_and_classes():
    assert S.ALL_TYPE_NAMES == tuple(c.SCHEMA_NAME for c in S.ALL_SCHEMA_CLASSES)
    for cls in S.ALL_SCHEMA_CLASSES:
        assert cls.SCHEMA_NAME == "Mocap" + cls.__name__
        if issubclass(cls, S._Typed):
            assert cls.TYPE_NAME == cls.SCHEMA_NAME


# Values that differ from every fallback, per property; rels get targets below.
SAMPLES = {
    "mocap:rootJoint": "Hips", "mocap:hipJoint": "Hips/Spine",
    "mocap:collisionRadius": 25.5, "mocap:collisionHeight": 175.25, "mocap:collide": False,
    "stationary:__INSTANCE_NAME__:frames": Gf.Vec2i(12, 48),
    "frame": 17, "targetFrame": 23, "position": Gf.Vec3d(1.5, 0.25, -3.75),
    "strength": "soft", "weight": 0.375, "space": "target", "time": 101.5,
    "stiffness": 2.5, "shape": "box", "radius": 3.25, "size": Gf.Vec3d(2, 1, 4),
    "margin": 0.125, "joint": "Hips/Spine/Chest", "mode": "blend", "timeOffset": -12.5,
    "wrap": "clamp", "referencePose": "restPose", "collisionAvoidance": True,
    "maxIterations": 25, "sampleStep": 0.5, "matchSpeed": True,
    "collisionStrategy": "accumulate", "minTimeInterval": 0.25, "maxWait": 1.5,
    "mocap:leftLegJoints": Vt.TokenArray(["Hips/LUpLeg", "Hips/LUpLeg/LLeg", "Hips/LUpLeg/LLeg/LFoot"]),
    "mocap:rightLegJoints": Vt.TokenArray(["RUpLeg", "RLeg", "RFoot", "RToe"]),
    "mocap:footLocking": False, "footLocking": False, "pivotOnFeet": False,
    "footContact:__INSTANCE_NAME__:joint": "LeftToe",
    "footContact:__INSTANCE_NAME__:frames": Gf.Vec2i(3, 9),
}
OFFSETS = {"MocapRelativeConstraint": Gf.Vec3d(0.75, 0, -1.25), "MocapSyncConstraint": 4.5}


def sample_value(type_name: str, prop: str):
    if prop == "offset":
        return OFFSETS[type_name]
    return SAMPLES[prop]


def make_schema(cls, stage):
    if issubclass(cls, S._Typed):
        return cls.Define(stage, f"/Edits/{cls.__name__}")
    if cls is S.AgentAPI:
        return cls.Apply(stage.DefinePrim("/Crowd/agent0", "SkelRoot"))
    return cls.Apply(stage.DefinePrim("/Clips/walk", "SkelAnimation"), "pause")


def get_schema(cls, stage):
    if issubclass(cls, S._Typed):
        return cls.Get(stage, f"/Edits/{cls.__name__}")
    if cls is S.AgentAPI:
        return cls.Get(stage, "/Crowd/agent0")
    return cls.Get(stage, f"/Clips/walk.{cls.NAMESPACE_PREFIX}:pause")


@pytest.mark.parametrize("cls", S.ALL_SCHEMA_CLASSES, ids=lambda c: c.SCHEMA_NAME)
def test_round_trip(cls):
    stage = fresh_stage()
    obj = make_schema(cls, stage)
    assert obj
    contract = CONTRACT[cls.SCHEMA_NAME]
    targets = {}
    for i, (prop, spec) in enumerate(contract.items()):
        suffix = accessor_suffix(prop)
        if spec == "rel":
            target = Sdf.Path(f"/Targets/t{i}")
            rel = getattr(obj, f"Create{suffix}Rel")()
            assert rel and rel.SetTargets([target])
            targets[prop] = [target]
        else:
            attr = getattr(obj, f"Create{suffix}Attr")(sample_value(cls.SCHEMA_NAME, prop))
            assert str(attr.GetTypeName()) == spec[0]
            assert attr.GetVariability() == spec[1]

    reopened = reopen(stage)
    again = get_schema(cls, reopened)
    assert again, cls.SCHEMA_NAME
    for prop, spec in contract.items():
        suffix = accessor_suffix(prop)
        if spec == "rel":
            assert getattr(again, f"Get{suffix}Rel")().GetTargets() == targets[prop]
            continue
        attr = getattr(again, f"Get{suffix}Attr")()
        assert attr.HasAuthoredValue(), prop
        assert str(attr.GetTypeName()) == spec[0], prop
        want = sample_value(cls.SCHEMA_NAME, prop)
        assert close(attr.Get(), want, 1e-6), (prop, attr.Get(), want)


def test_validity():
    stage = fresh_stage()
    pin = S.PositionConstraint.Define(stage, "/pin")
    plain = stage.DefinePrim("/plain", "Xform")
    assert pin and S.PositionConstraint(pin.GetPrim()) and S.PositionConstraint(pin)
    assert not S.TimeConstraint.Get(stage, "/pin")
    assert not S.PositionConstraint.Get(stage, "/missing")
    assert not S.PositionConstraint()
    assert not S.AgentAPI(plain)
    assert S.AgentAPI.CanApply(plain)
    assert S.AgentAPI.Apply(plain) and S.AgentAPI(plain)
    assert not S.StationaryAPI(stage.DefinePrim("/anim", "SkelAnimation"), "pause")
    assert not S.StationaryAPI(stage.GetPrimAtPath("/anim"))
    with pytest.raises(ValueError, match="invalid prim"):
        S.PositionConstraint().CreateFrameAttr(3)
    with pytest.raises(ValueError, match="invalid stage"):
        S.PositionConstraint.Get(None, "/pin")
    with pytest.raises(TypeError):
        S.PositionConstraint("/pin")


def test_create_write_sparsely():
    stage = fresh_stage()
    pin = S.PositionConstraint.Define(stage, "/pin")
    attr = pin.CreateWeightAttr(1.0, writeSparsely=True)
    assert attr and not attr.HasAuthoredValue()
    assert not stage.GetRootLayer().GetPropertyAtPath("/pin.weight")
    attr = pin.CreateWeightAttr(0.5, writeSparsely=True)
    assert attr.HasAuthoredValue() and close(attr.Get(), 0.5)
    # Without writeSparsely the fallback value is authored.
    assert pin.CreateFrameAttr(0).HasAuthoredValue()
    # With no value only the attribute spec is authored.
    time_pin = S.TimeConstraint.Define(stage, "/time")
    attr = time_pin.CreateTimeAttr()
    spec = stage.GetRootLayer().GetAttributeAtPath("/time.time")
    assert spec and spec.typeName == Sdf.ValueTypeNames.Double
    assert spec.variability == Sdf.VariabilityUniform and attr.Get() is None


def test_layer_weight_is_animatable():
    stage = fresh_stage()
    layer = S.AnimationLayer.Define(stage, "/Layers/phone")
    weight = layer.CreateWeightAttr()
    assert weight.Set(0.0, Usd.TimeCode(10)) and weight.Set(1.0, Usd.TimeCode(20))
    assert close(weight.Get(Usd.TimeCode(15)), 0.5)
    assert weight.GetTimeSamples() == [10.0, 20.0]


def test_relationship_targets_round_trip_through_composition():
    stage = fresh_stage()
    agents = [S.AgentAPI.Apply(stage.DefinePrim(f"/Crowd/a{i}", "SkelRoot")) for i in range(3)]
    group = S.AgentGroup.Define(stage, "/Edits/group")
    group.CreateMembersRel().SetTargets([a.GetPath() for a in agents])
    group.CreateStiffnessAttr(0.0)
    reopened = reopen(stage)
    again = S.AgentGroup.Get(reopened, "/Edits/group")
    assert again.GetMembersRel().GetForwardedTargets() == [a.GetPath() for a in agents]
    assert again.GetStiffnessAttr().Get() == 0.0
    assert isinstance(again.GetStiffnessAttr().Get(), float)


def test_package_exposes_plugin_path():
    assert Path(mocapedit.plugin_path()).resolve() == PLUGIN_DIR.resolve()
