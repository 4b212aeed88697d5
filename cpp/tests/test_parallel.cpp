// parallel_for: the same results on 1..4 threads, from concurrent callers and
// nested calls; exceptions reach the caller; the pool survives fork(); the
// parsing behind default_thread_count(); and detail::parallel_resize.
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <stdexcept>
#include <thread>
#include <vector>

#if defined(__unix__) || defined(__APPLE__)
#include <sys/wait.h>
#include <unistd.h>
#define EVOMESH_TEST_FORK 1
#endif

#include "check.hpp"
#include "evomesh/parallel.hpp"

using namespace evomesh;

namespace {

// Items of uneven cost, each writing its own outputs.
std::vector<double> compute(std::size_t n, int threads, std::uint64_t seed) {
  std::vector<double> out(n);
  parallel_for(n, threads, [&](std::size_t i) {
    double x = static_cast<double>((seed * 2654435761u + i) % 1000) / 1000.0;
    for (std::size_t k = 0; k < 50 + (i * 7919) % 400; ++k) x = std::sin(x + 0.5) * 1.0001;
    out[i] = x;
  });
  return out;
}

void check_thread_counts() {
  for (const std::size_t n : {0, 1, 2, 3, 7, 64, 1000}) {
    const std::vector<double> reference = compute(n, 1, n);
    for (int threads = 0; threads <= 4; ++threads) {
      CHECK(compute(n, threads, n) == reference) << "n " << n << ", threads " << threads;
    }
  }
  // Every item exactly once.
  std::vector<std::atomic<int>> hits(10000);
  parallel_for(hits.size(), 4, [&](std::size_t i) { ++hits[i]; });
  std::size_t wrong = 0;
  for (auto& h : hits) wrong += h != 1;
  CHECK(wrong == 0) << wrong << " items not run exactly once";
}

void check_concurrent_callers() {
  const std::vector<double> reference = compute(2000, 1, 7);
  std::atomic<int> mismatches{0};
  std::vector<std::thread> callers;
  for (int c = 0; c < 4; ++c) {
    callers.emplace_back([&, c] {
      for (int round = 0; round < 25; ++round) {
        if (compute(2000, 1 + (c + round) % 4, 7) != reference) ++mismatches;
      }
    });
  }
  for (auto& t : callers) t.join();
  CHECK(mismatches == 0) << mismatches << " concurrent runs differ";
}

void check_nested() {
  // Nested loops run inline in the worker: no deadlock, same result.
  std::vector<double> nested(40 * 50);
  std::atomic<int> outside{0};
  parallel_for(40, 3, [&](std::size_t i) {
    if (!detail::in_parallel_region()) ++outside;
    parallel_for(50, 3, [&](std::size_t j) { nested[50 * i + j] = std::sqrt(static_cast<double>(50 * i + j)); });
  });
  std::size_t wrong = 0;
  for (std::size_t k = 0; k < nested.size(); ++k) wrong += nested[k] != std::sqrt(static_cast<double>(k));
  CHECK(wrong == 0) << wrong << " wrong nested results";
  CHECK(outside == 0) << outside << " items not marked as in a parallel region";
  CHECK(!detail::in_parallel_region()) << "the caller's flag is restored";

  // A thread started from inside a work item is a caller of its own (it may
  // find the pool busy and start threads).
  std::vector<double> inner;
  parallel_for(2, 2, [&](std::size_t i) {
    if (i != 0) return;
    std::thread t([&] { inner = compute(300, 2, 3); });
    t.join();
  });
  CHECK(inner == compute(300, 1, 3)) << "a loop from a thread started inside a work item";
}

void check_exceptions() {
  for (const int threads : {1, 2, 4}) {
    std::atomic<int> ran{0};
    bool caught = false;
    try {
      parallel_for(1000, threads, [&](std::size_t i) {
        ++ran;
        if (i == 500) throw std::runtime_error("item 500");
      });
    } catch (const std::runtime_error& e) {
      caught = std::string(e.what()) == "item 500";
    }
    CHECK(caught) << "threads " << threads;
    CHECK(ran <= 1000);
    // The pool is usable afterwards.
    CHECK(compute(500, threads, 1) == compute(500, 1, 1)) << "after an exception, threads " << threads;
  }
  // A nested exception passes through the outer loop.
  bool caught = false;
  try {
    parallel_for(8, 2, [&](std::size_t) { parallel_for(8, 2, [&](std::size_t j) {
                                            if (j == 3) throw std::logic_error("inner");
                                          }); });
  } catch (const std::logic_error&) {
    caught = true;
  }
  CHECK(caught) << "nested exception";
}

void check_thread_limit() {
  CHECK(default_thread_count() >= 1);
  CHECK(resolve_threads(0) == default_thread_count());
  {
    const Thread_limit limit(3);
    CHECK(resolve_threads(0) == 3);
    CHECK(resolve_threads(5) == 5);
    int other = -1;
    std::thread t([&] { other = resolve_threads(0); });  // per thread
    t.join();
    CHECK(other == default_thread_count());
  }
  CHECK(resolve_threads(0) == default_thread_count());
}

void check_parsing() {
  using detail::parse_thread_count;
  CHECK(parse_thread_count(nullptr) == 0);
  CHECK(parse_thread_count("") == 0);
  CHECK(parse_thread_count("4") == 4);
  CHECK(parse_thread_count(" 12 ") == 12);
  CHECK(parse_thread_count("8,4,2") == 8);
  CHECK(parse_thread_count("0") == 0);
  CHECK(parse_thread_count("-3") == 0);
  CHECK(parse_thread_count("3x") == 0);
  CHECK(parse_thread_count("2.5") == 0);
  CHECK(parse_thread_count("abc") == 0);
  CHECK(parse_thread_count(",4") == 0);
  CHECK(parse_thread_count("99999999999999999999") == 0);
  CHECK(parse_thread_count("2147483647") == 2147483647);

  using detail::parse_cpu_max;
  CHECK(parse_cpu_max("max 100000\n") == 0);
  CHECK(parse_cpu_max("200000 100000\n") == 2);
  CHECK(parse_cpu_max("150000 100000") == 2);  // a fractional quota rounds up
  CHECK(parse_cpu_max("50000 100000") == 1);
  CHECK(parse_cpu_max("") == 0);
  CHECK(parse_cpu_max("garbage") == 0);
  CHECK(detail::quota_cpus(-1, 100000) == 0);  // cgroup v1: no limit
  CHECK(detail::quota_cpus(400000, 100000) == 4);
  CHECK(detail::quota_cpus(100000, 0) == 0);
}

void check_fork() {
#ifdef EVOMESH_TEST_FORK
  // The pool has workers now; the child has none and must not wait for them.
  CHECK(compute(1000, 2, 5) == compute(1000, 1, 5));
  std::fflush(nullptr);
  const pid_t child = fork();
  if (child == 0) {
    alarm(20);  // a hang becomes a failure
    const bool same = compute(1000, 3, 5) == compute(1000, 1, 5);
    _exit(same ? 0 : 1);
  }
  CHECK(child > 0) << "fork failed";
  if (child > 0) {
    int status = 0;
    waitpid(child, &status, 0);
    CHECK(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "parallel_for in a forked child, status " << status;
  }
#endif
}

}  // namespace

// parallel_resize against resize: from empty, with contents kept, within
// reserved capacity, with a fill value, small (no parallel touch) and large
// (touched in parallel), on 1 and 2 threads, also from inside a work item.
void check_parallel_resize() {
  struct Item {
    std::int64_t a;
    double b;
    std::uint8_t c;
  };
  for (int threads : {1, 2}) {
    const Thread_limit limit(threads);
    for (std::size_t n : {std::size_t{0}, std::size_t{1000}, std::size_t{3} << 20}) {
      for (std::size_t kept : {std::size_t{0}, std::size_t{777}}) {
        for (bool reserved : {false, true}) {
          std::vector<std::int64_t> ours(kept), reference(kept);
          for (std::size_t i = 0; i < kept; ++i) ours[i] = reference[i] = static_cast<std::int64_t>(i * 7 + 1);
          if (reserved) ours.reserve(n + 5);
          const std::int64_t* before = ours.data();
          detail::parallel_resize(ours, std::max(n, kept), std::int64_t{-3});
          reference.resize(std::max(n, kept), -3);
          CHECK(ours == reference) << "int64, n " << n << ", kept " << kept << ", reserved " << reserved;
          if (reserved && n > 0) CHECK(ours.data() == before) << "reserved capacity reused, n " << n;
        }
      }
      std::vector<Item> items;
      detail::parallel_resize(items, n);
      bool zero = true;
      for (const Item& item : items) zero = zero && item.a == 0 && item.b == 0.0 && item.c == 0;
      CHECK(items.size() == n && zero) << "value-initialised items, n " << n;
    }
    // shrinking and equal sizes behave as resize
    std::vector<double> v(5000, 2.0);
    detail::parallel_resize(v, 10);
    CHECK(v.size() == 10 && v[9] == 2.0);
    // from inside a work item (the touch runs on the calling thread)
    std::vector<std::vector<std::uint32_t>> nested(2);
    parallel_for(2, threads, [&](std::size_t i) { detail::parallel_resize(nested[i], std::size_t{1} << 21, 5u); });
    CHECK(nested[0] == std::vector<std::uint32_t>(std::size_t{1} << 21, 5u) && nested[1] == nested[0])
        << "parallel_resize inside a work item";
  }
}

int main() {
  return evomesh_test::run([] {
    const auto t0 = std::chrono::steady_clock::now();
    check_parsing();
    check_thread_limit();
    check_thread_counts();
    check_concurrent_callers();
    check_nested();
    check_exceptions();
    check_fork();
    check_parallel_resize();
    std::printf("default_thread_count() = %d, %.3f s\n", default_thread_count(),
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  });
}
