// default_thread_count() honours EVOMESH_NUM_THREADS, then OMP_NUM_THREADS, then
// the CPUs. It is read once, so each case is its own process (see CMakeLists.txt):
//   test_thread_env evomesh|omp|cpus
// A Thread_limit holds for every thread its work starts, checked in
// each case against that default (3 in the "evomesh" case: more than the limit).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <mutex>
#include <set>
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

// Under Thread_limit(limit): a Background thread and the caller run a
// parallel_for each, side by side. Every item sees the limit (on the caller,
// the pool's helpers and the Background thread), and at no time do more than
// `limit` items run.
void check_limit_reaches_every_thread(int limit) {
  std::atomic<int> running{0}, most{0};
  std::mutex mutex;
  std::set<int> limits_seen;
  auto item = [&](std::size_t) {
    const int now = ++running;
    for (int seen = most.load(); now > seen && !most.compare_exchange_weak(seen, now);) {
    }
    {
      const std::lock_guard<std::mutex> lock(mutex);
      limits_seen.insert(evomesh::resolve_threads(0));
    }
    std::this_thread::sleep_for(std::chrono::microseconds(300));
    --running;
  };
  int limit_in_background = -1;
  {
    const evomesh::Thread_limit thread_limit(limit);
    evomesh::Background background;
    background.start(
        [&] {
          limit_in_background = evomesh::resolve_threads(0);
          evomesh::parallel_for(48, 0, item);
        },
        /*on_thread=*/true);
    evomesh::parallel_for(48, 0, item);
    evomesh::parallel_for(48, limit + 2, item);  // an explicit count above the limit gets no more
    background.wait();
  }
  CHECK(limit_in_background == limit) << limit_in_background << " in the Background thread, limit " << limit;
  CHECK(limits_seen == std::set<int>{limit}) << *limits_seen.begin() << ".." << *limits_seen.rbegin();
  CHECK(most <= limit) << most << " items at once, limit " << limit;
  CHECK(evomesh::default_threads() == 0) << "the limit ends with its scope";
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
    for (int limit : {1, 2, 3}) check_limit_reaches_every_thread(limit);
  });
}
