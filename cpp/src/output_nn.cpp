#include "evomesh/output_nn.hpp"

#include <algorithm>
#include <cstdint>
#include <exception>
#include <limits>
#include <utility>

#include "evomesh/detail/point_tree.hpp"

namespace evomesh {

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr std::size_t kChunk = 4096;

double squared_distance(const Vec2& a, const Vec2& b) {
  const double dx = a[0] - b[0];
  const double dy = a[1] - b[1];
  return dx * dx + dy * dy;
}

}  // namespace

struct Selection_nn::Impl {
  detail::Point_tree tree;
  std::vector<double> nn2;  // by tree position
  explicit Impl(const std::vector<Vec2>& points) : tree(points) {}

  const std::vector<Vec2>& points() const { return tree.tree_points(); }

  // Every node's largest value[k] of the positions k below it (heap order, as
  // the tree's nodes).
  std::vector<double> max_below(const std::vector<double>& value) const {
    const auto& t = tree.tree();
    const std::size_t n_leaves = t.n_leaves();
    std::vector<double> most(2 * n_leaves, -kInfinity);
    parallel_for((n_leaves + 1023) / 1024, 0, [&](std::size_t c) {
      for (std::size_t leaf = c * 1024; leaf < std::min(n_leaves, (c + 1) * 1024); ++leaf) {
        double m = -kInfinity;
        for (std::size_t k = t.leaf_begin(leaf); k < t.leaf_begin(leaf + 1); ++k) m = std::max(m, value[k]);
        most[n_leaves + leaf] = m;
      }
    });
    for (std::size_t node = n_leaves - 1; node >= 1; --node) most[node] = std::max(most[2 * node], most[2 * node + 1]);
    return most;
  }

  // visit(position, squared distance) for every position k with
  // |x - p_k|^2 <= bound(k) (nodes pruned by `most`, the bounds' maxima).
  template <class Bound, class Visit>
  void reverse_search(const Vec2& x, const std::vector<double>& most, Bound&& bound, Visit&& visit) const {
    const auto& t = tree.tree();
    const auto& P = points();
    t.depth_first(1, [&](std::size_t m, detail::Kd_stack& stack) {
      if (detail::squared_distance(t.node(m), x[0], x[1]) > most[m]) return false;
      if (!t.is_leaf(m)) {
        stack.push_children(m);
        return false;
      }
      const std::size_t leaf = t.leaf(m);
      for (std::size_t k = t.leaf_begin(leaf); k < t.leaf_begin(leaf + 1); ++k) {
        const double d = squared_distance(P[k], x);
        if (d <= bound(k)) visit(k, d);
      }
      return false;
    });
  }

  // The squared distance from x to the nearest position with keep(k), or +inf.
  template <class Keep>
  double nearest(const Vec2& x, Keep&& keep) const {
    const auto& t = tree.tree();
    const auto& P = points();
    double best = kInfinity;
    t.depth_first(1, [&](std::size_t m, detail::Kd_stack& stack) {
      if (detail::squared_distance(t.node(m), x[0], x[1]) > best) return false;
      if (!t.is_leaf(m)) {
        if (detail::squared_distance(t.node(2 * m), x[0], x[1]) <=
            detail::squared_distance(t.node(2 * m + 1), x[0], x[1])) {
          stack.push_children(m);
        } else {
          stack.push_children_right_first(m);
        }
        return false;
      }
      const std::size_t leaf = t.leaf(m);
      for (std::size_t k = t.leaf_begin(leaf); k < t.leaf_begin(leaf + 1); ++k) {
        if (keep(k)) best = std::min(best, squared_distance(P[k], x));
      }
      return false;
    });
    return best;
  }
};

Selection_nn::Selection_nn(const std::vector<Vec2>& selected, int threads) {
  try {
    impl_ = std::make_unique<Impl>(selected);
  } catch (const std::exception&) {
    impl_.reset();  // (too many points for the tree: the output's nn from scratch says so)
    return;
  }
  work_.start(
      [this]() {
        // One thread: the other one is the mesher's.
        const std::size_t n = impl_->points().size();
        std::vector<double> nn2(n);
        for (std::size_t k = 0; k < n; ++k) nn2[k] = impl_->tree.squared_nn_at(k);
        impl_->nn2 = std::move(nn2);
      },
      resolve_threads(threads) > 1);
}

Selection_nn::~Selection_nn() = default;

bool Selection_nn::output_squared_nn(const std::vector<Vec2>& output, const std::vector<Index>& source,
                                     std::vector<double>& nn2) {
  try {
    work_.wait();
  } catch (const std::exception&) {
    return false;
  }
  if (!impl_ || impl_->nn2.size() != impl_->points().size() || output.size() < 2 || source.size() != output.size()) {
    return false;
  }
  const Impl& impl = *impl_;
  const auto& P = impl.points();
  const auto& point_at = impl.tree.tree().point_at();
  const std::size_t n_sel = P.size();
  std::vector<double> near = impl.nn2;  // by position; the output's nn2 of the kept ones at the end
  // Positions of the selected points, which are kept, and the added points.
  std::vector<std::uint32_t> position_of(n_sel);
  parallel_for((n_sel + kChunk - 1) / kChunk, 0, [&](std::size_t c) {
    for (std::size_t k = c * kChunk; k < std::min(n_sel, (c + 1) * kChunk); ++k) {
      position_of[point_at[k]] = static_cast<std::uint32_t>(k);
    }
  });
  std::vector<std::uint8_t> kept(n_sel, 0);
  std::vector<Index> added;
  for (std::size_t i = 0; i < output.size(); ++i) {
    const Index s = source[i];
    if (s < 0) {
      added.push_back(static_cast<Index>(i));
      continue;
    }
    if (static_cast<std::size_t>(s) >= n_sel) return false;
    const std::uint32_t k = position_of[s];
    if (kept[k] || P[k] != output[i]) return false;  // (not the selection it was started with)
    kept[k] = 1;
  }
  std::vector<std::uint32_t> dropped;
  for (std::size_t k = 0; k < n_sel; ++k) {
    if (!kept[k]) dropped.push_back(static_cast<std::uint32_t>(k));
  }
  if (n_sel - dropped.size() < 1) return false;
  auto is_kept = [&](std::size_t k) { return kept[k] != 0; };
  // Dropped points: a kept point within its nn of one searches again, among the kept ones.
  std::vector<double> most = impl.max_below(impl.nn2);
  if (!dropped.empty()) {
    std::vector<std::uint8_t> again(n_sel, 0);
    for (std::uint32_t d : dropped) {
      impl.reverse_search(P[d], most, [&](std::size_t k) { return impl.nn2[k]; },
                          [&](std::size_t k, double) {
                            if (kept[k]) again[k] = 1;
                          });
    }
    std::vector<std::uint32_t> redo;
    for (std::size_t k = 0; k < n_sel; ++k) {
      if (again[k]) redo.push_back(static_cast<std::uint32_t>(k));
    }
    parallel_for((redo.size() + 255) / 256, 0, [&](std::size_t c) {
      for (std::size_t j = c * 256; j < std::min(redo.size(), (c + 1) * 256); ++j) {
        const std::size_t k = redo[j];
        near[k] = impl.nearest(P[k], [&](std::size_t q) { return q != k && kept[q]; });
      }
    });
    if (!redo.empty()) most = impl.max_below(near);
  }
  // Added points: their own nn (the nearest kept point, the nearest other added
  // point), and the kept points they come closer to than those points' nn.
  const std::size_t n_added = added.size();
  std::vector<double> added_nn2(n_added, kInfinity);
  std::vector<std::vector<std::pair<std::uint32_t, double>>> closer((n_added + 255) / 256);
  parallel_for(closer.size(), 0, [&](std::size_t c) {
    for (std::size_t j = c * 256; j < std::min(n_added, (c + 1) * 256); ++j) {
      const Vec2& x = output[added[j]];
      added_nn2[j] = impl.nearest(x, is_kept);
      impl.reverse_search(x, most, [&](std::size_t k) { return near[k]; },
                          [&](std::size_t k, double d) {
                            if (kept[k] && d < near[k]) closer[c].emplace_back(static_cast<std::uint32_t>(k), d);
                          });
    }
  });
  if (n_added >= 2) {
    std::vector<Vec2> added_points(n_added);
    for (std::size_t j = 0; j < n_added; ++j) added_points[j] = output[added[j]];
    std::vector<double> among;
    try {
      among = detail::Point_tree(added_points).squared_nn(0);
    } catch (const std::exception&) {
      return false;  // duplicates
    }
    for (std::size_t j = 0; j < n_added; ++j) added_nn2[j] = std::min(added_nn2[j], among[j]);
  }
  for (const auto& list : closer) {
    for (const auto& [k, d] : list) near[k] = std::min(near[k], d);
  }
  nn2.assign(output.size(), kInfinity);
  std::size_t j = 0;
  for (std::size_t i = 0; i < output.size(); ++i) {
    nn2[i] = source[i] < 0 ? added_nn2[j++] : near[position_of[source[i]]];
    if (!(nn2[i] > 0)) return false;  // duplicates (or no other point): from scratch says so
  }
  return true;
}

}  // namespace evomesh
