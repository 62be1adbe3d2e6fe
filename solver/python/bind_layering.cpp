#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "mocapedit/additive_clip.h"
#include "mocapedit/layering.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using mocapedit::ConstPoseStreamView;
using mocapedit::PoseStreamView;
using mocapedit::Span;

// Three arrays (translations (..., 3), rotations (..., 4), scales (..., 3)) with the same
// leading shape, as float32 C-contiguous copies when needed.
struct PoseArrays {
  FloatArray t, r, s;
  std::vector<py::ssize_t> lead;  // leading shape, e.g. (T, J)

  PoseArrays(const py::tuple& arrays, const char* what, std::size_t lead_dims) {
    if (arrays.size() != 3)
      throw std::invalid_argument(std::string(what) + ": expected (translations, rotations, scales)");
    t = FloatArray::ensure(arrays[0]);
    r = FloatArray::ensure(arrays[1]);
    s = FloatArray::ensure(arrays[2]);
    if (!t || !r || !s) throw std::invalid_argument(std::string(what) + ": arrays of numbers expected");
    const std::size_t nd = lead_dims + 1;
    auto check = [&](const FloatArray& a, py::ssize_t width, const char* name) {
      if (static_cast<std::size_t>(a.ndim()) != nd || a.shape(a.ndim() - 1) != width)
        throw std::invalid_argument(std::string(what) + " " + name + ": expected " + std::to_string(nd) +
                                    " dimensions ending in " + std::to_string(width));
    };
    check(t, 3, "translations");
    check(r, 4, "rotations");
    check(s, 3, "scales");
    lead.assign(t.shape(), t.shape() + lead_dims);
    for (std::size_t d = 0; d < lead_dims; ++d)
      if (r.shape(d) != lead[d] || s.shape(d) != lead[d])
        throw std::invalid_argument(std::string(what) + ": translations, rotations and scales differ in shape");
  }

  ConstPoseStreamView view() const {
    return ConstPoseStreamView(Span<const float>(t.data(), t.size()), Span<const float>(r.data(), r.size()),
                               Span<const float>(s.data(), s.size()));
  }
};

struct PoseOutput {
  FloatArray t, r, s;
  explicit PoseOutput(const std::vector<py::ssize_t>& lead) {
    auto shape = [&](py::ssize_t w) {
      auto v = lead;
      v.push_back(w);
      return v;
    };
    t = FloatArray(shape(3));
    r = FloatArray(shape(4));
    s = FloatArray(shape(3));
  }
  PoseStreamView view() {
    return {Span<float>(t.mutable_data(), t.size()), Span<float>(r.mutable_data(), r.size()),
            Span<float>(s.mutable_data(), s.size())};
  }
  py::tuple tuple() const { return py::make_tuple(t, r, s); }
};

// Runs a job or builder without the GIL (its validation failure is an InvalidInput).
template <typename Job>
void RunWithoutGil(const Job& job) {
  py::gil_scoped_release release;
  job.Run();
}

mocapedit::LayerMode ParseMode(const std::string& mode) {
  if (mode == "blend") return mocapedit::LayerMode::kBlend;
  if (mode == "additive") return mocapedit::LayerMode::kAdditive;
  throw std::invalid_argument("layer mode must be 'blend' or 'additive', got '" + mode + "'");
}

}  // namespace

MOCAPEDIT_BINDINGS(BindLayering) {
  m.def(
      "subtree_joint_weights",
      [](const std::vector<int>& parents, int root) {
        const auto w = mocapedit::SubtreeJointWeights(Span<const int>(parents), root);
        return FloatArray(static_cast<py::ssize_t>(w.size()), w.data());
      },
      py::arg("parents"), py::arg("root"),
      "(J,) float32 joint weights: 1 for `root` and every joint below it, 0 elsewhere.\n\n"
      "`parents` (J,) parent index per joint (-1 for a root), parents before children;\n"
      "`root` -1 selects the whole skeleton.");

  m.def(
      "build_additive_clip",
      [](const py::tuple& reference, const py::tuple& clip) {
        const PoseArrays ref(reference, "reference", 1), c(clip, "clip", 2);
        mocapedit::AdditiveClipBuilder builder;
        builder.num_frames = static_cast<std::size_t>(c.lead[0]);
        builder.num_joints = static_cast<std::size_t>(c.lead[1]);
        if (ref.lead[0] != c.lead[1])
          throw std::invalid_argument("reference has " + std::to_string(ref.lead[0]) + " joints, the clip " +
                                      std::to_string(c.lead[1]));
        PoseOutput out(c.lead);
        builder.reference = ref.view();
        builder.clip = c.view();
        builder.output = out.view();
        RunWithoutGil(builder);
        return out.tuple();
      },
      py::arg("reference"), py::arg("clip"),
      "Deltas of a clip from a reference pose: the offline half of additive layering.\n\n"
      "reference: (translations (J,3), rotations (J,4) xyzw, scales (J,3)), one pose;\n"
      "clip: (translations (F,J,3), rotations (F,J,4), scales (F,J,3)).\n"
      "Returns (F,J,3), (F,J,4), (F,J,3) float32: clip - reference, clip * inverse(reference)\n"
      "(normalised, w >= 0), clip / reference.");

  m.def(
      "apply_layers",
      [](const py::tuple& source, const py::list& layers) {
        const PoseArrays src(source, "source", 2);
        const auto T = static_cast<std::size_t>(src.lead[0]), J = static_cast<std::size_t>(src.lead[1]);
        std::vector<PoseArrays> transforms;
        std::vector<FloatArray> weights, joint_weights;
        std::vector<mocapedit::LayeringJob::Layer> job_layers;
        transforms.reserve(layers.size());
        for (std::size_t l = 0; l < layers.size(); ++l) {
          const py::tuple item = layers[l].cast<py::tuple>();
          if (item.size() != 4)
            throw std::invalid_argument("layer " + std::to_string(l) +
                                        ": expected (mode, (translations, rotations, scales), weights, "
                                        "joint_weights or None)");
          mocapedit::LayeringJob::Layer layer;
          layer.mode = ParseMode(item[0].cast<std::string>());
          transforms.emplace_back(item[1].cast<py::tuple>(), "layer transforms", 2);
          layer.transforms = transforms.back().view();
          weights.push_back(FloatArray::ensure(item[2]));
          if (!weights.back() || weights.back().ndim() != 1)
            throw std::invalid_argument("layer " + std::to_string(l) + ": weights must be a (T,) array");
          layer.weights = Span<const float>(weights.back().data(), weights.back().size());
          if (!item[3].is_none()) {
            joint_weights.push_back(FloatArray::ensure(item[3]));
            if (!joint_weights.back() || joint_weights.back().ndim() != 1)
              throw std::invalid_argument("layer " + std::to_string(l) + ": joint_weights must be a (J,) array");
            layer.joint_weights = Span<const float>(joint_weights.back().data(), joint_weights.back().size());
          }
          job_layers.push_back(layer);
        }
        PoseOutput out(src.lead);
        mocapedit::LayeringJob job;
        job.num_poses = T;
        job.num_joints = J;
        job.source = src.view();
        job.layers = Span<const mocapedit::LayeringJob::Layer>(job_layers.data(), job_layers.size());
        job.output = out.view();
        RunWithoutGil(job);
        return out.tuple();
      },
      py::arg("source"), py::arg("layers"),
      "Layers poses in joint-local space (the C++ LayeringJob).\n\n"
      "source: (translations (T,J,3), rotations (T,J,4) xyzw, scales (T,J,3)).\n"
      "layers: list, in stacking order, of (mode 'blend'|'additive', (t, r, s) each (T,J,...),\n"
      "weights (T,) in [0,1], joint_weights (J,) in [0,1] or None). Additive layers take deltas\n"
      "(build_additive_clip). Returns new (T,J,3), (T,J,4), (T,J,3) float32 arrays.");
}
