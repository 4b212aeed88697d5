// Binding of the lexical-first MIS in rounds over a partition:
// evomesh._core.lexical_first_mis_in_rounds and evomesh._core.MisPart (one
// MPI rank's sweeps: python/evomesh/distributed/packing.py). Registered by module.cpp through bind_mis_rounds().
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstring>
#include <memory>
#include <vector>

#include "evomesh/mis_rounds.hpp"

#include "numpy_arrays.hpp"

namespace py = pybind11;
using namespace evomesh;
using namespace evomesh::bindings;

void bind_mis_rounds(py::module_& m) {
  m.def(
      "lexical_first_mis_in_rounds",
      [](const Float_array& centers, const Float_array& radii, const Int_array& order, std::size_t n_forced,
         const Int_array& part, int n_parts) {
        if (centers.ndim() != 2 || centers.shape(1) != 2) throw Input_error("centers must have shape (n, 2)");
        const auto n = static_cast<std::size_t>(centers.shape(0));
        if (radii.ndim() != 1 || order.ndim() != 1 || part.ndim() != 1 ||
            static_cast<std::size_t>(radii.shape(0)) != n || static_cast<std::size_t>(order.shape(0)) != n ||
            static_cast<std::size_t>(part.shape(0)) != n) {
          throw Input_error("radii, order and part must have one entry per centre");
        }
        std::vector<Vec2> c(n);
        if (n > 0) std::memcpy(c.data(), centers.data(), n * sizeof(Vec2));
        std::vector<double> r(radii.data(), radii.data() + n);
        std::vector<Index> o(order.data(), order.data() + n);
        std::vector<std::int32_t> p(n);
        for (std::size_t i = 0; i < n; ++i) {
          if (part.data()[i] < 0 || part.data()[i] >= n_parts) throw Input_error("part out of range");
          p[i] = static_cast<std::int32_t>(part.data()[i]);
        }
        Mis_rounds result;
        {
          py::gil_scoped_release release;
          result = lexical_first_mis_in_rounds(c, r, o, n_forced, p, n_parts);
        }
        py::dict out;
        out["kept"] = to_array(std::move(result.kept));
        out["rounds"] = result.rounds;
        out["messages"] = to_array(std::move(result.messages));
        out["undecided"] = to_array(std::move(result.undecided));
        out["halo"] = result.halo;
        return out;
      },
      py::arg("centers"), py::arg("radii"), py::arg("order"), py::arg("n_forced"), py::arg("part"),
      py::arg("n_parts"),
      "The lexical-first MIS computed in rounds by n_parts parts (simulated in one process): "
      "{'kept', 'rounds', 'messages' (per round), 'undecided' (per round), 'halo'}.");

  py::class_<Mis_part>(m, "MisPart",
                       "One rank's share of the lexical-first MIS in rounds: its own spheres and copies of the "
                       "others that can conflict with them (docs/distributed-step.md 3.4).")
      .def(py::init([](const Float_array& centers, const Float_array& radii, const Int_array& order,
                       const Byte_array& owned) {
             if (centers.ndim() != 2 || centers.shape(1) != 2) throw Input_error("centers must have shape (n, 2)");
             const auto n = static_cast<std::size_t>(centers.shape(0));
             if (radii.ndim() != 1 || order.ndim() != 1 || owned.ndim() != 1 ||
                 static_cast<std::size_t>(radii.shape(0)) != n || static_cast<std::size_t>(order.shape(0)) != n ||
                 static_cast<std::size_t>(owned.shape(0)) != n) {
               throw Input_error("radii, order and owned must have one entry per centre");
             }
             std::vector<Vec2> c(n);
             if (n > 0) std::memcpy(c.data(), centers.data(), n * sizeof(Vec2));
             std::vector<double> r(radii.data(), radii.data() + n);
             std::vector<Index> o(order.data(), order.data() + n);
             std::vector<std::uint8_t> w(owned.data(), owned.data() + n);
             py::gil_scoped_release release;
             return std::make_unique<Mis_part>(c, r, o, w);
           }),
           py::arg("centers"), py::arg("radii"), py::arg("order"), py::arg("owned"))
      .def(
          "sweep",
          [](Mis_part& part, const Byte_array& state) {
            std::vector<std::uint8_t> s(state.data(), state.data() + state.size());
            for (std::uint8_t v : s) {
              if (v > Mis_part::out) throw Input_error("states are 0 (unknown), 1 (in) or 2 (out)");
            }
            std::vector<Index> decided;
            {
              py::gil_scoped_release release;
              decided = part.sweep(s);
            }
            return py::make_tuple(to_array(std::move(s)), to_array(std::move(decided)));
          },
          py::arg("state"), "One round's sweep: (the new states, the own spheres it decided, in the order).")
      .def_property_readonly("undecided", &Mis_part::undecided);
}
