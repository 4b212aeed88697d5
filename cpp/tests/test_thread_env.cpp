// default_thread_count() honours EVOMESH_NUM_THREADS, then OMP_NUM_THREADS, then
// the CPUs. It is read once, so each case is its own process (see CMakeLists.txt):
//   test_thread_env evomesh|omp|cpus
#include <cstdlib>
#include <string>
#include <thread>

#include "check.hpp"
#include "evomesh/parallel.hpp"

namespace {

void set(const char* name, const char* value) {
#ifdef _WIN32
  _putenv_s(name, value);
#else
  setenv(name, value, 1);
#endif
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  return evomesh_test::run([&] {
    if (mode == "evomesh") {
      set("EVOMESH_NUM_THREADS", "3");
      set("OMP_NUM_THREADS", "5");
      CHECK(evomesh::default_thread_count() == 3) << evomesh::default_thread_count();
    } else if (mode == "omp") {
      set("EVOMESH_NUM_THREADS", "three");  // invalid: ignored
      set("OMP_NUM_THREADS", "5,2");
      CHECK(evomesh::default_thread_count() == 5) << evomesh::default_thread_count();
    } else if (mode == "cpus") {
      set("EVOMESH_NUM_THREADS", "0");
      set("OMP_NUM_THREADS", "-2");
      const int count = evomesh::default_thread_count();
      const int hardware = static_cast<int>(std::thread::hardware_concurrency());
      CHECK(count >= 1 && (hardware == 0 || count <= hardware)) << count << " of " << hardware;
    } else {
      CHECK(false) << "usage: test_thread_env evomesh|omp|cpus";
      return;
    }
    // Read once: later changes do not count.
    const int first = evomesh::default_thread_count();
    set("EVOMESH_NUM_THREADS", "7");
    CHECK(evomesh::default_thread_count() == first);
    // And parallel_for(..., 0, ...) uses it without a Thread_limit.
    CHECK(evomesh::resolve_threads(0) == first);
  });
}
