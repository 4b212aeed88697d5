// The incremental step (incremental_step.hpp) is chosen before any work and
// never hides a failure: frfc() takes it where incremental_applies() says so,
// with the full step's bits, and whatever it throws reaches frfc()'s caller
// (a catch-all used to rerun the full step, so a bug showed only as lost
// speed). The failure is injected: operator new is replaced for this binary and
// throws std::bad_alloc at the k-th allocation, for k spread over the step.
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include "check.hpp"
#include "evomesh/frfc.hpp"
#include "evomesh/incremental_step.hpp"
#include "evomesh/triangulation.hpp"
#include "grid_mesh.hpp"

namespace {

// Allocations left before one throws (then off again); -1: off. `counted` counts
// every allocation while armed or counting.
std::atomic<long> countdown{-1};
std::atomic<bool> counting{false};
std::atomic<long> counted{0};

void* allocate(std::size_t size) {
  if (counting.load(std::memory_order_relaxed)) counted.fetch_add(1, std::memory_order_relaxed);
  if (countdown.load(std::memory_order_relaxed) >= 0 && countdown.fetch_sub(1) == 0) throw std::bad_alloc();
  void* p = std::malloc(size == 0 ? 1 : size);
  if (p == nullptr) throw std::bad_alloc();
  return p;
}

}  // namespace

void* operator new(std::size_t size) { return allocate(size); }
void* operator new[](std::size_t size) { return allocate(size); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

using namespace evomesh;
using evomesh::testing::grid_mesh;

namespace {

double stat(const Evolve_result& result, const char* key) {
  for (const auto& entry : result.stats) {
    if (entry.first == key) return entry.second;
  }
  return std::nan("");
}

bool same_bits(const Evolve_result& a, const Evolve_result& b) {
  return a.mesh.points.size() == b.mesh.points.size() && a.mesh.triangles.size() == b.mesh.triangles.size() &&
         std::memcmp(a.mesh.points.data(), b.mesh.points.data(), a.mesh.points.size() * sizeof(Vec2)) == 0 &&
         std::memcmp(a.mesh.triangles.data(), b.mesh.triangles.data(),
                     a.mesh.triangles.size() * sizeof(Triangle)) == 0;
}

// frfc with one allocation failing at the k-th: "thrown" when bad_alloc reached
// the caller, "returned" when the step hid it, else what else came out.
const char* frfc_with_failure_at(long k, const Mesh_arrays& mesh, const std::vector<double>& delta,
                                 const Frfc_options& options) {
  const char* outcome = "returned";
  countdown.store(k);
  try {
    frfc(mesh, delta, options);
  } catch (const std::bad_alloc&) {
    outcome = "thrown";
  } catch (const std::exception&) {
    outcome = "another exception";
  }
  countdown.store(-1);
  return outcome;
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    const Mesh_arrays mesh = grid_mesh(40);
    Frfc_options options;
    options.threads = 1;  // every allocation on this thread, in one order
    // One point with delta = 1e-6 (this step once gave up late and reran the
    // full step), and a band of delta = 0.6.
    std::vector<std::vector<double>> deltas(2, std::vector<double>(mesh.points.size(), 1.0));
    deltas[0][20 * 40 + 20] = 1e-6;
    for (std::size_t i = 0; i < mesh.points.size(); ++i) {
      if (std::abs(mesh.points[i][0] - 0.5) < 0.1) deltas[1][i] = 0.6;
    }
    for (const auto& delta : deltas) {
      CHECK(incremental_applies(mesh, delta, options));
      Frfc_options full_options = options;
      full_options.incremental = false;
      const Evolve_result full = frfc(mesh, delta, full_options);
      counted.store(0);
      counting.store(true);
      const Evolve_result fast = frfc(mesh, delta, options);
      counting.store(false);
      const long n_allocations = counted.load();
      CHECK(stat(fast, "incremental_step") == 1) << stat(fast, "incremental_step");
      CHECK(stat(full, "incremental_step") == 0) << stat(full, "incremental_step");
      CHECK(same_bits(full, fast)) << "the incremental step's output differs from the full step's";
      CHECK(n_allocations > 100) << n_allocations;
      // The k-th allocation fails, k spread over the whole incremental step.
      constexpr int kTries = 12;
      for (int j = 0; j < kTries; ++j) {
        const long k = n_allocations * j / kTries;
        const char* outcome = frfc_with_failure_at(k, mesh, delta, options);
        CHECK(std::strcmp(outcome, "thrown") == 0) << "allocation " << k << " of " << n_allocations << ": " << outcome;
      }
    }
    // Called where it does not apply (delta != 1 at most points), it throws.
    const std::vector<double> everywhere(mesh.points.size(), 0.7);
    CHECK(!incremental_applies(mesh, everywhere, options));
    bool refused = false;
    try {
      incremental_frfc(mesh, everywhere, options);
    } catch (const std::invalid_argument&) {
      refused = true;
    }
    CHECK(refused);
    // A refused sample budget: the same error from both paths.
    Frfc_options small_budget = options;
    small_budget.max_samples = 50;
    std::string messages[2];
    for (const bool incremental : {false, true}) {
      small_budget.incremental = incremental;
      try {
        frfc(mesh, deltas[0], small_budget);
      } catch (const Input_error& e) {
        messages[incremental] = e.what();
      }
    }
    CHECK(!messages[0].empty() && messages[0] == messages[1]) << messages[0] << " | " << messages[1];
  });
}
