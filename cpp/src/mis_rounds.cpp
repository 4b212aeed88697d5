#include "evomesh/mis_rounds.hpp"

#include "evomesh/detail/kept_sphere_tree.hpp"
#include "evomesh/detail/sphere_conflict.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <stdexcept>
#include <unordered_map>
#include <utility>

namespace evomesh {

namespace {

// The cell of coordinate x in a grid of side `side`; Input_error when it
// leaves the 62-bit range (a centre too far out for its spheres' sizes).
std::int64_t cell_of(double x, double side) {
  const double c = std::floor(x / side);
  if (!(std::abs(c) < 4.0e18)) {
    throw Input_error("lexical_first_mis_in_rounds: a centre lies too far out for the spheres' radii");
  }
  return static_cast<std::int64_t>(c);
}

// Every sphere's earlier conflicting spheres (in `rank` order). The spheres go
// to one uniform grid per octave of radius (cell side twice the octave's
// largest radius R). A pair is found from its smaller sphere, which queries
// its own octave and the larger ones only: there its reach r + R is at most
// 2R, one cell, so every query visits at most 3 x 3 cells per octave (a pair
// within one octave is found from both ends and kept from the lower index).
// O(n L) cell visits for L octaves, plus the pairs met.
Conflict_lists earlier_conflicts(const std::vector<Vec2>& c, const std::vector<double>& r,
                                 const std::vector<std::size_t>& rank) {
  const std::size_t n = c.size();
  std::map<int, std::vector<Index>> by_octave;  // (ordered: the octaves at or above a sphere's)
  for (std::size_t i = 0; i < n; ++i) by_octave[std::ilogb(r[i])].push_back(static_cast<Index>(i));
  // One grid per octave, its members laid out cell by cell (one flat array; a
  // hash map gives a cell's range), so a query reads contiguous memory.
  struct Grid {
    int octave;
    double side;
    double reach;  // the octave's largest radius
    std::unordered_map<std::uint64_t, std::uint32_t> cell;  // key -> cell number
    std::vector<std::uint32_t> start;                        // cell number -> first member
    std::vector<Index> members;
  };
  auto key = [](std::int64_t ix, std::int64_t iy) {
    return (static_cast<std::uint64_t>(ix) << 32) ^ static_cast<std::uint64_t>(iy & 0xffffffff);
  };
  std::vector<Grid> grids;  // by increasing octave
  grids.reserve(by_octave.size());
  for (auto& [octave, members] : by_octave) {
    Grid g;
    g.octave = octave;
    g.reach = 0;
    for (Index i : members) g.reach = std::max(g.reach, r[i]);
    g.side = 2 * g.reach;
    std::vector<std::pair<std::uint64_t, Index>> keyed(members.size());
    for (std::size_t k = 0; k < members.size(); ++k) {
      const Index i = members[k];
      keyed[k] = {key(cell_of(c[i][0], g.side), cell_of(c[i][1], g.side)), i};
    }
    std::sort(keyed.begin(), keyed.end());
    g.members.resize(keyed.size());
    for (std::size_t k = 0; k < keyed.size(); ++k) {
      g.members[k] = keyed[k].second;
      if (k == 0 || keyed[k].first != keyed[k - 1].first) {
        g.cell.emplace(keyed[k].first, static_cast<std::uint32_t>(g.start.size()));
        g.start.push_back(static_cast<std::uint32_t>(k));
      }
    }
    g.start.push_back(static_cast<std::uint32_t>(keyed.size()));
    grids.push_back(std::move(g));
  }
  // The pairs (later sphere, earlier sphere), then counted into lists.
  std::vector<std::pair<Index, Index>> pairs;
  pairs.reserve(8 * n);
  for (std::size_t s = 0; s < n; ++s) {
    const int own = std::ilogb(r[s]);
    for (const Grid& g : grids) {
      if (g.octave < own) continue;
      const double reach = r[s] + g.reach;
      const std::int64_t x0 = cell_of(c[s][0] - reach, g.side), x1 = cell_of(c[s][0] + reach, g.side);
      const std::int64_t y0 = cell_of(c[s][1] - reach, g.side), y1 = cell_of(c[s][1] + reach, g.side);
      for (std::int64_t ix = x0; ix <= x1; ++ix) {
        for (std::int64_t iy = y0; iy <= y1; ++iy) {
          const auto it = g.cell.find(key(ix, iy));
          if (it == g.cell.end()) continue;
          for (std::uint32_t m = g.start[it->second]; m < g.start[it->second + 1]; ++m) {
            const Index t = g.members[m];
            if (static_cast<std::size_t>(t) == s || (g.octave == own && static_cast<std::size_t>(t) < s)) continue;
            // (packing.cpp's leaf_conflicts, operation for operation: symmetric in s and t)
            const double ex = c[t][0] - c[s][0], ey = c[t][1] - c[s][1], sum = r[s] + r[t];
            if (!detail::spheres_conflict(ex, ey, sum)) continue;
            if (rank[t] < rank[s]) pairs.emplace_back(static_cast<Index>(s), t);
            else pairs.emplace_back(t, static_cast<Index>(s));
          }
        }
      }
    }
  }
  // (two cells of one grid can share a key: a pair met twice is listed twice, harmlessly for the rule)
  Conflict_lists out;
  out.offset.assign(n + 1, 0);
  for (const auto& [later, earlier] : pairs) ++out.offset[static_cast<std::size_t>(later) + 1];
  for (std::size_t s = 0; s < n; ++s) out.offset[s + 1] += out.offset[s];
  out.list.resize(pairs.size());
  std::vector<std::size_t> fill(out.offset.begin(), out.offset.end() - 1);
  for (const auto& [later, earlier] : pairs) out.list[fill[static_cast<std::size_t>(later)]++] = earlier;
  pairs = {};
  // Each list sorted, repeats removed, compacted in place.
  std::size_t write = 0;
  for (std::size_t s = 0; s < n; ++s) {
    const auto first = out.list.begin() + static_cast<std::ptrdiff_t>(out.offset[s]);
    const auto last = out.list.begin() + static_cast<std::ptrdiff_t>(out.offset[s + 1]);
    std::sort(first, last);
    const auto unique_end = std::unique(first, last);
    out.offset[s] = write;
    for (auto it = first; it != unique_end; ++it) out.list[write++] = *it;
  }
  out.offset[n] = write;
  out.list.resize(write);
  return out;
}

// The rule of a round for one sphere, given its earlier conflicting spheres
// and the states it may read: out if one of them is in, in if all are out,
// else undecided (unknown).
template <class State_of>
std::uint8_t decide(const Conflict_lists& lists, std::size_t s, State_of state_of) {
  bool all_out = true;
  for (const Index* it = lists.begin(s); it != lists.end(s); ++it) {
    const Index t = *it;
    const std::uint8_t v = state_of(t);
    if (v == Mis_part::in) return Mis_part::out;
    if (v != Mis_part::out) all_out = false;
  }
  return all_out ? Mis_part::in : Mis_part::unknown;
}

// The ranks of the spheres in `order`, checked to be a permutation.
std::vector<std::size_t> ranks_of(const std::vector<Index>& order, const char* what) {
  const std::size_t n = order.size();
  std::vector<std::size_t> rank(n, n);
  for (std::size_t k = 0; k < n; ++k) {
    const Index i = order[k];
    if (i < 0 || static_cast<std::size_t>(i) >= n || rank[i] != n) {
      throw Input_error(std::string(what) + ": order must be a permutation of the spheres");
    }
    rank[i] = k;
  }
  return rank;
}

void check_spheres(const std::vector<Vec2>& centers, const std::vector<double>& radii, const char* what) {
  for (std::size_t i = 0; i < centers.size(); ++i) {
    if (!(radii[i] > 0) || !std::isfinite(radii[i]) || !std::isfinite(centers[i][0]) || !std::isfinite(centers[i][1])) {
      throw Input_error(std::string(what) + ": radii must be finite and positive, centres finite");
    }
  }
}

}  // namespace

Mis_part::Mis_part(const std::vector<Vec2>& centers, const std::vector<double>& radii, const std::vector<Index>& order,
                   const std::vector<std::uint8_t>& owned)
    : radii_(radii), owned_(owned), reported_(centers.size(), 0) {
  const std::size_t n = centers.size();
  if (radii.size() != n || order.size() != n || owned.size() != n) {
    throw Input_error("Mis_part: centers, radii, order and owned must have one entry per sphere");
  }
  ranks_of(order, "Mis_part");
  check_spheres(centers, radii, "Mis_part");
  tree_ = std::make_unique<detail::Kept_sphere_tree<2>>(centers, radii, std::vector<Index>(order), /*threads=*/1);
  for (std::size_t i = 0; i < n; ++i) undecided_ += owned[i] != 0;
}

Mis_part::Mis_part(Mis_part&&) noexcept = default;
Mis_part& Mis_part::operator=(Mis_part&&) noexcept = default;
Mis_part::~Mis_part() = default;

// The rule of a round for the sphere at `position` against the earlier
// spheres in the tree (in ones kept, undecided ones pending; out ones are
// never put there): out if a kept one conflicts, else undecided if a pending
// one does, else in.
std::uint8_t Mis_part::decide(std::size_t position) const {
  std::size_t hit = detail::Kept_sphere_tree<2>::kNone;
  detail::Kept_sphere_tree<2>::Met met;
  if (!tree_->conflicting_kept_or_pending(position, hit, met)) {
    // (more pending conflicts than the query lists: undecided unless a kept one conflicts)
    return tree_->conflicting_kept(position) != detail::Kept_sphere_tree<2>::kNone ? out : unknown;
  }
  if (hit != detail::Kept_sphere_tree<2>::kNone) return out;
  return met.size > 0 ? unknown : in;
}

std::vector<Index> Mis_part::sweep(std::vector<std::uint8_t>& state) {
  const std::size_t n = radii_.size();
  if (state.size() != n) throw Input_error("Mis_part::sweep: one state per sphere");
  detail::Kept_sphere_tree<2>& tree = *tree_;
  tree.reset();
  // Pending spheres are the undecided ones: the largest of their radii bounds
  // the pruning of the pending search (Kept_sphere_tree::set_pending_radius).
  double pending = -1;
  for (std::size_t i = 0; i < n; ++i) {
    if (state[i] == unknown) pending = std::max(pending, radii_[i]);
  }
  tree.set_pending_radius(pending);
  std::vector<Index> decided;
  undecided_ = 0;
  for (std::size_t k = 0; k < tree.n_visits(); ++k) {
    const std::size_t position = tree.visit(k);
    const auto s = static_cast<Index>(tree.sphere_at(position));
    if (owned_[s]) {
      if (state[s] == unknown) state[s] = decide(position);
      if (state[s] == unknown) {
        ++undecided_;
      } else if (!reported_[s]) {
        reported_[s] = 1;
        decided.push_back(s);
      }
    }
    if (state[s] == in) tree.keep(position);
    else if (state[s] == unknown) tree.mark_pending(position);
  }
  return decided;
}

Mis_rounds lexical_first_mis_in_rounds(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                                       const std::vector<Index>& order, std::size_t n_forced,
                                       const std::vector<std::int32_t>& part, int n_parts) {
  const std::size_t n = centers.size();
  if (radii.size() != n || order.size() != n || part.size() != n) {
    throw Input_error("lexical_first_mis_in_rounds: centers, radii, order and part must have one entry per sphere");
  }
  if (n_parts < 1 || n_forced > n) throw Input_error("lexical_first_mis_in_rounds: n_parts >= 1, n_forced <= n");
  const auto rank = ranks_of(order, "lexical_first_mis_in_rounds");
  check_spheres(centers, radii, "lexical_first_mis_in_rounds");
  for (std::size_t i = 0; i < n; ++i) {
    if (part[i] < 0 || part[i] >= n_parts) throw Input_error("lexical_first_mis_in_rounds: part out of range");
  }
  const auto earlier = earlier_conflicts(centers, radii, rank);
  // For the messages: the other parts each sphere conflicts with (either way round).
  std::vector<std::vector<std::int32_t>> told(n);
  for (std::size_t s = 0; s < n; ++s) {
    for (const Index* it = earlier.begin(s); it != earlier.end(s); ++it) {
      const Index t = *it;
      if (part[t] == part[s]) continue;
      told[s].push_back(part[t]);
      told[t].push_back(part[s]);
    }
  }
  Mis_rounds out;
  for (auto& parts : told) {
    std::sort(parts.begin(), parts.end());
    parts.erase(std::unique(parts.begin(), parts.end()), parts.end());
    out.halo += static_cast<std::int64_t>(parts.size());
  }
  constexpr std::uint8_t unknown = Mis_part::unknown, in = Mis_part::in;
  std::vector<std::uint8_t> state(n, unknown);
  for (std::size_t k = 0; k < n_forced; ++k) state[order[k]] = in;
  // Each part's spheres in the order.
  std::vector<std::vector<Index>> sweep(static_cast<std::size_t>(n_parts));
  for (std::size_t k = n_forced; k < n; ++k) sweep[part[order[k]]].push_back(order[k]);
  std::size_t left = n - n_forced;
  std::vector<std::uint8_t> seen = state;  // the states as the previous round left them
  while (left > 0) {
    std::int64_t messages = 0;
    for (auto& spheres : sweep) {
      std::size_t kept_undecided = 0;
      for (Index s : spheres) {
        const std::uint8_t v = decide(earlier, static_cast<std::size_t>(s),
                                      [&](Index t) { return part[t] == part[s] ? state[t] : seen[t]; });
        if (v != unknown) {
          state[s] = v;
          messages += static_cast<std::int64_t>(told[s].size());
          --left;
        } else {
          spheres[kept_undecided++] = s;
        }
      }
      spheres.resize(kept_undecided);
    }
    seen = state;
    ++out.rounds;
    out.messages.push_back(messages);
    out.undecided.push_back(static_cast<std::int64_t>(left));
  }
  out.kept.resize(n);
  for (std::size_t i = 0; i < n; ++i) out.kept[i] = state[i] == in;
  return out;
}

}  // namespace evomesh
