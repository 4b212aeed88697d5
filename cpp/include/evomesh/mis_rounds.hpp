// The lexical-first MIS in rounds over a partition (the argument is
// docs/distributed-step.md, section 3.4): the serial MIS of packing.hpp
// computed by P parts that each see only their own spheres' current states and
// the others' states as of the end of the previous round, the exchange a
// distributed step makes between rounds. Here the parts run in one process
// (the rounds are simulated), which proves the rule against the serial MIS on
// any partition and measures what a distributed step would pay: rounds and
// state messages, against mesh size and part count (benchmarks/mis_rounds.py).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

namespace detail {
template <std::size_t D>
class Kept_sphere_tree;
}

struct Mis_rounds {
  std::vector<std::uint8_t> kept;       // equal to lexical_first_mis(centers, radii, order, n_forced)
  int rounds = 0;                       // rounds until every sphere was decided
  std::vector<std::int64_t> messages;   // per round: (sphere, other part) pairs told a decision
  std::vector<std::int64_t> undecided;  // per round: spheres still undecided after it
  std::int64_t halo = 0;                // (sphere, other part) pairs with a conflict across parts
};

// Each round, every part sweeps its undecided spheres in the order `order` (a
// permutation of 0..n-1; the first n_forced are kept whatever they meet): a
// sphere is rejected when an earlier sphere it conflicts with (|c1 - c2| <
// r1 + r2, as lexical_first_mis) is kept, kept when every earlier sphere it
// conflicts with is rejected, and left undecided otherwise. Its own part's
// states are read as the sweep sets them, the other parts' as the previous
// round left them. Every sphere decided gets its serial state (induction along
// the order: its earlier conflicting spheres were decided with theirs), and
// each round decides at least the earliest undecided sphere, so the rounds end.
// part[i] in [0, n_parts). Finding the conflicts visits O(n L) grid cells, L
// the number of octaves the radii span; then O(conflicts) a round. Input_error
// for bad arrays and for centres too far out for their radii (grid overflow).
Mis_rounds lexical_first_mis_in_rounds(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                                       const std::vector<Index>& order, std::size_t n_forced,
                                       const std::vector<std::int32_t>& part, int n_parts);

// One rank's share of the same rounds when the parts are MPI ranks
// (python/evomesh/distributed/packing.py does the exchanges): the rank holds its
// own spheres and copies of every other sphere that can conflict with one of
// them (its halo), `order` lists them all in the global order, and sweep()
// applies the rule of a round to its own undecided spheres, reading its own
// states as it sets them and the copies' as the last exchange left them.
// Every sphere's earlier conflicting spheres, as one flat array: sphere s's are
// list[offset[s] .. offset[s + 1]), sorted.
struct Conflict_lists {
  std::vector<std::size_t> offset;
  std::vector<Index> list;
  const Index* begin(std::size_t s) const { return list.data() + offset[s]; }
  const Index* end(std::size_t s) const { return list.data() + offset[s + 1]; }
  std::size_t size() const { return offset.empty() ? 0 : offset.size() - 1; }
};

class Mis_part {
 public:
  enum : std::uint8_t { unknown = 0, in = 1, out = 2 };
  // `owned[i]`: sphere i is this rank's to decide. Input_error as
  // lexical_first_mis_in_rounds for bad arrays.
  Mis_part(const std::vector<Vec2>& centers, const std::vector<double>& radii, const std::vector<Index>& order,
           const std::vector<std::uint8_t>& owned);
  Mis_part(Mis_part&&) noexcept;
  Mis_part& operator=(Mis_part&&) noexcept;
  ~Mis_part();
  // One round's sweep over the undecided own spheres; `state` (one per sphere:
  // unknown, in or out; forced ones in) is updated. Returns the own spheres
  // decided since the last sweep (forced ones in the first), in the order.
  std::vector<Index> sweep(std::vector<std::uint8_t>& state);
  std::size_t undecided() const { return undecided_; }

 private:
  // The sweep walks the global order and keeps, in the kd-tree of the
  // serial packing (detail/kept_sphere_tree.hpp), the spheres it has passed
  // that are in ("kept") or undecided ("pending"); a sphere is decided against
  // those, the earlier ones (no conflict lists: a candidate overlaps dozens of
  // others, and the kept ones form a packing).
  std::uint8_t decide(std::size_t position) const;
  std::unique_ptr<detail::Kept_sphere_tree<2>> tree_;
  std::vector<double> radii_;
  std::vector<std::uint8_t> owned_;
  std::vector<std::uint8_t> reported_;
  std::size_t undecided_ = 0;
};

}  // namespace evomesh
