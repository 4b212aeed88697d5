#include "evomesh/parallel.hpp"

#include <atomic>
#include <cerrno>
#include <climits>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <exception>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#if defined(__linux__)
#include <sched.h>
#endif
#if defined(__unix__) || defined(__APPLE__)
#include <pthread.h>
#endif

namespace evomesh {

namespace detail {

namespace {

bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

// A positive int in text[begin, end) (blanks around it allowed), else 0.
int parse_positive(const std::string& text) {
  std::size_t begin = 0, end = text.size();
  while (begin < end && is_blank(text[begin])) ++begin;
  while (end > begin && is_blank(text[end - 1])) --end;
  if (begin == end) return 0;
  long long value = 0;
  for (std::size_t k = begin; k < end; ++k) {
    if (text[k] < '0' || text[k] > '9') return 0;
    value = 10 * value + (text[k] - '0');
    if (value > INT_MAX) return 0;
  }
  return static_cast<int>(value);
}

}  // namespace

int parse_thread_count(const char* text) {
  if (text == nullptr) return 0;
  std::string value(text);
  const std::size_t comma = value.find(',');
  if (comma != std::string::npos) value.resize(comma);
  return parse_positive(value);
}

int quota_cpus(long long quota, long long period) {
  if (quota <= 0 || period <= 0) return 0;
  const long long cpus = quota / period + (quota % period != 0);
  return cpus > INT_MAX ? INT_MAX : static_cast<int>(cpus);
}

int parse_cpu_max(const std::string& text) {
  std::istringstream in(text);
  long long quota = 0, period = 0;
  if (!(in >> quota >> period)) return 0;  // also "max ...": no limit
  return quota_cpus(quota, period);
}

}  // namespace detail

namespace {

#if defined(__linux__)

// CPUs in this process's affinity mask (0: unknown). The mask may be larger than
// cpu_set_t on machines with more than 1024 CPUs, hence the growing buffer.
int affinity_cpus() {
  for (int n_cpus = 1024; n_cpus <= (1 << 20); n_cpus *= 2) {
    cpu_set_t* set = CPU_ALLOC(n_cpus);
    if (set == nullptr) return 0;
    const std::size_t size = CPU_ALLOC_SIZE(n_cpus);
    CPU_ZERO_S(size, set);
    const int status = sched_getaffinity(0, size, set);
    const int error = errno;
    const int count = status == 0 ? CPU_COUNT_S(size, set) : 0;
    CPU_FREE(set);
    if (status == 0) return count;
    if (error != EINVAL) return 0;
  }
  return 0;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  if (in) text << in.rdbuf();
  return text.str();
}

// The cgroup directories whose quota applies: `path` (this process's cgroup
// under `mount`) and its ancestors up to the mount point itself. Without a
// cgroup namespace the path names the host's hierarchy and may not exist under
// the container's mount; the mount point is then the container's own cgroup.
std::vector<std::string> cgroup_dirs(const std::string& mount, std::string path) {
  std::vector<std::string> dirs;
  while (!path.empty() && path[0] == '/' && path != "/") {
    dirs.push_back(mount + path);
    path.resize(path.rfind('/'));
  }
  dirs.push_back(mount);
  return dirs;
}

// The smallest CPU quota among the cgroups of this process, v2 (cpu.max) or v1
// (cpu.cfs_quota_us / cpu.cfs_period_us); 0 when none is set.
int cgroup_cpus() {
  int best = 0;
  auto take = [&best](int cpus) {
    if (cpus > 0 && (best == 0 || cpus < best)) best = cpus;
  };
  std::istringstream lines(read_file("/proc/self/cgroup"));
  std::string v2_path, v1_path;
  for (std::string line; std::getline(lines, line);) {
    // "hierarchy-id:controller,list:path"; v2's line is "0::path".
    const std::size_t a = line.find(':');
    const std::size_t b = a == std::string::npos ? a : line.find(':', a + 1);
    if (b == std::string::npos) continue;
    const std::string controllers = "," + line.substr(a + 1, b - a - 1) + ",";
    if (line.compare(0, a, "0") == 0 && controllers == ",,") v2_path = line.substr(b + 1);
    if (controllers.find(",cpu,") != std::string::npos) v1_path = line.substr(b + 1);
  }
  for (const auto& dir : cgroup_dirs("/sys/fs/cgroup", v2_path)) {
    take(detail::parse_cpu_max(read_file(dir + "/cpu.max")));
  }
  for (const char* mount : {"/sys/fs/cgroup/cpu", "/sys/fs/cgroup/cpu,cpuacct", "/sys/fs/cgroup/cpuacct,cpu"}) {
    for (const auto& dir : cgroup_dirs(mount, v1_path)) {
      long long quota = 0, period = 0;
      std::istringstream q(read_file(dir + "/cpu.cfs_quota_us")), p(read_file(dir + "/cpu.cfs_period_us"));
      if (q >> quota && p >> period) take(detail::quota_cpus(quota, period));
    }
  }
  return best;
}

#endif

int compute_environment_thread_count() {
  if (const int n = detail::parse_thread_count(std::getenv("EVOMESH_NUM_THREADS"))) return n;
  return detail::parse_thread_count(std::getenv("OMP_NUM_THREADS"));
}

int compute_available_cpu_count() {
  int cpus = static_cast<int>(std::thread::hardware_concurrency());
#if defined(__linux__)
  if (const int affinity = affinity_cpus()) cpus = affinity;
  if (const int quota = cgroup_cpus()) cpus = cpus > 0 ? std::min(cpus, quota) : quota;
#endif
  return std::max(cpus, 1);
}

// ---- Counts of the parallel regions (detail::parallel_counts) ----

std::atomic<std::size_t> g_regions{0}, g_widest{0}, g_running{0}, g_peak_running{0};

void raise_to(std::atomic<std::size_t>& maximum, std::size_t value) {
  std::size_t seen = maximum.load(std::memory_order_relaxed);
  while (seen < value && !maximum.compare_exchange_weak(seen, value, std::memory_order_relaxed)) {
  }
}

// ---- The pool ----

thread_local bool t_in_region = false;

// Marks the calling thread as running work items for its lifetime.
class Region_guard {
 public:
  Region_guard() : saved_(t_in_region) { t_in_region = true; }
  ~Region_guard() { t_in_region = saved_; }
  Region_guard(const Region_guard&) = delete;
  Region_guard& operator=(const Region_guard&) = delete;

 private:
  bool saved_;
};

// One parallel_for call: threads take the next item until none is left, all
// under the caller's Thread_context (the caller took the helpers' units).
struct Job {
  Job(std::size_t n_items, detail::Item_function function, void* data)
      : n(n_items), item(function), context(data), caller(detail::thread_context()) {}
  std::size_t n;
  detail::Item_function item;
  void* context;
  detail::Thread_context caller;
  std::atomic<std::size_t> next{0};
  std::atomic<std::size_t> entered{0};  // threads that ran run(), the caller included
  std::mutex error_mutex;
  std::exception_ptr error;

  void run() noexcept {
    const Region_guard guard;
    entered.fetch_add(1, std::memory_order_relaxed);
    raise_to(g_peak_running, g_running.fetch_add(1, std::memory_order_relaxed) + 1);
    struct Leave {
      ~Leave() { g_running.fetch_sub(1, std::memory_order_relaxed); }
    } leave;
    try {
      const detail::Working_under working(caller, /*unit_taken=*/true);
      for (std::size_t i = next++; i < n; i = next++) item(context, i);
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next = n;
    }
  }
};

// Persistent workers, started on demand and kept until the process exits. One
// caller at a time holds the pool (busy_); helpers 0 .. k-1 run its job.
class Pool {
 public:
  // More helpers than this are threads started for the call.
  static constexpr std::size_t kMaxWorkers = 256;

  // Runs `job` on the caller and up to `helpers` workers; false (nothing run)
  // when another caller holds the pool.
  bool try_run(Job& job, std::size_t helpers) {
    std::unique_lock<std::mutex> busy(busy_, std::try_to_lock);
    if (!busy.owns_lock()) return false;
    // Only the holder of busy_ writes generation_, so reading it here is safe.
    while (workers_.size() < helpers) {
      try {
        wakes_.emplace_back();
        workers_.emplace_back(&Pool::work, this, workers_.size(), generation_, &wakes_.back());
      } catch (...) {
        if (wakes_.size() > workers_.size()) wakes_.pop_back();
        break;  // no more threads to be had: run with those there are
      }
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      job_ = &job;
      helpers_ = std::min(helpers, workers_.size());
      finished_ = 0;
      ++generation_;
    }
    // Only the helpers wake: the other workers sleep on (a step with threads = k
    // keeps its other workers, from an earlier call with more threads, idle).
    for (std::size_t k = 0; k < helpers_; ++k) wakes_[k].notify_one();
    job.run();
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, [this] { return finished_ == helpers_; });
    job_ = nullptr;
    return true;
  }

 private:
  // A helper of generation g is counted in finished_ before generation g + 1
  // can start, so no helper misses the job it is part of.
  // A worker not among a generation's helpers skips it (is not woken).
  void work(std::size_t id, std::uint64_t seen, std::condition_variable* wake) {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      wake->wait(lock, [&] { return generation_ != seen && id < helpers_; });
      seen = generation_;
      Job* job = job_;
      lock.unlock();
      job->run();
      lock.lock();
      if (++finished_ == helpers_) done_.notify_one();
    }
  }

  std::mutex busy_;
  std::mutex mutex_;  // guards the fields below
  std::condition_variable done_;
  std::uint64_t generation_ = 0;
  Job* job_ = nullptr;
  std::size_t helpers_ = 0, finished_ = 0;
  std::vector<std::thread> workers_;  // touched only by the holder of busy_
  std::deque<std::condition_variable> wakes_;  // one a worker (stable addresses), as workers_
};

// Never destroyed: workers blocked in a wait are simply ended with the process
// (joining them from a static destructor could hang at exit or in a DLL unload).
std::atomic<Pool*> g_pool{nullptr};

#if defined(__unix__) || defined(__APPLE__)
// A forked child has none of the parent's workers (and maybe a pool held by a
// thread that does not exist there): it starts a fresh pool, leaking the old one.
void forget_pool_in_child() { g_pool.store(nullptr); }
#endif

Pool& pool() {
  Pool* current = g_pool.load(std::memory_order_acquire);
  if (current != nullptr) return *current;
#if defined(__unix__) || defined(__APPLE__)
  static const bool registered = (pthread_atfork(nullptr, nullptr, forget_pool_in_child), true);
  (void)registered;
#endif
  Pool* fresh = new Pool;  // no threads yet, so losing the race below costs nothing
  if (g_pool.compare_exchange_strong(current, fresh, std::memory_order_acq_rel)) return *fresh;
  delete fresh;
  return *current;
}

}  // namespace

int environment_thread_count() {
  static const int count = compute_environment_thread_count();
  return count;
}

int available_cpu_count() {
  static const int count = compute_available_cpu_count();
  return count;
}

int default_thread_count() {
  const int named = environment_thread_count();
  return named > 0 ? named : available_cpu_count();
}

namespace detail {

bool in_parallel_region() { return t_in_region; }

Parallel_counts parallel_counts(bool reset) {
  Parallel_counts counts;
  counts.regions = reset ? g_regions.exchange(0) : g_regions.load();
  counts.widest = reset ? g_widest.exchange(0) : g_widest.load();
  counts.peak_running = reset ? g_peak_running.exchange(0) : g_peak_running.load();
  return counts;
}

std::size_t Thread_budget::take_up_to(std::size_t wanted) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::size_t taken = std::min(wanted, free_);
  free_ -= taken;
  return taken;
}

void Thread_budget::take_one() {
  std::unique_lock<std::mutex> lock(mutex_);
  freed_.wait(lock, [this] { return free_ > 0; });
  --free_;
}

void Thread_budget::give(std::size_t units) {
  if (units == 0) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    free_ += units;
  }
  freed_.notify_all();
}

Working_under::Working_under(const Thread_context& context, bool unit_taken)
    : saved_(thread_context()), gives_back_(context.budget != nullptr && !unit_taken) {
  if (gives_back_) context.budget->take_one();
  thread_context() = {context.limit, context.budget, context.budget != nullptr};
}

Working_under::~Working_under() {
  Thread_context& current = thread_context();
  if (gives_back_) current.budget->give(1);
  current = saved_;
}

Lent_unit::Lent_unit() : lent_(thread_context().budget != nullptr && thread_context().holds_unit) {
  if (!lent_) return;
  thread_context().holds_unit = false;
  thread_context().budget->give(1);
}

Lent_unit::~Lent_unit() {
  if (!lent_) return;
  thread_context().budget->take_one();
  thread_context().holds_unit = true;
}

void run_parallel(std::size_t n, std::size_t threads, Item_function item, void* context) {
  Job job(n, item, context);
  // The helpers' units, given back once they are done (as many as are free).
  Thread_budget* const budget = job.caller.budget;
  const std::size_t helpers = budget ? budget->take_up_to(threads - 1) : threads - 1;
  struct Give_back {
    Thread_budget* budget;
    std::size_t units;
    ~Give_back() {
      if (budget) budget->give(units);
    }
  } give_back{budget, helpers};
  if (helpers == 0) {
    job.run();
  } else if (helpers > Pool::kMaxWorkers || !pool().try_run(job, helpers)) {
    std::vector<std::thread> extra;
    try {
      for (std::size_t k = 0; k < helpers; ++k) extra.emplace_back([&job] { job.run(); });
    } catch (...) {
      // No more threads to be had: the items still all run, on those there are.
    }
    job.run();
    for (auto& thread : extra) thread.join();
  }
  if (job.entered > 1) {
    g_regions.fetch_add(1, std::memory_order_relaxed);
    raise_to(g_widest, job.entered);
  }
  if (job.error) std::rethrow_exception(job.error);
}

}  // namespace detail

Thread_limit::Thread_limit(int threads) : saved_(detail::thread_context()) {
  detail::Thread_context& context = detail::thread_context();
  context.limit = threads;
  budget_ = std::make_unique<detail::Thread_budget>(resolve_threads(threads));
  context.budget = budget_.get();
  context.holds_unit = true;
}

Thread_limit::~Thread_limit() { detail::thread_context() = saved_; }

}  // namespace evomesh
