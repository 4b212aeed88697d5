// How a step runs, as opposed to what it computes (docs/distributed-step.md
// section 2.3): the threads, the memory policy, profiling and the site filter of the
// spacing function. Nothing here changes a step's output bits.
//
// Design: a separate argument of the outlines (frfc, drfc, drfc_refine,
// incremental_frfc, empty_scope_frfc), not a member of Frfc_options/Drfc_options.
// The options say what the step computes (its result is a function of the mesh,
// delta and the options); the context says how it runs, and is where an exchange
// between ranks would travel (it has none yet: docs/distributed-step.md, Open),
// which an options value bound to Python and compared field by field cannot hold. The options keep their
// `threads` field because it is a user-facing setting (evomesh.FrfcOptions):
// the caller that builds the context reads it (Step_context::from_threads, the
// bindings), the stages never do. The three-argument overloads of the
// outlines do exactly that with the other fields at their defaults.
//
// The environment is read only in the bindings (cpp/bindings/module.cpp:
// EVOMESH_STAGE_PROFILE, EVOMESH_SITE_FILTER) and in default_thread_count()
// (parallel.hpp); never inside a stage.
#pragma once

namespace evomesh {

struct Step_context {
  // Threads the step may keep busy (0: default_thread_count()). The outline
  // opens Thread_limit(threads) and its stages run their loops under it
  // (parallel_for(..., 0, ...)); a stage never reads Frfc_options::threads.
  int threads = 0;
  // Stage_timer adds each stage's peak RSS, heap in use, CPU seconds, page
  // faults and kernel time to the stats (diagnostics, Linux; step.hpp).
  bool profile = false;
  // Sites hidden by a mesh neighbour are left out of the Apollonius graph
  // (f is the same either way); false is for benchmarks only.
  bool filter_sites = true;
  // Between stages, the outline gives the free memory of every malloc arena
  // back to the system (detail::release_free_memory): what a stage freed on
  // its worker threads then does not stay resident while the next allocates.
  bool release_memory = true;

  static Step_context from_threads(int threads) {
    Step_context context;
    context.threads = threads;
    return context;
  }
};

}  // namespace evomesh
