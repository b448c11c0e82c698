"""Tests for drake_skill.perception.systems (the PcaeFeaturizer LeafSystem)."""

import numpy as np
import pytest
import torch
from pydrake.common.value import AbstractValue
from pydrake.common.yaml import yaml_load_typed
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from drake_skill.perception import pcae
from drake_skill.perception.features import GoalFeatures
from drake_skill.perception.systems import PcaeFeaturizer, PcaeFeaturizerConfig

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    m = pcae.PointCloudAutoencoder()
    with torch.no_grad():
        m.train()
        m(pcae.normalize_points(torch.rand(4, pcae.N_POINTS, 3) * 0.3))
    return m.eval()


def _cloud(seed, size=(0.3, 0.2, 0.15)):
    return np.random.default_rng(seed).uniform(0.0, 1.0, size=(pcae.N_POINTS, 3)) * np.asarray(size)


@pytest.fixture(scope="module")
def pca(model):
    codes = model.encode_points(np.stack([_cloud(100 + i, (0.2 + 0.01 * i, 0.2, 0.1 + 0.02 * i)) for i in range(20)]))
    return GoalFeatures(8).fit(codes)


class FrameSource(LeafSystem):
    """Test source: frame k = floor(t / 0.1) outputs clouds[k] and valid[k] (the last one after the end)."""

    def __init__(self, clouds, valid):
        super().__init__()
        self._clouds, self._valid = clouds, valid
        self.DeclareAbstractOutputPort("object_points", lambda: AbstractValue.Make(np.zeros((pcae.N_POINTS, 3))),
                                       self._calc_points)
        self.DeclareVectorOutputPort("valid", 1, self._calc_valid)

    def _k(self, context):
        return min(int(np.floor(context.get_time() / 0.1 + 1e-9)), len(self._valid) - 1)

    def _calc_points(self, context, output):
        output.set_value(self._clouds[self._k(context)])

    def _calc_valid(self, context, output):
        output.SetAtIndex(0, float(self._valid[self._k(context)]))


def _diagram(model, pca, clouds, valid):
    b = DiagramBuilder()
    src = b.AddSystem(FrameSource(clouds, valid))
    feat = b.AddSystem(PcaeFeaturizer(pca, model=model))
    b.Connect(src.GetOutputPort("object_points"), feat.get_object_points_input_port())
    b.Connect(src.GetOutputPort("valid"), feat.get_valid_input_port())
    return b.Build(), feat


def _read(feat, diagram_context):
    ctx = feat.GetMyContextFromRoot(diagram_context)
    return (
        feat.get_code_output_port().Eval(ctx).copy(),
        feat.get_goal_data_output_port().Eval(ctx).copy(),
        float(feat.get_goal_valid_output_port().Eval(ctx)[0]),
    )


def test_ports(model, pca):
    feat = PcaeFeaturizer(pca, model=model)
    assert feat.get_input_port(0).get_name() == "object_points"
    assert feat.get_input_port(1).get_name() == "valid"
    assert [feat.get_output_port(i).get_name() for i in range(3)] == ["code", "goal_data", "goal_valid"]
    assert feat.get_code_output_port().size() == 128
    assert feat.get_goal_data_output_port().size() == 8
    # No direct feedthrough: outputs come from the state only.
    assert not feat.HasAnyDirectFeedthrough()


def test_holds_last_valid_code_on_invalid_frames(model, pca):
    a, b, c = _cloud(1), _cloud(2, (0.3, 0.2, 0.3)), _cloud(3, (0.1, 0.1, 0.4))
    garbage = np.full((pcae.N_POINTS, 3), np.nan)  # invalid frames may carry anything
    clouds = [a, b, garbage, garbage, garbage, c, c]
    valid = [1, 1, 0, 0, 0, 1, 1]
    diagram, feat = _diagram(model, pca, clouds, valid)
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    code_b, code_c = model.encode_points(b), model.encode_points(c)
    assert np.linalg.norm(code_b - code_c) > 1e-2

    code, goal, ok = _read(feat, ctx)  # before any update: zeros, not valid
    assert ok == 0.0 and not np.any(code) and not np.any(goal)

    sim.AdvanceTo(0.15)  # frames 0 (a) and 1 (b), both valid
    code, goal, ok = _read(feat, ctx)
    np.testing.assert_allclose(code, code_b, atol=1e-6)
    np.testing.assert_allclose(goal, pca.transform(code_b), atol=1e-6)
    assert ok == 1.0

    for t in (0.25, 0.35, 0.45):  # frames 2-4 invalid: held and marked
        sim.AdvanceTo(t)
        code, goal, ok = _read(feat, ctx)
        np.testing.assert_allclose(code, code_b, atol=1e-6)
        np.testing.assert_allclose(goal, pca.transform(code_b), atol=1e-6)
        assert ok == 0.0
        assert feat.has_valid_frame(feat.GetMyContextFromRoot(ctx))

    sim.AdvanceTo(0.55)  # frame 5 valid again
    code, goal, ok = _read(feat, ctx)
    np.testing.assert_allclose(code, code_c, atol=1e-6)
    assert ok == 1.0

    # Reset to defaults starts a new run; a second run gives the same numbers.
    diagram.SetDefaultContext(ctx)
    ctx.SetTime(0.0)
    code, goal, ok = _read(feat, ctx)
    assert ok == 0.0 and not np.any(code)
    sim.Initialize()
    sim.AdvanceTo(0.15)
    np.testing.assert_array_equal(_read(feat, ctx)[0], model.encode_points(b))


def test_without_pca_and_unconnected_valid(model):
    b = DiagramBuilder()
    src = b.AddSystem(FrameSource([_cloud(4)], [1]))
    feat = b.AddSystem(PcaeFeaturizer(None, PcaeFeaturizerConfig(period_s=0.05), model=model))
    b.Connect(src.GetOutputPort("object_points"), feat.get_object_points_input_port())
    diagram = b.Build()
    sim = Simulator(diagram)
    sim.AdvanceTo(0.01)
    code, goal, ok = _read(feat, sim.get_context())
    np.testing.assert_allclose(code, model.encode_points(_cloud(4)), atol=1e-6)
    assert not np.any(goal) and ok == 0.0  # no PCA: goal data not available


def test_bad_points_on_a_valid_frame_raise(model, pca):
    diagram, _ = _diagram(model, pca, [np.zeros((100, 3))], [1])
    sim = Simulator(diagram)
    with pytest.raises(ValueError, match=r"object_points: expected 2048 points .*got shape \(100, 3\)"):
        sim.AdvanceTo(0.05)


def test_config_and_construction_errors(model, pca):
    cfg = yaml_load_typed(schema=PcaeFeaturizerConfig, data="period_s: 0.2\noffset_s: 0.05\n")
    feat = PcaeFeaturizer(pca, cfg, model=model)
    attr = feat.GetUniquePeriodicDiscreteUpdateAttribute()
    assert (attr.period_sec(), attr.offset_sec()) == (0.2, 0.05)
    with pytest.raises(ValueError, match=r"config.period_s: expected a finite period > 0 s, got 0.0"):
        PcaeFeaturizer(pca, PcaeFeaturizerConfig(period_s=0.0), model=model)
    with pytest.raises(ValueError, match="not fitted"):
        PcaeFeaturizer(GoalFeatures(), model=model)
    with pytest.raises(FileNotFoundError, match="missing.safetensors"):
        PcaeFeaturizer(pca, PcaeFeaturizerConfig(weights="/nonexistent/missing.safetensors"))


def test_shipped_weights_load():
    feat = PcaeFeaturizer(None)
    ctx = feat.CreateDefaultContext()
    feat.get_object_points_input_port().FixValue(ctx, AbstractValue.Make(_cloud(5)))
    feat.get_valid_input_port().FixValue(ctx, [1.0])
    state = feat.EvalUniquePeriodicDiscreteUpdate(ctx)
    code = state.get_vector(0).get_value()
    assert code.shape == (128,) and np.all(np.isfinite(code)) and np.any(code > 0)
    np.testing.assert_allclose(code, pcae.load_pcae().encode_points(_cloud(5)), atol=1e-6)


def test_cloud_in_object_frame_matches_drake_transform():
    from pydrake.math import RigidTransform, RotationMatrix

    X_WO = RigidTransform(RotationMatrix.MakeZRotation(0.07), [0.45, -0.02, 0.001])
    pts = _cloud(7) + [0.3, -0.1, 0.0]
    expected = (X_WO.inverse() @ pts.T).T
    vec = np.concatenate([X_WO.translation(), X_WO.rotation().ToQuaternion().wxyz()])
    np.testing.assert_allclose(pcae.cloud_in_object_frame(pts, vec), expected, atol=1e-6)
    np.testing.assert_allclose(pcae.cloud_in_object_frame(pts[None], X_WO.GetAsMatrix4())[0], expected, atol=1e-6)
    with pytest.raises(ValueError, match="X_WO"):
        pcae.cloud_in_object_frame(pts, np.zeros(6))


def test_object_frame_latched_at_the_first_valid_frame(model, pca):
    """With X_WO connected the clouds are encoded in the object frame of the run's first valid frame."""
    from pydrake.math import RigidTransform, RotationMatrix

    a, b = _cloud(11) + [0.4, 0.0, 0.0], _cloud(12) + [0.4, 0.0, 0.0]
    X1 = RigidTransform(RotationMatrix.MakeZRotation(0.08), [0.45, 0.01, 0.0])
    builder = DiagramBuilder()
    src = builder.AddSystem(FrameSource([a, a, b], [0, 1, 1]))
    feat = builder.AddSystem(PcaeFeaturizer(pca, model=model))
    builder.Connect(src.GetOutputPort("object_points"), feat.get_object_points_input_port())
    builder.Connect(src.GetOutputPort("valid"), feat.get_valid_input_port())
    builder.ExportInput(feat.get_X_WO_input_port(), "X_WO")
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    diagram.get_input_port(0).FixValue(ctx, X1)
    sim.AdvanceTo(0.15)      # frame 1: the first valid one latches X1
    np.testing.assert_allclose(_read(feat, ctx)[0],
                               model.encode_points(pcae.cloud_in_object_frame(a, X1.GetAsMatrix4())), atol=1e-6)
    # Moving the perceived pose afterwards does not move the frame of this run.
    diagram.get_input_port(0).FixValue(ctx, RigidTransform([0.1, 0.0, 0.0]))
    sim.AdvanceTo(0.25)
    code_b = _read(feat, ctx)[0]
    np.testing.assert_allclose(code_b, model.encode_points(pcae.cloud_in_object_frame(b, X1.GetAsMatrix4())), atol=1e-6)
    assert np.linalg.norm(code_b - model.encode_points(b)) > 1e-4
