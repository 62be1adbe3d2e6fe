#include <pybind11/eigen.h>
#include <pybind11/numpy.h>

#include <stdexcept>

#include "mocapedit/clip_sampling.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;

// A (F, J, width) float32 array viewed as F*J rows.
template <typename Rows>
Eigen::Map<const Rows> RowsOf(const FloatArray& a, const char* name, py::ssize_t width) {
  if (a.ndim() != 3 || a.shape(2) != width)
    throw std::invalid_argument(std::string("sample_clip: ") + name + " must have shape (F, J, " +
                                std::to_string(width) + ")");
  return Eigen::Map<const Rows>(a.data(), a.shape(0) * a.shape(1), width);
}

}  // namespace

MOCAPEDIT_BINDINGS(BindClipSampling) {
  using mocapedit::Quatf4Rows;
  using mocapedit::Vec3fRows;
  m.def(
      "sample_clip",
      [](const FloatArray& translations, const FloatArray& rotations, const FloatArray& scales,
         const Eigen::Ref<const Eigen::VectorXd>& frames) {
        const auto t = RowsOf<Vec3fRows>(translations, "translations", 3);
        const auto r = RowsOf<Quatf4Rows>(rotations, "rotations", 4);
        const auto s = RowsOf<Vec3fRows>(scales, "scales", 3);
        const py::ssize_t joints = translations.shape(1);
        if (rotations.shape(0) != translations.shape(0) || rotations.shape(1) != joints ||
            scales.shape(0) != translations.shape(0) || scales.shape(1) != joints)
          throw std::invalid_argument("sample_clip: translations, rotations and scales need the same (F, J)");
        const py::ssize_t count = frames.size();
        FloatArray out_t({count, joints, py::ssize_t(3)});
        FloatArray out_r({count, joints, py::ssize_t(4)});
        FloatArray out_s({count, joints, py::ssize_t(3)});
        Eigen::Map<Vec3fRows> mt(out_t.mutable_data(), count * joints, 3);
        Eigen::Map<Quatf4Rows> mr(out_r.mutable_data(), count * joints, 4);
        Eigen::Map<Vec3fRows> ms(out_s.mutable_data(), count * joints, 3);
        {
          py::gil_scoped_release release;
          mocapedit::SampleClip(t, r, s, static_cast<int>(joints), frames, mt, mr, ms);
        }
        return py::make_tuple(out_t, out_r, out_s);
      },
      py::arg("translations"), py::arg("rotations"), py::arg("scales"), py::arg("frames"),
      "A clip (F, J, 3/4/3 float32 translations, (x, y, z, w) rotations, scales) sampled at\n"
      "(T,) fractional frames: ((T, J, 3), (T, J, 4), (T, J, 3)) float32. Linear translations and\n"
      "scales, normalised shortest-arc slerp rotations; whole frames are copied bit for bit.");
  m.def(
      "frames_at_times",
      [](const Eigen::Ref<const Eigen::VectorXd>& time_map, const Eigen::Ref<const Eigen::VectorXd>& times) {
        py::gil_scoped_release release;
        return mocapedit::FramesAtTimes(time_map, times);
      },
      py::arg("time_map"), py::arg("times"),
      "(T,) fractional source frames playing at shot `times` under an increasing (F,) time map\n"
      "(its inverse, linear between frames, clamped to [0, F-1]).");
}
