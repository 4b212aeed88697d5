// A minimal deterministic parallel loop: work items are fixed in advance, so the
// result never depends on how many threads run them.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace evomesh {

// The thread count that parallel_for uses when asked for 0 threads, on the
// calling thread (0: hardware concurrency). Set for a scope with Thread_limit.
inline int& default_threads() {
  thread_local int threads = 0;
  return threads;
}

// Limits every parallel_for(..., 0, ...) called from this thread, for its lifetime.
class Thread_limit {
 public:
  explicit Thread_limit(int threads) : saved_(default_threads()) { default_threads() = threads; }
  ~Thread_limit() { default_threads() = saved_; }
  Thread_limit(const Thread_limit&) = delete;
  Thread_limit& operator=(const Thread_limit&) = delete;

 private:
  int saved_;
};

// Calls body(i) for i in [0, n) on up to `threads` threads (0: default_threads(),
// or hardware concurrency). The first exception thrown by a body is rethrown in
// the caller.
template <class Body>
void parallel_for(std::size_t n, int threads, Body body) {
  if (threads <= 0) threads = default_threads();
  std::size_t t = threads > 0 ? static_cast<std::size_t>(threads)
                              : std::max(1u, std::thread::hardware_concurrency());
  t = std::min(t, n);
  if (t <= 1) {
    for (std::size_t i = 0; i < n; ++i) body(i);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&]() {
    try {
      for (std::size_t i = next++; i < n; i = next++) body(i);
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next = n;
    }
  };
  std::vector<std::thread> pool;
  for (std::size_t k = 1; k < t; ++k) pool.emplace_back(worker);
  worker();
  for (auto& th : pool) th.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace evomesh
