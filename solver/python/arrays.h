// numpy arrays as the job bindings take them: C-contiguous, converted when they are not, and
// viewed as the jobs' Spans.
#pragma once

#include <pybind11/numpy.h>

#include <cstddef>
#include <cstdint>

#include "mocapedit/layering.h"  // Span

namespace mocapedit::python {

using DoubleArray = pybind11::array_t<double, pybind11::array::c_style | pybind11::array::forcecast>;
using IndexArray = pybind11::array_t<std::int64_t, pybind11::array::c_style | pybind11::array::forcecast>;

inline Span<const double> View(const DoubleArray& a) {
  return Span<const double>(a.data(), static_cast<std::size_t>(a.size()));
}
inline Span<double> View(DoubleArray& a) { return Span<double>(a.mutable_data(), static_cast<std::size_t>(a.size())); }

}  // namespace mocapedit::python
