"""Animation layers end to end: MocapAnimationLayer prims solved, the edits layer composed
over the input, and the result read back through UsdSkel (local transforms and FK)."""
from __future__ import annotations

import re

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdSkel, Vt

from mocapedit import _solver
from mocapedit.geometry import animation, kinematics
from mocapedit.data import examples, gestures, walker
from mocapedit.solve import layering
from mocapedit.pipeline import processor
from mocapedit.usd import schema
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.passes import Pass
from mocapedit.pipeline.passes.layering import run as run_layering
from mocapedit.pipeline.processor import EditedPath, solve

from conftest import REPO, run_cli, world_joints

FRAMES = 36
CHEST = "Root/Hips/Spine/Chest"


# ---- stage building -----------------------------------------------------------------------

def street(tmp_path, offsets=(0.0, 0.0, 5.0), frames=FRAMES, name="shot.usda", walk=None):
    """Agents a0, a1, ... walking side by side; a_i starts at shot time offsets[i]."""
    walk = walk or walker.walk(frames=frames, name="walk")
    agents = [examples.AgentSpec(f"a{i}", walk, (1.5 * i, 0.0, 0.0), 0.0, time_offset=o)
              for i, o in enumerate(offsets)]
    path = tmp_path / name
    examples.build_crowd_stage(path, agents, clips_dir=tmp_path / "clips")
    return path, walk


def add_clip(stage, path, joints, translations, rotations, scales=None, start=0.0):
    """A SkelAnimation on the shot stage with samples at start, start + 1, ..."""
    anim = UsdSkel.Animation.Define(stage, path)
    anim.GetJointsAttr().Set(list(joints))
    frames = len(translations)
    if scales is None:
        scales = np.ones((frames, len(joints), 3), np.float16)
    for f in range(frames):
        anim.GetTranslationsAttr().Set(Vt.Vec3fArray.FromNumpy(np.asarray(translations[f], np.float32)), start + f)
        anim.GetRotationsAttr().Set(Vt.QuatfArray.FromNumpy(np.asarray(rotations[f], np.float32)), start + f)
        anim.GetScalesAttr().Set(Vt.Vec3hArray.FromNumpy(np.asarray(scales[f], np.float16)), start + f)
    return anim


def add_layer(stage, path, agents, animation_path, joint="", mode="additive", weight=1.0,
              time_offset=0.0, wrap="loop", reference="firstFrame"):
    layer = schema.AnimationLayer.Define(stage, path)
    layer.CreateAgentsRel().SetTargets([Sdf.Path(a) for a in agents])
    if animation_path:
        layer.CreateAnimationRel().SetTargets([Sdf.Path(animation_path)])
    layer.CreateJointAttr(joint)
    layer.CreateModeAttr(mode)
    attr = layer.CreateWeightAttr()
    if isinstance(weight, dict):
        for t, w in weight.items():
            attr.Set(float(w), float(t))
    else:
        attr.Set(float(weight))
    layer.CreateTimeOffsetAttr(float(time_offset))
    layer.CreateWrapAttr(wrap)
    layer.CreateReferencePoseAttr(reference)
    return layer


def compose(tmp_path, stage, **options):
    stage.GetRootLayer().Save()
    edits, composed = tmp_path / "edits.usda", tmp_path / "composed.usda"
    result = solve(stage.GetRootLayer().realPath, output=str(edits), composed=str(composed), **options)
    return result, Usd.Stage.Open(str(composed))


def skel_query(stage, agent):
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(stage.GetPrimAtPath(agent)), Usd.PrimDefaultPredicate)
    return cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath(agent + "/Skel")))


def local_matrices(stage, agent, times):
    """(T,J,4,4) joint-local matrices (row vectors) of an agent, by UsdSkel."""
    q = skel_query(stage, agent)
    return np.array([np.array(q.ComputeJointLocalTransforms(Usd.TimeCode(float(t)))) for t in times])


def joints_of(stage, agent):
    return list(skel_query(stage, agent).GetJointOrder())


def quat(degrees, axis):
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    a = np.radians(degrees) / 2
    return np.append(np.sin(a) * axis, np.cos(a))


def written(result, agent):
    return bool(result.layer.GetPrimAtPath(agent + "/Skel"))


# ---- the numpy side and the job agree -----------------------------------------------------

def _random_pose(rng, t, j):
    q = rng.normal(size=(t, j, 4))
    return (rng.normal(size=(t, j, 3)).astype(np.float32), (q / np.linalg.norm(q, axis=-1, keepdims=True)).astype(np.float32),
            (1 + 0.2 * rng.normal(size=(t, j, 3))).astype(np.float32))


def _rotation_difference(a, b):
    """Largest component difference of (...,4) quaternions, b taken with a's sign."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return float(np.abs(a - sign * b).max())


def test_the_job_matches_its_numpy_peer_on_random_stacks():
    rng = np.random.default_rng(3)
    t, j = 50, 9
    source = _random_pose(rng, t, j)
    layers = []
    for mode in ("additive", "blend", "additive"):
        weights = rng.uniform(0, 1, t).astype(np.float32)
        weights[:5] = 0.0
        weights[5:10] = 1.0
        mask = rng.choice([0.0, 1.0, 0.3], size=j).astype(np.float32)
        layers.append((mode, _random_pose(rng, t, j), weights, mask))
    job = _solver.apply_layers(source, layers)
    peer = layering.apply_layers_numpy(source, layers)
    np.testing.assert_allclose(job[0], peer[0], atol=2e-5)
    np.testing.assert_allclose(job[2], peer[2], atol=2e-5)
    assert _rotation_difference(job[1], peer[1]) < 1e-6
    # The additive deltas from the builder: a clip relative to its own first frame.
    clip = _random_pose(rng, 6, j)
    dt, dr, ds = _solver.build_additive_clip(tuple(a[0] for a in clip), clip)
    assert np.all(dt[0] == 0) and np.all(ds[0] == 1) and np.all(dr[0] == [0, 0, 0, 1])
    assert _rotation_difference(layering.quat_multiply(dr, clip[1][0]), clip[1]) < 1e-6


def test_binding_errors_are_value_errors():
    rng = np.random.default_rng(0)
    source = _random_pose(rng, 4, 3)
    with pytest.raises(ValueError, match="weight of pose 2"):
        _solver.apply_layers(source, [("blend", source, np.array([0, 0.5, 1.5, 1], np.float32), None)])
    with pytest.raises(ValueError, match="mode must be 'blend' or 'additive'"):
        _solver.apply_layers(source, [("over", source, np.ones(4, np.float32), None)])
    with pytest.raises(ValueError, match="joint_weights"):
        _solver.apply_layers(source, [("blend", source, np.ones(4, np.float32), np.ones(5, np.float32))])
    with pytest.raises(ValueError, match="parents must precede"):
        _solver.subtree_joint_weights([-1, 2, 0], 0)


def test_joints_match_by_path_then_by_unique_bare_name():
    skel = ["Root", "Root/Hips", "Root/Hips/Spine", "Root/Hips/LeftLeg", "Root/Hips/RightLeg"]
    got = layering.match_joints(["Other/Spine", "Root/Hips", "Nope", "Hips"], skel)
    # Spine by its bare name; Root/Hips by path; "Hips" would claim Root/Hips a second time.
    assert got.tolist() == [2, 1, -1, -1]


def test_rest_matrices_decompose_back():
    rng = np.random.default_rng(1)
    t, r, s = _random_pose(rng, 1, 7)
    m = kinematics.compose_trs(t[0], r[0], s[0])
    bt, br, bs = layering.trs_from_matrices(m)
    np.testing.assert_allclose(kinematics.compose_trs(bt, br, bs), m, atol=2e-6)


# ---- the quality targets, on the composed stage ------------------------------------------

def test_weight_zero_gives_the_source_exactly(tmp_path):
    path, walk = street(tmp_path, offsets=(0.0, 0.0))
    stage = Usd.Stage.Open(str(path))
    idle = walker.idle(frames=FRAMES)
    add_clip(stage, "/Layers/Idle", idle.joints, idle.translations, idle.rotations)
    add_layer(stage, "/Layers/Zero", ["/World/Crowd/a0"], "/Layers/Idle", "Spine", "blend", weight=0.0)
    # Eased: zero up to time 10, then in; the poses before 10 are the source exactly.
    add_layer(stage, "/Layers/Eased", ["/World/Crowd/a1"], "/Layers/Idle", "Spine", "blend",
              weight={10: 0.0, 20: 1.0})
    result, out = compose(tmp_path, stage)
    src = Usd.Stage.Open(str(path))
    times = np.arange(FRAMES)
    assert not written(result, "/World/Crowd/a0"), "a layer at weight 0 changes nothing"
    np.testing.assert_array_equal(local_matrices(out, "/World/Crowd/a0", times),
                                  local_matrices(src, "/World/Crowd/a0", times))
    np.testing.assert_array_equal(world_joints(out, "/World/Crowd/a1/Skel", times[:11]),
                                  world_joints(src, "/World/Crowd/a1/Skel", times[:11]))
    assert not np.allclose(world_joints(out, "/World/Crowd/a1/Skel", [25]),
                           world_joints(src, "/World/Crowd/a1/Skel", [25]), atol=1e-3)


def test_blend_at_weight_one_gives_the_layer_on_the_subtree_and_the_source_elsewhere(tmp_path):
    path, walk = street(tmp_path)
    stage = Usd.Stage.Open(str(path))
    idle = walker.idle(frames=FRAMES, phase=0.3)
    add_clip(stage, "/Layers/Idle", idle.joints, idle.translations, idle.rotations)
    add_layer(stage, "/Layers/Blend", ["/World/Crowd/a0", "/World/Crowd/a2"], "/Layers/Idle", "Spine", "blend")
    result, out = compose(tmp_path, stage)
    src = Usd.Stage.Open(str(path))
    joints = joints_of(out, "/World/Crowd/a0")
    sub = np.array([j == "Root/Hips/Spine" or j.startswith("Root/Hips/Spine/") for j in joints])
    assert sub.sum() == 12
    layer_local = kinematics.compose_trs(idle.translations, idle.rotations)
    for agent, start in (("/World/Crowd/a0", 0.0), ("/World/Crowd/a2", 5.0)):
        times = start + np.arange(FRAMES)
        got = local_matrices(out, agent, times)
        # At shot time t the layer clip (times 0..35) plays frame t mod 36.
        expect = layer_local[(times.astype(int)) % FRAMES]
        np.testing.assert_allclose(got[:, sub], expect[:, sub], atol=1e-6)
        np.testing.assert_array_equal(got[:, ~sub], local_matrices(src, agent, times)[:, ~sub])
    assert not written(result, "/World/Crowd/a1")


@pytest.mark.parametrize("reference", ["firstFrame", "restPose"])
def test_an_additive_layer_equal_to_its_reference_changes_nothing(tmp_path, reference):
    path, walk = street(tmp_path, offsets=(0.0,))
    stage = Usd.Stage.Open(str(path))
    if reference == "firstFrame":
        pose = walker.idle(frames=1, phase=0.7)
        t, r = np.repeat(pose.translations, 8, 0), np.repeat(pose.rotations, 8, 0)
    else:
        t = np.repeat(walk.rest_translations[None], 8, 0)
        r = np.repeat(walk.rest_rotations[None], 8, 0)
    add_clip(stage, "/Layers/Still", walk.joints, t, r)
    add_layer(stage, "/Layers/Add", ["/World/Crowd/a0"], "/Layers/Still", "", "additive",
              weight={0: 0.2, 30: 1.0}, reference=reference)
    result, out = compose(tmp_path, stage)
    assert not written(result, "/World/Crowd/a0")
    assert result.report.stats["layeredAgents"] == 0
    assert any("unchanged" in n for n in result.report.agents["/World/Crowd/a0"]["notes"])
    src = Usd.Stage.Open(str(path))
    times = np.arange(FRAMES)
    np.testing.assert_array_equal(world_joints(out, "/World/Crowd/a0/Skel", times),
                                  world_joints(src, "/World/Crowd/a0/Skel", times))


def _known_delta_clip(stage, path, delta):
    """A one-joint (Chest) clip: frame 0 a pose P, frame 1 delta * P (same translation)."""
    p = quat(25.0, (1.0, 1.0, 0.0))
    t = np.zeros((2, 1, 3), np.float32) + np.float32([0.0, 0.2, 0.0])
    r = np.array([[p], [layering.quat_multiply(delta, p)]], np.float32)
    add_clip(stage, path, [CHEST], t, r)


@pytest.mark.parametrize("weight", [1.0, 0.5])
def test_a_known_delta_rotation_composes_exactly(tmp_path, weight):
    # A source whose chest is turned far from its rest, so that the two operand orders differ.
    walk = walker.walk(frames=FRAMES, name="walk")
    c = walk.joints.index(CHEST)
    walk.rotations[:, c] = layering.quat_multiply(quat(80.0, (1.0, 0.0, 0.2)), walk.rotations[:, c])
    path, walk = street(tmp_path, offsets=(0.0,), walk=walk)
    stage = Usd.Stage.Open(str(path))
    delta = quat(40.0, (0.3, 1.0, 0.2))
    _known_delta_clip(stage, "/Layers/Delta", delta)
    # Clamped one time code ahead, the layer plays its frame 1 (delta * P) at every shot time.
    add_layer(stage, "/Layers/Add", ["/World/Crowd/a0"], "/Layers/Delta", "Spine", "additive",
              weight=weight, time_offset=-1.0, wrap="clamp")
    result, out = compose(tmp_path, stage)
    src = Usd.Stage.Open(str(path))
    times = np.arange(FRAMES)
    got, before = local_matrices(out, "/World/Crowd/a0", times), local_matrices(src, "/World/Crowd/a0", times)
    weighted = quat(40.0 * weight, (0.3, 1.0, 0.2))
    # slerp(identity, delta, w) * source: the delta turns the joint in its parent's space,
    # after the source rotation. In USD's row-vector matrices: R(source) @ R(delta).
    expect = kinematics.compose_trs(walk.translations[:, c], layering.quat_multiply(weighted, walk.rotations[:, c]))
    np.testing.assert_allclose(got[:, c], expect, atol=1e-6)
    np.testing.assert_allclose(got[:, c, :3, :3], before[:, c, :3, :3] @ kinematics.quat_to_matrix3(weighted),
                               atol=1e-6)
    # The wrong order (source * delta) is far from it: the test can tell them apart.
    wrong = kinematics.quat_to_matrix3(weighted) @ before[:, c, :3, :3]
    assert np.abs(got[:, c, :3, :3] - wrong).max() > 0.05
    others = np.arange(len(walk.joints)) != c
    np.testing.assert_array_equal(got[:, others], before[:, others])


def test_stacking_order_follows_stage_order(tmp_path):
    idle = walker.idle(frames=FRAMES, phase=0.4)
    delta = quat(30.0, (0.0, 0.0, 1.0))
    c = idle.joints.index(CHEST)
    results = {}
    for order in (("Blend", "Add"), ("Add", "Blend")):
        folder = tmp_path / "_".join(order)
        folder.mkdir()
        path, walk = street(folder, offsets=(0.0,))
        stage = Usd.Stage.Open(str(path))
        add_clip(stage, "/Clips/Idle", idle.joints, idle.translations, idle.rotations)
        _known_delta_clip(stage, "/Clips/Delta", delta)
        for name in order:  # prims are defined, and so traversed, in this order
            if name == "Blend":
                add_layer(stage, "/Layers/Blend", ["/World/Crowd/a0"], "/Clips/Idle", "Spine", "blend")
            else:
                add_layer(stage, "/Layers/Add", ["/World/Crowd/a0"], "/Clips/Delta", "Chest", "additive",
                          time_offset=-1.0, wrap="clamp")
        result, out = compose(folder, stage)
        assert [l.path for l in result.data.layers] == [f"/Layers/{n}" for n in order]
        results[order] = local_matrices(out, "/World/Crowd/a0", np.arange(FRAMES))[:, c]
    # Blend then add: the delta goes on top of the blended pose.
    added = kinematics.compose_trs(idle.translations[:, c], layering.quat_multiply(delta, idle.rotations[:, c]))
    np.testing.assert_allclose(results[("Blend", "Add")], added, atol=1e-6)
    # Add then blend at weight 1: the blend replaces what was below it.
    np.testing.assert_allclose(results[("Add", "Blend")],
                               kinematics.compose_trs(idle.translations[:, c], idle.rotations[:, c]), atol=1e-6)


def test_time_offset_and_wrap_choose_the_layer_frame(tmp_path):
    path, walk = street(tmp_path, offsets=(0.0, 0.0, 0.0), frames=24)
    stage = Usd.Stage.Open(str(path))
    idle = walker.idle(frames=10, phase=0.1)
    add_clip(stage, "/Layers/Idle", idle.joints, idle.translations, idle.rotations)
    add_layer(stage, "/Layers/Loop", ["/World/Crowd/a0"], "/Layers/Idle", "Spine", "blend", time_offset=3.0)
    add_layer(stage, "/Layers/Clamp", ["/World/Crowd/a1"], "/Layers/Idle", "Spine", "blend", time_offset=3.0,
              wrap="clamp")
    add_layer(stage, "/Layers/Half", ["/World/Crowd/a2"], "/Layers/Idle", "Spine", "blend", time_offset=3.5)
    result, out = compose(tmp_path, stage)
    times = np.arange(24)
    head = idle.joints.index("Root/Hips/Spine/Chest/Neck/Head")
    local = kinematics.compose_trs(idle.translations, idle.rotations)[:, head]
    loop = local_matrices(out, "/World/Crowd/a0", times)[:, head]
    np.testing.assert_allclose(loop, local[(times - 3) % 10], atol=1e-6)
    clamp = local_matrices(out, "/World/Crowd/a1", times)[:, head]
    np.testing.assert_allclose(clamp, local[np.clip(times - 3, 0, 9)], atol=1e-6)
    # Half a frame off, across the loop seam: at t = 13 the clip plays 9.5, between 9 and 0.
    half = local_matrices(out, "/World/Crowd/a2", [13.0])[0, head]
    r = animation.slerp(idle.rotations[9, head], idle.rotations[0, head], 0.5)
    t = 0.5 * (idle.translations[9, head] + idle.translations[0, head])
    np.testing.assert_allclose(half, kinematics.compose_trs(t, r), atol=1e-6)


def test_layers_on_many_agents_share_data_and_unchanged_agents_are_not_written(tmp_path):
    path, walk = street(tmp_path, offsets=(0.0, 0.0, 5.0, 0.0))
    stage = Usd.Stage.Open(str(path))
    phone = gestures.phone_call(frames=48)
    add_clip(stage, "/Layers/Phone", phone.joints, phone.translations, phone.rotations)
    add_layer(stage, "/Layers/Call", ["/World/Crowd/a0", "/World/Crowd/a1", "/World/Crowd/a2"], "/Layers/Phone",
              "Spine", "additive", weight={4: 0.0, 12: 1.0, 24: 1.0, 32: 0.0}, reference="restPose")
    result, out = compose(tmp_path, stage)
    anims = [p.path for p in result.layer.GetPrimAtPath("/MocapEdit/Animations").nameChildren]
    # a0 and a1 play the same clip at the same times under the same layer: one animation.
    assert [str(p) for p in anims] == ["/MocapEdit/Animations/World_Crowd_a0", "/MocapEdit/Animations/World_Crowd_a2"]
    for agent, anim in (("a0", "a0"), ("a1", "a0"), ("a2", "a2")):
        rel = out.GetPrimAtPath(f"/World/Crowd/{agent}/Skel").GetRelationship("skel:animationSource")
        assert rel.GetTargets() == [Sdf.Path(f"/MocapEdit/Animations/World_Crowd_{anim}")]
    assert not written(result, "/World/Crowd/a3")
    assert result.report.stats["layeredAgents"] == 3
    # Shared or not, each agent plays its own layered motion.
    np.testing.assert_allclose(world_joints(out, "/World/Crowd/a1/Skel", [16])[0] - [1.5, 0, 0],
                               world_joints(out, "/World/Crowd/a0/Skel", [16])[0], atol=1e-9)


# ---- with the path and time edits ---------------------------------------------------------

@pytest.fixture
def passes(monkeypatch):
    def install(*fns):
        monkeypatch.setattr(processor, "PASSES", tuple(Pass(*p) for p in fns))
    return install


@pytest.mark.parametrize("path_edit", [False, True])
@pytest.mark.parametrize("time_edit", [False, True])
def test_layering_with_path_and_time_edits_equals_the_steps_by_hand(tmp_path, passes, path_edit, time_edit):
    path, walk = street(tmp_path, offsets=(0.0, 3.0))
    agent_path = "/World/Crowd/a1"
    stage = Usd.Stage.Open(str(path))
    phone = gestures.phone_call(frames=20)
    add_clip(stage, "/Layers/Phone", phone.joints, phone.translations, phone.rotations)
    weight = {6: 0.0, 14: 1.0, 30: 1.0, 40: 0.25}
    add_layer(stage, "/Layers/Call", [agent_path], "/Layers/Phone", "Spine", "additive", weight=weight,
              time_offset=2.5, reference="restPose")
    angle, shift = 0.6, np.array([2.0, -1.0])
    rot = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])

    def move(ctx):
        traj = ctx.trajectories[agent_path]
        ctx.paths[agent_path] = EditedPath(ground=traj.ground @ rot + shift, heading=traj.heading + angle)

    def retime(ctx):
        ctx.time_maps[agent_path] = ctx.data.agents[agent_path].sample_times * 1.5 + 4.0

    chosen = [("path", move)] if path_edit else []
    if time_edit:
        chosen.append(("time", retime))
    passes(*chosen, ("layering", run_layering))
    result, out = compose(tmp_path, stage)

    # By hand: 1. the shot times and the source frame played at each.
    src_times = 3.0 + np.arange(FRAMES)
    if time_edit:
        time_map = src_times * 1.5 + 4.0
        times = np.arange(np.ceil(time_map[0]), np.floor(time_map[-1]) + 1)
        frames = np.interp(times, time_map, np.arange(FRAMES))
    else:
        times, frames = src_times, np.arange(FRAMES, dtype=np.float64)
    # 2. the warped source pose.
    clip = result.data.clip_of(result.data.agents[agent_path])
    pose = animation.sample_pose(clip, frames)
    # 3. the layer: its clip at t - timeOffset, looped over its 20 frames; its deltas from the
    # rest pose (identity rotations, so the deltas are its rotations); the eased weight.
    u = np.mod(times - 2.5, 20.0)
    layer_pose = animation.sample_pose(result.data.clips[result.data.layers[0].clip_key], u, loop=True)
    w = np.interp(times, sorted(weight), [weight[k] for k in sorted(weight)]).astype(np.float32)
    cols = [walk.joints.index(j) for j in phone.joints]
    lt = np.zeros_like(pose.translations)
    lr = np.zeros_like(pose.rotations)
    lr[..., 3] = 1
    ls = np.ones_like(pose.scales)
    lt[:, cols] = layer_pose.translations - phone.rest_translations
    lr[:, cols] = layer_pose.rotations
    mask = np.zeros(len(walk.joints), np.float32)
    mask[cols] = 1
    t, r, s = layering.apply_layers_numpy((pose.translations, pose.rotations, pose.scales),
                                          [("additive", (lt, lr, ls), w, mask)])
    # 4. forward kinematics, placed in the world by the agent's transform.
    agent = result.data.agents[agent_path]
    world = kinematics.skel_space(kinematics.compose_trs(t, r, s), agent.parents) @ agent.skel_to_world
    expect = world[..., 3, :3]
    # 5. the path edit: a rigid turn and shift of the ground coordinates (x, -z).
    if path_edit:
        g = np.stack([expect[..., 0], -expect[..., 2]], -1) @ rot + shift
        expect = np.stack([g[..., 0], expect[..., 1], -g[..., 1]], -1)
    got = world_joints(out, agent.skeleton_path, times)
    np.testing.assert_allclose(got, expect, atol=2e-5)
    # The layer did something, where its weight is not 0.
    assert np.abs(r - pose.rotations)[w > 0].max() > 0.1


# ---- bad input ----------------------------------------------------------------------------

def _bad_stage(tmp_path, case):
    path, walk = street(tmp_path, offsets=(0.0,))
    stage = Usd.Stage.Open(str(path))
    idle = walker.idle(frames=4)
    add_clip(stage, "/Layers/Idle", idle.joints, idle.translations, idle.rotations)
    kw = dict(agents=["/World/Crowd/a0"], animation_path="/Layers/Idle", joint="Spine")
    if case == "joint":
        kw["joint"] = "Tail"
    elif case == "no-shared-joints":
        add_clip(stage, "/Layers/Alien", ["Body", "Body/Tentacle"], np.zeros((2, 2, 3)), np.tile([0, 0, 0, 1.0], (2, 2, 1)))
        kw["animation_path"] = "/Layers/Alien"
    elif case == "weight-negative":
        kw["weight"] = -0.5
    elif case == "weight-above-one":
        kw["weight"] = 1.5
    elif case == "weight-sampled":
        kw["weight"] = {0: 0.0, 10: 1.2}
    elif case == "no-animation":
        kw["animation_path"] = None
    elif case == "not-an-animation":
        kw["animation_path"] = "/World"
    elif case == "missing-prim":
        kw["animation_path"] = "/Layers/Nowhere"
    elif case == "animation-without-samples":
        UsdSkel.Animation.Define(stage, "/Layers/Empty").GetJointsAttr().Set(["Root"])
        kw["animation_path"] = "/Layers/Empty"
    elif case == "not-an-agent":
        kw["agents"] = ["/World"]
    elif case == "mode":
        add_layer(stage, "/Layers/L", **kw).GetModeAttr().Set("multiply")
        stage.GetRootLayer().Save()
        return path
    add_layer(stage, "/Layers/L", **kw)
    stage.GetRootLayer().Save()
    return path


@pytest.mark.parametrize("case,needle", [
    ("joint", r"</Layers/L>\.joint: joint 'Tail' is not in the skeleton </World/Crowd/a0/Skel>"),
    ("no-shared-joints", r"</Layers/L>\.animation: layer clip </Layers/Alien> shares no joint"),
    ("weight-negative", r"</Layers/L>\.weight: weight must be within \[0, 1\], got -0\.5"),
    ("weight-above-one", r"</Layers/L>\.weight: weight must be within \[0, 1\], got 1\.5"),
    ("weight-sampled", r"</Layers/L>\.weight: weight must be within \[0, 1\], got 1\.2 at time 10"),
    ("no-animation", r"</Layers/L>\.animation: has no animation"),
    ("not-an-animation", r"</Layers/L>\.animation: targets </World>, which is not a SkelAnimation"),
    ("missing-prim", r"</Layers/L>\.animation: targets </Layers/Nowhere>, which does not exist"),
    ("animation-without-samples", r"</Layers/L>\.animation: animation </Layers/Empty> cannot be layered: "
                                  r".*clip has no samples"),
    ("not-an-agent", r"</Layers/L>\.agents: targets </World>, which is not an agent \(no MocapAgentAPI\)"),
    ("mode", r"</Layers/L>\.mode: must be one of blend, additive, got 'multiply'"),
])
def test_bad_layers_fail_naming_the_layer_prim_and_write_nothing(tmp_path, case, needle):
    path = _bad_stage(tmp_path, case)
    out = tmp_path / "out.usda"
    proc = run_cli("solve", path, "-o", out)
    assert proc.returncode == 1, proc.stderr
    assert re.search(needle, proc.stderr), proc.stderr
    assert not out.exists()


def test_a_bare_joint_name_must_be_unique(tmp_path):
    path, walk = street(tmp_path, offsets=(0.0,))
    stage = Usd.Stage.Open(str(path))
    idle = walker.idle(frames=4)
    add_clip(stage, "/Layers/Idle", idle.joints, idle.translations, idle.rotations)
    add_layer(stage, "/Layers/L", ["/World/Crowd/a0"], "/Layers/Idle", "Root/Hips/Spine/Chest/Neck")
    stage.GetRootLayer().Save()
    solve(str(path))  # a full joint path is fine
    # Rename a joint so that two joints share the bare name "Neck".
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/World/Crowd/a0/Skel"))
    joints = list(skel.GetJointsAttr().Get())
    joints = [j.replace("LeftShoulder/LeftArm/LeftForeArm/LeftHand", "LeftShoulder/LeftArm/LeftForeArm/Neck")
              for j in joints]
    skel.GetJointsAttr().Set(joints)
    stage.GetPrimAtPath("/Layers/L").GetAttribute("joint").Set("Neck")
    with pytest.raises(MocapEditError, match=r"</Layers/L>\.joint: the bare name 'Neck' is not unique"):
        solve(stage)


# ---- the example street -------------------------------------------------------------------

def test_the_phone_call_street_example(tmp_path):
    """example_stages/layering_street.usda: five of eight walkers take a call."""
    stage_path = REPO / "example_stages" / "layering_street.usda"
    result = solve(str(stage_path), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    out, src = Usd.Stage.Open(str(tmp_path / "c.usda")), Usd.Stage.Open(str(stage_path))
    layered = {f"/World/Crowd/agent_{i:04d}" for i in (0, 2, 3, 5, 6)}
    assert {p for p in result.data.agents if written(result, p)} == layered
    hand, head = (walker.JOINTS.index(j) for j in (
        "Root/Hips/Spine/Chest/RightShoulder/RightArm/RightForeArm/RightHand", "Root/Hips/Spine/Chest/Neck/Head"))
    for agent in sorted(result.data.agents):
        skel = agent + "/Skel"
        start = float(result.data.agents[agent].sample_times[0])
        before = world_joints(out, skel, [start + 2])[0]
        np.testing.assert_array_equal(before, world_joints(src, skel, [start + 2])[0])  # weight 0 there
        mid = world_joints(out, skel, [70.0])[0]
        near = np.linalg.norm(mid[hand] - mid[head]) < 0.25
        assert near == (agent in layered), agent  # the phone at the ear in the middle of the call


def test_the_avx2_and_baseline_kernels_give_the_same_bits(tmp_path):
    """The job picks its SIMD kernel for the machine; MOCAPEDIT_NO_AVX2=1 forces the baseline."""
    import os
    import subprocess
    import sys
    script = tmp_path / "layer.py"
    script.write_text(
        "import sys\nimport numpy as np\nfrom mocapedit import _solver\n"
        "rng = np.random.default_rng(4)\n"
        "def pose():\n"
        "    q = rng.normal(size=(40, 23, 4))\n"
        "    return (rng.normal(size=(40, 23, 3)).astype(np.float32),\n"
        "            (q / np.linalg.norm(q, axis=-1, keepdims=True)).astype(np.float32),\n"
        "            (1 + 0.1 * rng.normal(size=(40, 23, 3))).astype(np.float32))\n"
        "src, a, b = pose(), pose(), pose()\n"
        "mask = np.where(np.arange(23) % 5 == 0, 0.5, 1.0).astype(np.float32)\n"
        "w = rng.uniform(0, 1, 40).astype(np.float32)\n"
        "out = _solver.apply_layers(src, [('additive', a, w, None), ('blend', b, w[::-1].copy(), mask)])\n"
        "np.save(sys.argv[1], np.concatenate([o.ravel() for o in out]))\n")
    results = []
    for flag in ("0", "1"):
        out = tmp_path / f"out{flag}.npy"
        proc = subprocess.run([sys.executable, str(script), str(out)], capture_output=True, text=True,
                              env={**os.environ, "MOCAPEDIT_NO_AVX2": flag})
        assert proc.returncode == 0, proc.stderr
        results.append(np.load(out))
    np.testing.assert_array_equal(results[0], results[1])


def test_with_the_time_pass_layering_applies_to_the_warped_pose(tmp_path):
    """Solved with the real time pass: the layered result is the time-only result (read back
    from its composed stage) layered by hand at the same shot times."""
    path, walk = street(tmp_path, offsets=(0.0,))
    stage = Usd.Stage.Open(str(path))
    examples.add_time_constraint(stage, "/Edits/Late", "/World/Crowd/a0", 20, 31.5)
    stage.GetRootLayer().Save()
    (tmp_path / "time").mkdir()
    # Baked, so its samples sit on the shot times the layered result is baked at.
    _, warped = compose(tmp_path / "time", stage, bake_timing=True)
    phone = gestures.phone_call(frames=24)
    add_clip(stage, "/Layers/Phone", phone.joints, phone.translations, phone.rotations)
    weight = {4: 0.0, 16: 1.0}
    add_layer(stage, "/Layers/Call", ["/World/Crowd/a0"], "/Layers/Phone", "Spine", "additive", weight=weight,
              reference="restPose")
    both, out = compose(tmp_path, stage)
    anim = warped.GetPrimAtPath("/MocapEdit/Animations/World_Crowd_a0")
    times = np.array(anim.GetAttribute("rotations").GetTimeSamples())
    assert len(times) > FRAMES, "the constraint slows the clip down"
    assert times.tolist() == out.GetPrimAtPath("/MocapEdit/Animations/World_Crowd_a0") \
        .GetAttribute("rotations").GetTimeSamples()
    pose = [np.array([np.array(anim.GetAttribute(n).Get(t)) for t in times], np.float32)
            for n in ("translations", "rotations", "scales")]
    layer_pose = animation.sample_pose(both.data.clips[both.data.layers[0].clip_key], times, loop=True)
    cols = [walk.joints.index(j) for j in phone.joints]
    lt, lr, ls = np.zeros_like(pose[0]), np.zeros_like(pose[1]), np.ones_like(pose[2])
    lr[..., 3] = 1
    lr[:, cols] = layer_pose.rotations
    w = np.interp(times, sorted(weight), [weight[k] for k in sorted(weight)]).astype(np.float32)
    mask = np.zeros(len(walk.joints), np.float32)
    mask[cols] = 1
    _, expect, _ = layering.apply_layers_numpy(tuple(pose), [("additive", (lt, lr, ls), w, mask)])
    got = out.GetPrimAtPath("/MocapEdit/Animations/World_Crowd_a0").GetAttribute("rotations")
    got = np.array([np.array(got.Get(t)) for t in times])
    assert _rotation_difference(got, expect) < 1e-6
    assert _rotation_difference(got, pose[1]) > 0.1


@pytest.mark.parametrize("mode,reference", [("blend", "firstFrame"), ("additive", "firstFrame"),
                                            ("additive", "restPose")])
def test_a_layer_clip_with_rotations_only_leaves_translations_and_scales_to_the_source(tmp_path, mode, reference):
    path, walk = street(tmp_path, offsets=(0.0,))
    stage = Usd.Stage.Open(str(path))
    nod = UsdSkel.Animation.Define(stage, "/Layers/Nod")
    nod.GetJointsAttr().Set([CHEST])
    rotations = [quat(0.0, (1, 0, 0)), quat(30.0, (1, 0, 0)), quat(10.0, (0, 1, 1))]
    for f, q in enumerate(rotations):
        nod.GetRotationsAttr().Set(Vt.QuatfArray.FromNumpy(np.array([q], np.float32)), 12.0 * f)
    add_layer(stage, "/Layers/L", ["/World/Crowd/a0"], "/Layers/Nod", "", mode, reference=reference)
    result, out = compose(tmp_path, stage)
    notes = result.report.agents["/World/Crowd/a0"]["notes"]
    keeps = "stay as below" if mode == "blend" else "get nothing added"
    assert f"layer </Layers/L>: {mode} on 1 joints from (whole skeleton); the clip authors rotations only: " \
           f"translations and scales {keeps}" in notes
    src = Usd.Stage.Open(str(path))
    chest = joints_of(out, "/World/Crowd/a0").index(CHEST)
    times = np.arange(FRAMES)
    got_t, got_r, got_s = layering.trs_from_matrices(local_matrices(out, "/World/Crowd/a0", times)[:, chest])
    src_t, src_r, src_s = layering.trs_from_matrices(local_matrices(src, "/World/Crowd/a0", times)[:, chest])
    np.testing.assert_allclose(got_t, src_t, atol=1e-6)
    np.testing.assert_allclose(got_s, src_s, atol=1e-6)
    assert _rotation_difference(got_r, src_r) > 0.05, "the rotations are layered"
    if mode == "blend":  # at weight 1 the chest turns as the clip says, at its samples
        for f, q in enumerate(rotations):
            assert _rotation_difference(got_r[12 * f], q) < 1e-5


def test_a_layer_clip_from_another_rig_stops_the_solve_before_any_other_pass(tmp_path, monkeypatch):
    path, walk = street(tmp_path, offsets=(0.0, 0.0))
    stage = Usd.Stage.Open(str(path))
    add_clip(stage, "/Layers/Alien", ["Tentacle"], np.zeros((2, 1, 3)), np.tile([0, 0, 0, 1.0], (2, 1, 1)))
    add_layer(stage, "/Layers/L", ["/World/Crowd/a0"], "/Layers/Alien")
    stage.GetRootLayer().Save()
    ran = []
    monkeypatch.setattr(processor, "PASSES", tuple(
        Pass(p.name, lambda ctx, p=p: (ran.append(p.name), p.run(ctx))) for p in processor.PASSES))
    with pytest.raises(MocapEditError, match=r"</Layers/L>\.animation: layer clip </Layers/Alien> shares no joint"):
        solve(str(path), output=str(tmp_path / "e.usda"), collisions=True)
    assert ran == ["layering-check"], "path edits, time warp and collision avoidance must not run first"
    assert not (tmp_path / "e.usda").exists()


def test_a_partial_layer_between_full_ones_keeps_the_channels_of_the_layers_below(tmp_path):
    path, walk = street(tmp_path, offsets=(0.0, 0.0))
    stage = Usd.Stage.Open(str(path))
    idle = walker.idle(frames=FRAMES, phase=0.4)
    add_clip(stage, "/Layers/Idle", idle.joints, idle.translations, idle.rotations)
    nod = UsdSkel.Animation.Define(stage, "/Layers/Nod")
    nod.GetJointsAttr().Set([CHEST])
    nod.GetRotationsAttr().Set(Vt.QuatfArray.FromNumpy(np.array([quat(40.0, (1, 0, 0))], np.float32)), 0.0)
    # a0: the idle blended on the spine, then the nod on the chest, then the idle added again;
    # a1: the same without the nod.
    add_layer(stage, "/Layers/A", ["/World/Crowd/a0", "/World/Crowd/a1"], "/Layers/Idle", "Spine", "blend", weight=0.7)
    add_layer(stage, "/Layers/B", ["/World/Crowd/a0"], "/Layers/Nod", "", "blend")
    add_layer(stage, "/Layers/C", ["/World/Crowd/a0", "/World/Crowd/a1"], "/Layers/Idle", "Spine", "additive",
              weight=0.5)
    result, out = compose(tmp_path, stage)
    joints = joints_of(out, "/World/Crowd/a0")
    chest = joints.index(CHEST)
    times = np.arange(FRAMES)
    with_nod = layering.trs_from_matrices(local_matrices(out, "/World/Crowd/a0", times))
    without = layering.trs_from_matrices(local_matrices(out, "/World/Crowd/a1", times))
    # The nod leaves every translation and scale, and every joint but the chest, as the layers
    # around it make them; the chest's rotation is the nod's, then layer C's delta on top.
    np.testing.assert_allclose(with_nod[0], without[0], atol=1e-6)
    np.testing.assert_allclose(with_nod[2], without[2], atol=1e-6)
    others = np.arange(len(joints)) != chest
    assert _rotation_difference(with_nod[1][:, others], without[1][:, others]) < 1e-6
    assert _rotation_difference(with_nod[1][:, chest], without[1][:, chest]) > 0.05


def test_a_blended_joint_that_hangs_from_another_parent_in_the_layer_clip_is_noted(tmp_path):
    """A layer clip of another rig, rooted at Hips where the agents' skeleton has Root above
    Hips: its joints match by bare name, and Hips' transform, relative to nothing in its clip,
    is taken relative to Root: a body rooted elsewhere lies a metre away on the ground (a CMU
    punch blended over a CC walk), with no word. The report now says which joint and why."""
    path, walk = street(tmp_path)
    stage = Usd.Stage.Open(str(path))
    idle = walker.idle(frames=FRAMES, phase=0.3)
    keep = [k for k, j in enumerate(idle.joints) if j != "Root"]
    add_clip(stage, "/Layers/Other", [idle.joints[k][len("Root/"):] for k in keep],
             idle.translations[:, keep], idle.rotations[:, keep])
    add_layer(stage, "/Layers/Blend", ["/World/Crowd/a0"], "/Layers/Other", "", "blend")
    result, _ = compose(tmp_path, stage)
    notes = result.report.agents["/World/Crowd/a0"].get("notes") or []
    assert any("'Hips' hangs from nothing in the layer's clip but from 'Root'" in n for n in notes), notes
    # A clip of the same rig says nothing of it.
    (tmp_path / "same").mkdir()
    path2, _ = street(tmp_path / "same")
    stage2 = Usd.Stage.Open(str(path2))
    add_clip(stage2, "/Layers/Idle", idle.joints, idle.translations, idle.rotations)
    add_layer(stage2, "/Layers/Blend", ["/World/Crowd/a0"], "/Layers/Idle", "", "blend")
    result2, _ = compose(tmp_path / "same", stage2)
    assert not any("hangs from" in n for n in result2.report.agents["/World/Crowd/a0"].get("notes") or [])
