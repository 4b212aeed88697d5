// numpy arrays in and out of the bindings: one home for the array types the
// binding files accept and for handing a result vector to numpy without a copy.
// Only cpp/bindings includes this (the core never sees pybind11).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <utility>
#include <vector>

namespace evomesh::bindings {

namespace py = pybind11;

using Float_array = py::array_t<double, py::array::c_style | py::array::forcecast>;
using Int_array = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;
using Byte_array = py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>;

// The vector's buffer as an array of the given shape (default: its length),
// without copying: the array owns the vector (moved to the heap).
template <class T>
py::array_t<T> to_array(std::vector<T>&& v, std::vector<py::ssize_t> shape = {}) {
  if (shape.empty()) shape = {static_cast<py::ssize_t>(v.size())};
  auto* holder = new std::vector<T>(std::move(v));
  py::capsule owner(holder, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, holder->data(), owner);
}

}  // namespace evomesh::bindings
