"""Authoring API for the mocapEdit schema, shaped like USD's generated schema classes.

The schema is codeless (``schema/schema.usda``), so USD has no Python classes for it;
these thin wrappers give the same feel::

    from mocapedit.usd import schema
    pin = schema.PositionConstraint.Define(stage, "/Edits/pin")
    pin.CreateAgentRel().SetTargets([agent.GetPath()])
    pin.CreateFrameAttr(120)
    pin.CreatePositionAttr(Gf.Vec3d(4, 0, 2))

    schema.AgentAPI.Apply(skel_root)
    schema.StationaryAPI.Apply(anim_prim, "pause").CreateFramesAttr(Gf.Vec2i(30, 60))

Each class wraps a ``Usd.Prim``; it is true when the prim is valid and has the schema
(``IsA`` for typed schemas, ``HasAPI`` for API schemas). ``Get<Name>Attr`` /
``Get<Name>Rel`` return the property (possibly not authored, reading the fallback);
``Create<Name>Attr(default=None, writeSparsely=False)`` / ``Create<Name>Rel()`` author
it. Property types, variability and fallbacks come from the registered prim definition,
so ``schema/schema.usda`` stays the single source of truth. Units, spaces and meanings
are documented there.

Only authoring lives here: reading a stage into a problem is the reader's job.
"""
from __future__ import annotations

from typing import Any, Callable

from pxr import Sdf, Usd

__all__ = [
    "ALL_TYPE_NAMES",
    "ALL_SCHEMA_CLASSES",
    "SchemaNotRegisteredError",
    "AgentAPI",
    "StationaryAPI",
    "FootContactAPI",
    "PositionConstraint",
    "RelativeConstraint",
    "TimeConstraint",
    "SyncConstraint",
    "AgentGroup",
    "AvoidRegion",
    "AnimationLayer",
    "SolveSettings",
]


class SchemaNotRegisteredError(RuntimeError):
    """The mocapEdit schema plugin is not registered in this process."""


def _require_registered(schema_name: str) -> None:
    if Usd.SchemaRegistry.GetTypeFromSchemaTypeName(schema_name).isUnknown:
        raise SchemaNotRegisteredError(
            f"the schema type {schema_name!r} is not registered with USD: import mocapedit "
            "(which registers its plugin) before opening stages, or point "
            "PXR_PLUGINPATH_NAME at the plugin/mocapEdit folder")


def _as_prim(prim_or_schema: Any) -> Usd.Prim:
    if prim_or_schema is None:
        return Usd.Prim()
    if isinstance(prim_or_schema, Usd.Prim):
        return prim_or_schema
    get_prim = getattr(prim_or_schema, "GetPrim", None)
    if get_prim is None:
        raise TypeError(f"expected a Usd.Prim or a schema object, got {type(prim_or_schema)!r}")
    return get_prim()


def _stage_prim(stage: Usd.Stage, path: Sdf.Path | str) -> Usd.Prim:
    if not stage:
        raise ValueError("invalid stage")
    return stage.GetPrimAtPath(Sdf.Path(str(path)))


def _as_value_type(value: Any, type_name: Sdf.ValueTypeName) -> Any:
    # USD turns a Python tuple of ints into a double vector before it looks at the
    # attribute's type, so (30, 60) would not set an int2; build the Gf type here.
    python_class = type_name.type.pythonClass
    if python_class is not None and isinstance(value, (tuple, list)):
        return python_class(*value)
    return value


def _values_equal(a: Any, b: Any) -> bool:
    try:
        return bool(a == b)
    except Exception:  # Gf/Vt types do not all compare with every Python value
        return False


# -- accessor factories ---------------------------------------------------------------
#
# Each schema class lists its properties with one line per property, for instance
#     GetFrameAttr, CreateFrameAttr = _attribute("frame")
# ``name`` is the name declared in schema.usda; multiple-apply schemas turn it into the
# instance's property name (``frames`` -> ``stationary:pause:frames``).

def _accessor_suffix(name: str) -> str:
    """``mocap:rootJoint`` -> ``RootJoint``, as usdGenSchema names accessors."""
    base = name.split(":")[-1]
    return base[:1].upper() + base[1:]


def _attribute(name: str) -> tuple[Callable[..., Usd.Attribute], Callable[..., Usd.Attribute]]:
    def get(self) -> Usd.Attribute:
        return self._prim.GetAttribute(self._property_name(name))

    def create(self, default: Any = None, writeSparsely: bool = False) -> Usd.Attribute:
        full_name = self._property_name(name)
        prim = self._writable_prim()
        definition = self._attribute_definition(name)
        default = _as_value_type(default, definition.GetTypeName())
        if writeSparsely:
            existing = prim.GetAttribute(full_name)
            if default is None or (existing and not existing.HasAuthoredValue()
                                   and _values_equal(existing.Get(), default)):
                return existing
        attr = prim.CreateAttribute(full_name, definition.GetTypeName(), False,
                                    definition.GetVariability())
        if default is not None and not attr.Set(default):
            raise ValueError(f"{attr.GetPath()}: cannot set {default!r} "
                             f"(type {definition.GetTypeName()})")
        return attr

    accessor = _accessor_suffix(name)
    get.__name__ = get.__qualname__ = f"Get{accessor}Attr"
    create.__name__ = create.__qualname__ = f"Create{accessor}Attr"
    get.__doc__ = f"Return the {name!r} attribute (it may be unauthored and read its fallback)."
    create.__doc__ = (f"Author the {name!r} attribute, with ``default`` as its default value "
                      "if given; with writeSparsely, skip authoring a value equal to the "
                      "fallback.")
    return get, create


def _relationship(name: str) -> tuple[Callable[..., Usd.Relationship],
                                       Callable[..., Usd.Relationship]]:
    def get(self) -> Usd.Relationship:
        return self._prim.GetRelationship(self._property_name(name))

    def create(self) -> Usd.Relationship:
        _require_registered(self.SCHEMA_NAME)
        return self._writable_prim().CreateRelationship(self._property_name(name), False)

    accessor = _accessor_suffix(name)
    get.__name__ = get.__qualname__ = f"Get{accessor}Rel"
    create.__name__ = create.__qualname__ = f"Create{accessor}Rel"
    get.__doc__ = f"Return the {name!r} relationship."
    create.__doc__ = f"Author the {name!r} relationship (without targets) and return it."
    return get, create


# -- bases ----------------------------------------------------------------------------

class _Schema:
    SCHEMA_NAME: str = ""
    #: The schema's properties by their names in schema.usda; each gets ``Get<Name>Attr`` and
    #: ``Create<Name>Attr`` (``Get<Name>Rel`` and ``Create<Name>Rel``), as usdGenSchema would write.
    ATTRIBUTES: tuple[str, ...] = ()
    RELATIONSHIPS: tuple[str, ...] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for names, make in ((cls.__dict__.get("ATTRIBUTES", ()), _attribute),
                            (cls.__dict__.get("RELATIONSHIPS", ()), _relationship)):
            for name in names:
                get, create = make(name)
                setattr(cls, get.__name__, get)
                setattr(cls, create.__name__, create)

    def __init__(self, prim: Any = None) -> None:
        self._prim = _as_prim(prim)

    def GetPrim(self) -> Usd.Prim:
        return self._prim

    def GetPath(self) -> Sdf.Path:
        return self._prim.GetPath()

    def __bool__(self) -> bool:
        return bool(self._prim) and self._has_schema()

    def __repr__(self) -> str:
        return f"mocapedit.usd.schema.{type(self).__name__}({self._prim!r})"

    def _has_schema(self) -> bool:
        raise NotImplementedError

    def _property_name(self, name: str) -> str:
        return name

    def _definition(self) -> Usd.PrimDefinition:
        raise NotImplementedError

    def _definition_property_name(self, name: str) -> str:
        return name

    def _attribute_definition(self, name: str):
        _require_registered(self.SCHEMA_NAME)
        definition = self._definition().GetAttributeDefinition(
            self._definition_property_name(name))
        if not definition:
            raise SchemaNotRegisteredError(
                f"{self.SCHEMA_NAME} has no attribute {name!r} in the registered schema; "
                "the plugin is older than this module (regenerate plugin/)")
        return definition

    def _writable_prim(self) -> Usd.Prim:
        if not self._prim:
            raise ValueError(f"{type(self).__name__}: cannot author on an invalid prim")
        return self._prim


class _Typed(_Schema):
    """Base of the concrete typed schemas."""

    #: The prim type name, as in ``def MocapPositionConstraint "pin"``.
    TYPE_NAME: str = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.SCHEMA_NAME = cls.TYPE_NAME

    @classmethod
    def Define(cls, stage: Usd.Stage, path: Sdf.Path | str):
        """Define a prim of this type at ``path`` (creating ancestors as needed)."""
        if not stage:
            raise ValueError("invalid stage")
        _require_registered(cls.TYPE_NAME)
        return cls(stage.DefinePrim(Sdf.Path(str(path)), cls.TYPE_NAME))

    @classmethod
    def Get(cls, stage: Usd.Stage, path: Sdf.Path | str):
        """Wrap the prim at ``path``; the result is false unless it is of this type."""
        return cls(_stage_prim(stage, path))

    def _has_schema(self) -> bool:
        return self._prim.IsA(self.TYPE_NAME)

    def _definition(self) -> Usd.PrimDefinition:
        return Usd.SchemaRegistry().FindConcretePrimDefinition(self.TYPE_NAME)


class _SingleApplyAPI(_Schema):
    """Base of the single-apply API schemas."""

    @classmethod
    def Apply(cls, prim: Usd.Prim):
        """Apply the schema to ``prim`` (authors it in apiSchemas) and return it."""
        _require_registered(cls.SCHEMA_NAME)
        prim = _as_prim(prim)
        if not prim:
            raise ValueError(f"{cls.SCHEMA_NAME}: cannot apply to an invalid prim")
        if not prim.ApplyAPI(cls.SCHEMA_NAME):
            return cls()
        return cls(prim)

    @classmethod
    def CanApply(cls, prim: Usd.Prim):
        """Whether the schema may be applied to ``prim``; false results carry ``whyNot``."""
        _require_registered(cls.SCHEMA_NAME)
        return _as_prim(prim).CanApplyAPI(cls.SCHEMA_NAME)

    @classmethod
    def Get(cls, stage: Usd.Stage, path: Sdf.Path | str):
        """Wrap the prim at ``path``; the result is false unless the schema is applied."""
        return cls(_stage_prim(stage, path))

    def _has_schema(self) -> bool:
        return self._prim.HasAPI(self.SCHEMA_NAME)

    def _definition(self) -> Usd.PrimDefinition:
        return Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(self.SCHEMA_NAME)


class _MultipleApplyAPI(_Schema):
    """Base of the multiple-apply API schemas: one object per applied instance name."""

    #: The property namespace of every instance (``<prefix>:<name>:<property>``).
    NAMESPACE_PREFIX: str = ""

    def __init__(self, prim: Any = None, name: str = "") -> None:
        super().__init__(prim)
        if not name and isinstance(prim, _MultipleApplyAPI):
            name = prim.GetName()
        self._name = str(name)

    def GetName(self) -> str:
        """The instance name, ``pause`` in ``stationary:pause:frames``."""
        return self._name

    def __bool__(self) -> bool:
        return bool(self._prim) and bool(self._name) and self._has_schema()

    def __repr__(self) -> str:
        return f"mocapedit.usd.schema.{type(self).__name__}({self._prim!r}, {self._name!r})"

    @classmethod
    def Apply(cls, prim: Usd.Prim, name: str):
        """Apply the instance ``name`` of the schema to ``prim`` and return it."""
        _require_registered(cls.SCHEMA_NAME)
        prim = _as_prim(prim)
        if not prim:
            raise ValueError(f"{cls.SCHEMA_NAME}: cannot apply to an invalid prim")
        if not name:
            raise ValueError(f"{cls.SCHEMA_NAME}: an instance name is required")
        if not prim.ApplyAPI(cls.SCHEMA_NAME, name):
            return cls()
        return cls(prim, name)

    @classmethod
    def CanApply(cls, prim: Usd.Prim, name: str):
        """Whether instance ``name`` may be applied to ``prim``; false results carry
        ``whyNot``."""
        _require_registered(cls.SCHEMA_NAME)
        return _as_prim(prim).CanApplyAPI(cls.SCHEMA_NAME, name)

    @classmethod
    def Get(cls, stage_or_prim: Usd.Stage | Usd.Prim, path_or_name: Sdf.Path | str):
        """``Get(stage, "/Anim.stationary:pause")`` or ``Get(prim, "pause")``."""
        if isinstance(stage_or_prim, Usd.Prim):
            return cls(stage_or_prim, str(path_or_name))
        path = Sdf.Path(str(path_or_name))
        if not cls.IsSchemaPath(path):
            raise ValueError(f"{path} is not a {cls.SCHEMA_NAME} path "
                             f"(expected </Prim.{cls.NAMESPACE_PREFIX}:name>)")
        name = path.name.split(":", 1)[1]
        return cls(_stage_prim(stage_or_prim, path.GetPrimPath()), name)

    @classmethod
    def GetAll(cls, prim: Usd.Prim) -> list:
        """Every applied instance of the schema on ``prim``, in apiSchemas order."""
        prim = _as_prim(prim)
        instances = []
        for applied in (prim.GetAppliedSchemas() if prim else []):
            type_name, instance = Usd.SchemaRegistry.GetTypeNameAndInstance(applied)
            if type_name == cls.SCHEMA_NAME and instance:
                instances.append(cls(prim, instance))
        return instances

    @classmethod
    def IsSchemaPath(cls, path: Sdf.Path | str) -> bool:
        """Whether ``path`` names an instance, like </Anim.stationary:pause>."""
        path = Sdf.Path(str(path))
        if not path.IsPropertyPath():
            return False
        parts = path.name.split(":")
        return len(parts) == 2 and parts[0] == cls.NAMESPACE_PREFIX and bool(parts[1])

    def _has_schema(self) -> bool:
        return self._prim.HasAPI(self.SCHEMA_NAME, self._name)

    def _property_name(self, name: str) -> str:
        return Usd.SchemaRegistry.MakeMultipleApplyNameInstance(
            self._definition_property_name(name), self._name)

    def _definition_property_name(self, name: str) -> str:
        return Usd.SchemaRegistry.MakeMultipleApplyNameTemplate(self.NAMESPACE_PREFIX, name)

    def _definition(self) -> Usd.PrimDefinition:
        return Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(self.SCHEMA_NAME)

    def _writable_prim(self) -> Usd.Prim:
        if not self._name:
            raise ValueError(f"{type(self).__name__}: cannot author without an instance name")
        return super()._writable_prim()


# -- API schemas ----------------------------------------------------------------------

class AgentAPI(_SingleApplyAPI):
    """``MocapAgentAPI``: this character (SkelRoot, or the prim binding the skeleton) is
    an editable crowd agent."""

    SCHEMA_NAME = "MocapAgentAPI"

    RELATIONSHIPS = ("mocap:animationSource", "mocap:pathCurve")
    ATTRIBUTES = (
        "mocap:rootJoint", "mocap:hipJoint", "mocap:collisionRadius",
        "mocap:collisionHeight", "mocap:collide", "mocap:leftLegJoints",
        "mocap:rightLegJoints", "mocap:footLocking",
    )


class StationaryAPI(_MultipleApplyAPI):
    """``MocapStationaryAPI``: a named stationary frame range on a SkelAnimation clip."""

    SCHEMA_NAME = "MocapStationaryAPI"
    NAMESPACE_PREFIX = "stationary"

    ATTRIBUTES = ("frames",)

    @classmethod
    def IsStationaryAPIPath(cls, path: Sdf.Path | str) -> bool:
        """Whether ``path`` names an instance, like </Anim.stationary:pause>."""
        return cls.IsSchemaPath(path)


class FootContactAPI(_MultipleApplyAPI):
    """``MocapFootContactAPI``: a named foot contact (joint and frame range) on a SkelAnimation clip."""

    SCHEMA_NAME = "MocapFootContactAPI"
    NAMESPACE_PREFIX = "footContact"

    ATTRIBUTES = ("joint", "frames")


# -- typed schemas --------------------------------------------------------------------

class PositionConstraint(_Typed):
    """``MocapPositionConstraint``: pin an agent's root at one frame to a world position."""

    TYPE_NAME = "MocapPositionConstraint"

    RELATIONSHIPS = ("agent",)
    ATTRIBUTES = ("frame", "position", "strength", "weight")


class RelativeConstraint(_Typed):
    """``MocapRelativeConstraint``: keep an agent at an offset from another agent."""

    TYPE_NAME = "MocapRelativeConstraint"

    RELATIONSHIPS = ("agent", "target")
    ATTRIBUTES = ("frame", "targetFrame", "offset", "space", "strength", "weight")


class TimeConstraint(_Typed):
    """``MocapTimeConstraint``: make one frame of an agent play at a shot time code."""

    TYPE_NAME = "MocapTimeConstraint"

    RELATIONSHIPS = ("agent",)
    ATTRIBUTES = ("frame", "time", "strength", "weight")


class SyncConstraint(_Typed):
    """``MocapSyncConstraint``: play an agent's frame a time offset after another's."""

    TYPE_NAME = "MocapSyncConstraint"

    RELATIONSHIPS = ("agent", "target")
    ATTRIBUTES = ("frame", "targetFrame", "offset", "strength", "weight")


class AgentGroup(_Typed):
    """``MocapAgentGroup``: agents that keep their formation while any one is edited."""

    TYPE_NAME = "MocapAgentGroup"

    RELATIONSHIPS = ("members",)
    ATTRIBUTES = ("stiffness",)


class AvoidRegion(_Typed):
    """``MocapAvoidRegion``: a ground region agents stay out of.

    The prim is Xformable: place it with ``UsdGeom.XformCommonAPI(region.GetPrim())``
    or ``UsdGeom.Xformable(region.GetPrim())``.
    """

    TYPE_NAME = "MocapAvoidRegion"

    RELATIONSHIPS = ("agents", "geometry")
    ATTRIBUTES = ("shape", "radius", "size", "margin")


class AnimationLayer(_Typed):
    """``MocapAnimationLayer``: layer a joint subtree of another clip over agents."""

    TYPE_NAME = "MocapAnimationLayer"

    RELATIONSHIPS = ("agents", "animation")
    ATTRIBUTES = ("joint", "mode", "weight", "timeOffset", "wrap", "referencePose")


class SolveSettings(_Typed):
    """``MocapSolveSettings``: settings of the whole solve (at most one per stage)."""

    TYPE_NAME = "MocapSolveSettings"

    ATTRIBUTES = (
        "collisionAvoidance", "maxIterations", "sampleStep", "margin", "matchSpeed",
        "collisionStrategy", "minTimeInterval", "maxWait", "footLocking", "pivotOnFeet",
    )


#: Every schema class of the library, API schemas first.
ALL_SCHEMA_CLASSES: tuple[type[_Schema], ...] = (
    AgentAPI,
    StationaryAPI,
    FootContactAPI,
    PositionConstraint,
    RelativeConstraint,
    TimeConstraint,
    SyncConstraint,
    AgentGroup,
    AvoidRegion,
    AnimationLayer,
    SolveSettings,
)

#: The schema type names of the library (prim type names and API schema names).
ALL_TYPE_NAMES: tuple[str, ...] = tuple(cls.SCHEMA_NAME for cls in ALL_SCHEMA_CLASSES)

