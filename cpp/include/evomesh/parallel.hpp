// A minimal deterministic parallel loop: work items are fixed in advance, so the
// result never depends on how many threads run them, nor on which threads.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <memory>
#include <mutex>
#include <string>
#include <cstring>
#include <thread>
#include <type_traits>
#include <vector>
#include <utility>

namespace evomesh {

// The thread count of parallel_for(..., 0, ...) when no Thread_limit is set:
// the environment variable EVOMESH_NUM_THREADS, else OMP_NUM_THREADS (its first
// entry), else the CPUs this process may use (on Linux the smaller of its CPU
// affinity mask and its cgroup CPU quota; elsewhere hardware concurrency).
// Invalid values are ignored. At least 1; read once, on first use.
int default_thread_count();
// Its two sources, each read once: the count the environment names
// (EVOMESH_NUM_THREADS, else OMP_NUM_THREADS; 0 when neither holds a valid
// count), and the CPUs this process may use (at least 1). A caller that shares
// the CPUs with other processes divides the second, never the first (MPI ranks
// on one node: evomesh.distributed.threads).
int environment_thread_count();
int available_cpu_count();

namespace detail {

// The threads that the work of one Thread_limit scope may keep busy at once
// (units): the thread that opened the scope holds one; parallel_for takes
// helpers only from the free ones (none free: its items run on the caller),
// and a Background thread holds one while it works. A thread that waits for a
// Background thread lends its unit meanwhile. So a step with threads = k never
// has more than k threads working, whatever its stages start beside each
// other (several processes per node, each with its share of the cores).
class Thread_budget {
 public:
  explicit Thread_budget(int units) : free_(units > 1 ? static_cast<std::size_t>(units) - 1 : 0) {}
  // Takes up to `wanted` free units at once, without waiting; returns how many.
  std::size_t take_up_to(std::size_t wanted);
  // Takes one unit, waiting until one is free.
  void take_one();
  void give(std::size_t units);

 private:
  std::mutex mutex_;
  std::condition_variable freed_;
  std::size_t free_;
};

// What the calling thread works under: the thread count of parallel_for(..., 0,
// ...) (0: default_thread_count()), the budget it draws from (null: none) and
// whether it holds a unit of it. Set by Thread_limit and passed on to the
// threads that work for it (parallel_for's helpers, Background threads).
struct Thread_context {
  int limit = 0;
  Thread_budget* budget = nullptr;
  bool holds_unit = false;
};
inline Thread_context& thread_context() {
  thread_local Thread_context context;
  return context;
}

// For its lifetime, the calling thread works under `context` (holding a unit
// if it has a budget: taken here, waiting for one if need be, and given back
// at the end; or, with `unit_taken`, one its caller took for it and gives
// back). A helper's or a Background thread's share of a Thread_limit.
class Working_under {
 public:
  explicit Working_under(const Thread_context& context, bool unit_taken = false);
  ~Working_under();
  Working_under(const Working_under&) = delete;
  Working_under& operator=(const Working_under&) = delete;

 private:
  Thread_context saved_;
  bool gives_back_;
};

// While it lives, the calling thread's unit (if it holds one) is free for
// others: around a wait for another thread, which may need it to go on.
class Lent_unit {
 public:
  Lent_unit();
  ~Lent_unit();  // takes the unit back (waiting until one is free)
  Lent_unit(const Lent_unit&) = delete;
  Lent_unit& operator=(const Lent_unit&) = delete;

 private:
  bool lent_;
};

}  // namespace detail

// The thread count that parallel_for uses when asked for 0 threads, on the
// calling thread (0: default_thread_count()). Set for a scope with Thread_limit.
inline int& default_threads() { return detail::thread_context().limit; }

// Limits every parallel_for(..., 0, ...) called from this thread, for its
// lifetime, to `threads` threads (0: default_thread_count()), and everything
// it runs at once, on any thread, to that many (detail::Thread_budget).
class Thread_limit {
 public:
  explicit Thread_limit(int threads);
  ~Thread_limit();
  Thread_limit(const Thread_limit&) = delete;
  Thread_limit& operator=(const Thread_limit&) = delete;

 private:
  detail::Thread_context saved_;
  std::unique_ptr<detail::Thread_budget> budget_;
};

// The number of threads parallel_for(..., threads, ...) would use for many items.
inline int resolve_threads(int threads) {
  if (threads > 0) return threads;
  if (default_threads() > 0) return default_threads();
  return default_thread_count();
}

namespace detail {

// Parses a thread-count variable: the first entry of a comma-separated list
// (OMP_NUM_THREADS may hold one per nesting level), a positive integer that fits
// an int, surrounding blanks allowed. 0 when absent or invalid.
int parse_thread_count(const char* text);
// CPUs granted by a cgroup quota: ceil(quota / period), 0 for no limit
// (quota <= 0, as v1's -1) or nonsense.
int quota_cpus(long long quota, long long period);
// The same from the text of cgroup v2's cpu.max ("max 100000", "150000 100000").
int parse_cpu_max(const std::string& text);

// Whether the calling thread is running parallel_for work items: a nested
// parallel_for then runs inline (the outer loop already has the threads).
bool in_parallel_region();

// What the parallel regions (parallel_for calls run on more than one thread)
// of this process did, for tests that a thread limit holds: their number, the
// most threads one region ran on (the caller and every helper it got, whether
// or not a helper found an item left: independent of timing), and the most
// threads running regions' items at once, over all regions (a lower bound of
// what could run at once: it depends on timing). Counted since the last reset.
struct Parallel_counts {
  std::size_t regions = 0;
  std::size_t widest = 0;
  std::size_t peak_running = 0;
};
// The counts so far; with `reset`, they start again from zero.
Parallel_counts parallel_counts(bool reset = false);

using Item_function = void (*)(void* context, std::size_t i);
// Runs item(context, i) for i in [0, n) on the caller and up to threads - 1
// helpers (threads >= 2; as many as the caller's Thread_budget has free, all
// without one), then rethrows the first exception an item threw. Helpers come
// from a persistent pool; while another thread's loop holds the pool, or when
// the pool cannot supply that many, they are threads started for the call.
// They work under the caller's Thread_context.
void run_parallel(std::size_t n, std::size_t threads, Item_function item, void* context);

}  // namespace detail

// Calls body(i) for i in [0, n) on up to `threads` threads (0: default_threads(),
// else default_thread_count()). The first exception thrown by a body is rethrown
// in the caller. Nested calls (from inside a body) run on the calling thread.
template <class Body>
void parallel_for(std::size_t n, int threads, Body body) {
  const std::size_t t = std::min(static_cast<std::size_t>(std::max(1, resolve_threads(threads))), n);
  if (t <= 1 || detail::in_parallel_region()) {
    for (std::size_t i = 0; i < n; ++i) body(i);
    return;
  }
  detail::run_parallel(
      n, t, [](void* context, std::size_t i) { (*static_cast<Body*>(context))(i); }, &body);
}

namespace detail {

// v.resize(n, value) (elements value-initialised when no value is given), with
// the pages of the new elements' storage first touched on parallel_for's
// default threads. A plain resize touches them all on the calling thread, and
// the first touch (the page fault, not the zeroing) is what fresh memory
// costs: 1.7 us a 4 KiB page on one thread and 1.0 on two in a warm process on
// the 2-core VM measured, up to 14 us (a 513 MB resize took 1.8 s) late in a
// 1e7 step. The storage (fresh, or capacity reserved before) is zeroed as raw
// bytes before resize constructs the elements in it (trivially copyable T).
template <class T>
void parallel_resize(std::vector<T>& v, std::size_t n, const T& value = T()) {
  static_assert(std::is_trivially_copyable_v<T>, "parallel_resize: trivially copyable elements only");
  constexpr std::size_t kChunkBytes = std::size_t{1} << 21;
  if (n > v.size() && (n - v.size()) * sizeof(T) >= 2 * kChunkBytes) {
    // Fresh storage is touched whole (the elements kept are copied over it),
    // reserved capacity from the current end.
    const bool fresh_storage = n > v.capacity();
    std::vector<T> fresh;
    if (fresh_storage) fresh.reserve(n);
    unsigned char* raw = reinterpret_cast<unsigned char*>(fresh_storage ? fresh.data() : v.data());
    const std::size_t begin_byte = fresh_storage ? 0 : v.size() * sizeof(T), end_byte = n * sizeof(T);
    parallel_for((end_byte - begin_byte + kChunkBytes - 1) / kChunkBytes, 0, [&](std::size_t c) {
      const std::size_t begin = begin_byte + c * kChunkBytes;
      std::memset(raw + begin, 0, std::min(end_byte, begin + kChunkBytes) - begin);
    });
    if (fresh_storage) {
      fresh.insert(fresh.end(), v.begin(), v.end());
      v.swap(fresh);
    }
  }
  v.resize(n, value);
}

}  // namespace detail

// Work started on another thread and waited for later; the destructor waits
// too, so an exception on the main path never leaves a running thread behind.
// The thread works under its starter's Thread_limit: its parallel_for calls
// see the same limit, and it works only while it holds a unit of the
// starter's budget (it may so start late, when the budget is all in use); a
// thread waiting for it lends its own unit meanwhile.
class Background {
 public:
  template <class Work>
  void start(Work work, bool on_thread) {
    if (!on_thread) {
      work();
      return;
    }
    thread_ = std::thread([this, work, context = detail::thread_context()]() {
      try {
        const detail::Working_under working(context);
        work();
      } catch (...) {
        error_ = std::current_exception();
      }
    });
  }
  void wait() {
    join();
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }
  ~Background() { join(); }

 private:
  void join() {
    if (!thread_.joinable()) return;
    const detail::Lent_unit lent;
    thread_.join();
  }
  std::thread thread_;
  std::exception_ptr error_;
};

}  // namespace evomesh
