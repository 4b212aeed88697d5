// Binding of the thread limit for callers that run several core calls as one
// step from Python (python/evomesh/distributed/threads.py: a step on MPI
// ranks): evomesh._core.ThreadLimit, the two sources of the default thread
// count, and the parallel regions' counts for tests. Registered by module.cpp
// through bind_threads().
#include <pybind11/pybind11.h>

#include <optional>
#include <stdexcept>
#include <thread>

#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace py = pybind11;
using namespace evomesh;

namespace {

// A Thread_limit held from __enter__ to __exit__ on the calling thread: every
// core call made from that thread meanwhile (they run on it with the GIL
// released) runs its parallel loops under it, as a serial step's stages run
// under the one its outline opens. Limits nest, the inner one in force.
class Thread_limit_scope {
 public:
  explicit Thread_limit_scope(int threads) : threads_(threads) {
    if (threads < 0) throw Input_error("threads must be 0 (the default count) or a positive integer");
  }

  void enter() {
    if (limit_) throw std::logic_error("ThreadLimit: entered twice");
    limit_.emplace(threads_);
    owner_ = std::this_thread::get_id();
    budget_ = detail::thread_context().budget;
  }

  // The limit before __enter__ is back in force. Leaving on another thread, or
  // while a limit entered later is still open, would put the wrong one back.
  void exit() {
    if (!limit_) throw std::logic_error("ThreadLimit: left without being entered");
    if (owner_ != std::this_thread::get_id() || detail::thread_context().budget != budget_) {
      throw std::logic_error("ThreadLimit: left on another thread or before a limit entered after it");
    }
    limit_.reset();
  }

  int threads() const { return threads_; }

 private:
  int threads_;
  std::optional<Thread_limit> limit_;
  std::thread::id owner_;
  const detail::Thread_budget* budget_ = nullptr;
};

}  // namespace

void bind_threads(py::module_& m) {
  py::class_<Thread_limit_scope>(m, "ThreadLimit")
      .def(py::init<int>(), py::arg("threads"))
      .def_property_readonly("threads", &Thread_limit_scope::threads)
      .def("__enter__", [](Thread_limit_scope& self) -> Thread_limit_scope& {
            self.enter();
            return self;
          }, py::return_value_policy::reference)
      .def("__exit__", [](Thread_limit_scope& self, py::args) { self.exit(); })
      .doc() = "A context manager: core calls from this thread, while it is open, keep at most `threads` "
               "threads working at once (0: default_thread_count()). Results do not depend on it.";
  m.def("environment_thread_count", &environment_thread_count,
        "The thread count EVOMESH_NUM_THREADS names, else OMP_NUM_THREADS (its first entry); 0 when neither "
        "holds a positive integer. Read once.");
  m.def("available_cpu_count", &available_cpu_count,
        "The CPUs this process may use: on Linux the smaller of its CPU affinity mask and its cgroup CPU "
        "quota, elsewhere hardware concurrency. At least 1. Read once.");
  m.def(
      "_parallel_counts",
      [](bool reset) {
        const detail::Parallel_counts counts = detail::parallel_counts(reset);
        py::dict out;
        out["regions"] = counts.regions;
        out["widest"] = counts.widest;
        out["peak_running"] = counts.peak_running;
        return out;
      },
      py::arg("reset") = false,
      "For tests: the parallel loops run on more than one thread in this process ('regions'), the most "
      "threads one ran on ('widest': caller and helpers, independent of timing) and the most running "
      "loops' items at once ('peak_running', timing-dependent), since the last reset (reset=True: "
      "return them and start again from zero).");
}
