// One FRFC step on a convex polyhedron's tetrahedral mesh (tet/tet_step.hpp): the stages
// named in tet_step() at the end, each a function above it.
#include "evomesh/tet/tet_step.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_map>

#include "evomesh/detail/bits.hpp"
#include "evomesh/detail/kept_sphere_tree.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/nd/cone_envelope.hpp"
#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh::tet {

namespace {

using Point_3 = Kernel::Point_3;
using Envelope = nd::Cone_envelope<3>;
using Spheres = detail::Kept_sphere_tree<3>;  // the kept spheres, for their drop filter (covers)
using Mask = Polyhedral_domain::Mask;

Point_3 to_cgal(const Vec3& p) { return Point_3(p[0], p[1], p[2]); }

// A counter-based random stream: the same number for the same (seed, stage,
// element, cell, axis) whatever the thread or the order of the draws.
using evomesh::detail::mix;
double uniform(std::uint64_t seed, std::uint64_t stage, std::uint64_t element, std::uint64_t cell, int axis) {
  const std::uint64_t h = mix(mix(mix(mix(seed) ^ stage) ^ element) ^ (cell * 4 + static_cast<std::uint64_t>(axis)));
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}

// Packing classes, in order (tet_step.hpp).
enum Class : int {
  required_class = 0,
  corner_class,
  old_edge_class,
  new_edge_class,
  old_face_class,
  new_face_class,
  original_class,
  steiner_class,
  sampled_class,
};

struct Candidate {
  Vec3 x;
  double f;
  int cls;
  Index id;      // global id: the old index, or n_old + the sample's number
  Index origin;  // old index or -1
  Index parent;  // old tetrahedron of a new point
  bool rejected; // by the near-boundary rule
  Mask on;       // the facets it lies on
};

std::uint64_t edge_key(Index a, Index b) {
  return (static_cast<std::uint64_t>(std::min(a, b)) << 32) | static_cast<std::uint64_t>(std::max(a, b));
}

// f at x, the search started from the values at the old tetrahedron's vertices.
double f_in_tet(const Envelope& envelope, const Tet_step_input& in, Index tet, const Vec3& x,
                std::size_t& evaluations) {
  double best = std::numeric_limits<double>::infinity();
  for (Index v : in.tets[static_cast<std::size_t>(tet)]) {
    best = std::min(best, Envelope::value(in.weight[static_cast<std::size_t>(v)], in.points[static_cast<std::size_t>(v)], x));
  }
  evaluations += 4;
  return envelope(x, best, evaluations);
}

// f at new candidates (parallel; the same values whatever the threads), then
// capped by the size request.
void evaluate_f(const Envelope& envelope, const Tet_step_input& in, std::vector<Candidate>& candidates,
                std::size_t first, const Size_cap& cap, int threads, std::size_t& evaluations) {
  const std::size_t n = candidates.size() - first;
  constexpr std::size_t kChunk = 1024;
  const std::size_t n_chunks = (n + kChunk - 1) / kChunk;
  std::vector<std::size_t> counts(n_chunks, 0);
  parallel_for(n_chunks, threads, [&](std::size_t c) {
    for (std::size_t k = first + c * kChunk; k < first + std::min(n, (c + 1) * kChunk); ++k) {
      candidates[k].f = f_in_tet(envelope, in, candidates[k].parent, candidates[k].x, counts[c]);
    }
  });
  for (std::size_t c : counts) evaluations += c;
  if (!cap || n == 0) return;
  std::vector<Vec3> x(n);
  std::vector<Index> tet(n);
  for (std::size_t k = 0; k < n; ++k) x[k] = candidates[first + k].x, tet[k] = candidates[first + k].parent;
  std::vector<double> limit(n);
  cap(x, tet, limit);
  if (limit.size() != n) throw Input_error("the size request returned the wrong number of values");
  for (std::size_t k = 0; k < n; ++k) {
    if (!(limit[k] > 0) || !std::isfinite(limit[k])) throw Input_error("the size request must be finite and positive");
    candidates[first + k].f = std::min(candidates[first + k].f, limit[k]);
  }
}

void check_cells(double cells, double max_samples, const char* where) {
  if (cells > max_samples) {
    throw Input_error(std::string("the step would draw ") + format_count(cells) + " samples " + where +
                      ", above max_samples = " + format_count(max_samples) + " (refine over several steps)");
  }
}

// Stage: samples on the domain's edges (the 1-D rule: cells of side c f(q) / 2
// on each piece between consecutive old points of an edge, measured along the
// edge's largest coordinate; points exactly on the edge,
// Polyhedral_domain::edge_point).
void sample_edges(const Tet_step_input& in, const std::vector<Mask>& on_old, const std::vector<double>& f_old,
                  const Tet_step_options& options, std::vector<Candidate>& out) {
  const Polyhedral_domain& domain = in.domain;
  std::unordered_map<std::uint64_t, Index> edge_tet;
  for (std::size_t t = 0; t < in.boundary.size(); ++t) {
    const Face& face = in.boundary[t];
    for (int i = 0; i < 3; ++i) edge_tet.emplace(edge_key(face[i], face[(i + 1) % 3]), in.boundary_tet[t]);
  }
  const std::size_t n = in.points.size();
  double cells = 0;
  struct Piece { Index a, b; std::size_t edge; };
  std::vector<Piece> pieces;
  // The old points of each edge, in index order, in one pass over the points:
  // a point on two facets lies on their edge; a corner (three or more) on each
  // edge of two of its facets.
  std::vector<Mask> edge_mask(domain.n_edges());
  std::unordered_map<Mask, std::size_t> edge_of_mask;
  for (std::size_t e = 0; e < domain.n_edges(); ++e) {
    const auto [f0, f1] = domain.edge_facets(e);
    edge_mask[e] = (Mask{1} << f0) | (Mask{1} << f1);
    edge_of_mask.emplace(edge_mask[e], e);
  }
  std::vector<std::vector<Index>> old_on_edge(domain.n_edges());
  for (std::size_t p = 0; p < n; ++p) {
    const int facets = evomesh::detail::popcount(on_old[p]);
    if (facets == 2) {
      if (const auto it = edge_of_mask.find(on_old[p]); it != edge_of_mask.end()) {
        old_on_edge[it->second].push_back(static_cast<Index>(p));
      }
    } else if (facets > 2) {
      for (std::size_t e = 0; e < domain.n_edges(); ++e) {
        if ((on_old[p] & edge_mask[e]) == edge_mask[e]) old_on_edge[e].push_back(static_cast<Index>(p));
      }
    }
  }
  for (std::size_t e = 0; e < domain.n_edges(); ++e) {
    const int axis = domain.edge_axis(e);
    std::vector<Index>& on_edge = old_on_edge[e];
    std::sort(on_edge.begin(), on_edge.end(), [&](Index a, Index b) {
      return in.points[static_cast<std::size_t>(a)][axis] < in.points[static_cast<std::size_t>(b)][axis];
    });
    for (std::size_t k = 0; k + 1 < on_edge.size(); ++k) pieces.push_back({on_edge[k], on_edge[k + 1], e});
  }
  std::vector<double> sides(pieces.size());
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    const auto a = static_cast<std::size_t>(pieces[i].a), b = static_cast<std::size_t>(pieces[i].b);
    const int axis = domain.edge_axis(pieces[i].edge);
    // The cell's side along the edge's axis (its length along the edge: c f / 2).
    sides[i] = options.cell_factor * std::min(f_old[a], f_old[b]) / 2;
    if (!domain.edge_is_axis_aligned(pieces[i].edge)) sides[i] *= domain.edge_axis_scale(pieces[i].edge);
    cells += std::ceil((in.points[b][axis] - in.points[a][axis]) / sides[i]);
  }
  check_cells(cells, options.max_samples, "on the domain's edges");
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    const auto [a, b, e] = pieces[i];
    const int axis = domain.edge_axis(e);
    const auto [f0, f1] = domain.edge_facets(e);
    const auto it = edge_tet.find(edge_key(a, b));
    if (it == edge_tet.end()) throw Input_error("consecutive points on a domain edge are not joined by a boundary edge");
    const Vec3& pa = in.points[static_cast<std::size_t>(a)];
    const double end = in.points[static_cast<std::size_t>(b)][axis];
    const auto n_cells = static_cast<std::uint64_t>(std::ceil((end - pa[axis]) / sides[i]));
    for (std::uint64_t cell = 0; cell < n_cells; ++cell) {
      const double value = pa[axis] + (static_cast<double>(cell) + uniform(options.seed, 1, i, cell, 0)) * sides[i];
      Vec3 x;
      if (!domain.edge_point(e, value, x) || !(x[axis] > pa[axis] && x[axis] < end)) continue;
      out.push_back({x, 0, new_edge_class, 0, -1, it->second, false,
                     (Mask{1} << f0) | (Mask{1} << f1)});
    }
  }
}

// Stage: samples on the domain's facets (the 2-D rule: cells of side
// c f(q) / (2 sqrt 2) over each boundary triangle, seen in the coordinate
// plane its facet projects onto best; a facet normal to an axis keeps that
// coordinate exact, another facet's samples go to its lattice,
// Polyhedral_domain::snap_to_facet).
void sample_faces(const Tet_step_input& in, const std::vector<double>& f_old, const Tet_step_options& options,
                  std::vector<Candidate>& out) {
  const Polyhedral_domain& domain = in.domain;
  std::vector<double> sides(in.boundary.size());
  double cells = 0;
  for (std::size_t t = 0; t < in.boundary.size(); ++t) {
    const Face& face = in.boundary[t];
    const auto facet = static_cast<std::size_t>(in.boundary_facet[t]);
    double f_min = std::numeric_limits<double>::infinity();
    Vec3 lo = in.points[static_cast<std::size_t>(face[0])], hi = lo;
    for (Index v : face) {
      f_min = std::min(f_min, f_old[static_cast<std::size_t>(v)]);
      for (int i = 0; i < 3; ++i) {
        lo[i] = std::min(lo[i], in.points[static_cast<std::size_t>(v)][i]);
        hi[i] = std::max(hi[i], in.points[static_cast<std::size_t>(v)][i]);
      }
    }
    sides[t] = options.cell_factor * f_min / (2 * std::sqrt(2.0));
    // In the projection lengths shrink by at most the projection scale.
    if (domain.facet_axis(facet) < 0) sides[t] *= domain.facet_projection_scale(facet);
    const int axis = domain.facet_projection_axis(facet), u = (axis + 1) % 3, v = (axis + 2) % 3;
    cells += std::ceil((hi[u] - lo[u]) / sides[t]) * std::ceil((hi[v] - lo[v]) / sides[t]);
  }
  check_cells(cells, options.max_samples, "on the domain's facets");
  for (std::size_t t = 0; t < in.boundary.size(); ++t) {
    const Face& face = in.boundary[t];
    const auto facet = static_cast<std::size_t>(in.boundary_facet[t]);
    const int axis = domain.facet_projection_axis(facet), u = (axis + 1) % 3, v = (axis + 2) % 3;
    const Mask on = Mask{1} << facet;
    Vec2 corner[3];
    double lo_u = std::numeric_limits<double>::infinity(), lo_v = lo_u, hi_u = -lo_u, hi_v = -lo_u;
    for (int i = 0; i < 3; ++i) {
      const Vec3& p = in.points[static_cast<std::size_t>(face[i])];
      corner[i] = {p[u], p[v]};
      lo_u = std::min(lo_u, p[u]), hi_u = std::max(hi_u, p[u]);
      lo_v = std::min(lo_v, p[v]), hi_v = std::max(hi_v, p[v]);
    }
    const int turn = orientation(corner[0], corner[1], corner[2]);
    if (turn == 0) throw Input_error("a boundary triangle is flat");
    const auto inside = [&](const Vec2& y) {
      return orientation(corner[0], corner[1], y) == turn && orientation(corner[1], corner[2], y) == turn &&
             orientation(corner[2], corner[0], y) == turn;
    };
    const Vec3& a = in.points[static_cast<std::size_t>(face[0])];
    const auto n_u = static_cast<std::uint64_t>(std::ceil((hi_u - lo_u) / sides[t]));
    const auto n_v = static_cast<std::uint64_t>(std::ceil((hi_v - lo_v) / sides[t]));
    for (std::uint64_t i = 0; i < n_u; ++i) {
      for (std::uint64_t j = 0; j < n_v; ++j) {
        const std::uint64_t cell = i * n_v + j;
        const Vec2 y{lo_u + (static_cast<double>(i) + uniform(options.seed, 2, t, cell, 0)) * sides[t],
                     lo_v + (static_cast<double>(j) + uniform(options.seed, 2, t, cell, 1)) * sides[t]};
        if (!inside(y)) continue;
        Vec3 x = a;
        x[u] = y[0], x[v] = y[1];
        // On a tilted facet: onto the lattice, and still inside the triangle
        // (the projection of points on one plane keeps their orientations).
        if (domain.facet_axis(facet) < 0 && (!domain.snap_to_facet(facet, x) || !inside({x[u], x[v]}))) continue;
        out.push_back({x, 0, new_face_class, 0, -1, in.boundary_tet[t], false, on});
      }
    }
  }
}

// Stage: samples in the old tetrahedra (cells of side c f(q) / (2 sqrt 3), a
// random point in each, kept when strictly inside), except those strictly
// inside a sphere already selected (the drop filter: such a sample conflicts
// whatever its radius, so it is never stored nor given an f).
std::size_t sample_tets(const Tet_step_input& in, const std::vector<double>& f_old, const Spheres& selected,
                        const Tet_step_options& options, std::vector<Candidate>& out) {
  const std::size_t m = in.tets.size();
  std::vector<double> sides(m);
  double cells = 0;
  for (std::size_t t = 0; t < m; ++t) {
    Vec3 lo = in.points[static_cast<std::size_t>(in.tets[t][0])], hi = lo;
    double f_min = std::numeric_limits<double>::infinity();
    for (Index v : in.tets[t]) {
      const Vec3& p = in.points[static_cast<std::size_t>(v)];
      f_min = std::min(f_min, f_old[static_cast<std::size_t>(v)]);
      for (int i = 0; i < 3; ++i) lo[i] = std::min(lo[i], p[i]), hi[i] = std::max(hi[i], p[i]);
    }
    sides[t] = options.cell_factor * f_min / (2 * std::sqrt(3.0));
    double c = 1;
    for (int i = 0; i < 3; ++i) c *= std::ceil((hi[i] - lo[i]) / sides[t]);
    cells += c;
  }
  check_cells(cells, options.max_samples, "in the tetrahedra");
  constexpr std::size_t kChunk = 256;
  const std::size_t n_chunks = (m + kChunk - 1) / kChunk;
  std::vector<std::vector<Candidate>> chunk_out(n_chunks);
  std::vector<std::size_t> dropped(n_chunks, 0);
  parallel_for(n_chunks, options.threads, [&](std::size_t c) {
    for (std::size_t t = c * kChunk; t < std::min(m, (c + 1) * kChunk); ++t) {
      Point_3 corner[4];
      Vec3 lo = in.points[static_cast<std::size_t>(in.tets[t][0])], hi = lo;
      for (int k = 0; k < 4; ++k) {
        const Vec3& p = in.points[static_cast<std::size_t>(in.tets[t][k])];
        corner[k] = to_cgal(p);
        for (int i = 0; i < 3; ++i) lo[i] = std::min(lo[i], p[i]), hi[i] = std::max(hi[i], p[i]);
      }
      std::uint64_t n_cells[3];
      for (int i = 0; i < 3; ++i) n_cells[i] = static_cast<std::uint64_t>(std::ceil((hi[i] - lo[i]) / sides[t]));
      for (std::uint64_t i = 0; i < n_cells[0]; ++i) {
        for (std::uint64_t j = 0; j < n_cells[1]; ++j) {
          for (std::uint64_t k = 0; k < n_cells[2]; ++k) {
            const std::uint64_t cell = (i * n_cells[1] + j) * n_cells[2] + k;
            const std::uint64_t index[3] = {i, j, k};
            Vec3 x;
            for (int a = 0; a < 3; ++a) {
              x[a] = lo[a] + (static_cast<double>(index[a]) + uniform(options.seed, 3, t, cell, a)) * sides[t];
            }
            const Point_3 q = to_cgal(x);
            if (CGAL::orientation(q, corner[1], corner[2], corner[3]) != CGAL::POSITIVE ||
                CGAL::orientation(corner[0], q, corner[2], corner[3]) != CGAL::POSITIVE ||
                CGAL::orientation(corner[0], corner[1], q, corner[3]) != CGAL::POSITIVE ||
                CGAL::orientation(corner[0], corner[1], corner[2], q) != CGAL::POSITIVE) {
              continue;
            }
            if (selected.covers(x)) {
              ++dropped[c];
              continue;
            }
            chunk_out[c].push_back({x, 0, sampled_class, 0, -1, static_cast<Index>(t), false, 0});
          }
        }
      }
    }
  });
  std::size_t n_dropped = 0;
  for (std::size_t c = 0; c < n_chunks; ++c) {
    out.insert(out.end(), chunk_out[c].begin(), chunk_out[c].end());
    n_dropped += dropped[c];
  }
  return n_dropped;
}

// The near-boundary rule (tet_step.hpp, boundary_clearance).
void apply_clearance(const Polyhedral_domain& domain, double clearance, std::vector<Candidate>& candidates,
                     std::size_t first) {
  for (std::size_t k = first; k < candidates.size(); ++k) {
    Candidate& c = candidates[k];
    if (c.cls <= corner_class) continue;
    c.rejected = domain.clearance(c.x, c.on) < clearance * c.f;
  }
}

// The packing order of candidates[first..) (class, f, id: packing_order, the
// 2-D step's, ties by index, and ids grow with the index), as indices into
// candidates; the rejected ones left out (never kept, they meet nothing).
std::vector<Index> packing_order_of(const std::vector<Candidate>& candidates, std::size_t first) {
  std::vector<std::uint8_t> classes(candidates.size() - first);
  std::vector<double> f(candidates.size() - first);
  for (std::size_t k = first; k < candidates.size(); ++k) {
    classes[k - first] = static_cast<std::uint8_t>(candidates[k].cls);
    f[k - first] = candidates[k].f;
  }
  std::vector<Index> order;
  for (Index i : packing_order(std::move(classes), std::move(f))) {
    const std::size_t k = first + static_cast<std::size_t>(i);
    if (!candidates[k].rejected) order.push_back(static_cast<Index>(k));
  }
  return order;
}

std::vector<nd::Point<3>> centres(const std::vector<Candidate>& candidates) {
  std::vector<nd::Point<3>> out(candidates.size());
  for (std::size_t k = 0; k < candidates.size(); ++k) out[k] = candidates[k].x;
  return out;
}

std::vector<double> radii(const std::vector<Candidate>& candidates, double radius_scale) {
  std::vector<double> out(candidates.size());
  for (std::size_t k = 0; k < candidates.size(); ++k) out[k] = radius_scale * candidates[k].f / 2;
  return out;
}

// The kept spheres, for the drop filter (Spheres::covers).
Spheres kept_spheres(const std::vector<Candidate>& candidates, const std::vector<std::uint8_t>& kept,
                     double radius_scale, int threads) {
  std::vector<nd::Point<3>> x;
  std::vector<double> r;
  for (std::size_t k = 0; k < kept.size(); ++k) {
    if (!kept[k]) continue;
    x.push_back(candidates[k].x);
    r.push_back(radius_scale * candidates[k].f / 2);
  }
  std::vector<Index> order(x.size());
  std::iota(order.begin(), order.end(), Index{0});
  Spheres spheres(x, r, std::move(order), threads);
  for (std::size_t k = 0; k < spheres.n_visits(); ++k) spheres.keep(spheres.visit(k));
  return spheres;
}

Tet_point_kind output_kind(const Candidate& c, const Tet_step_input& in) {
  const int planes = Polyhedral_domain::count(c.on);
  if (planes >= 3) return Tet_point_kind::corner;
  if (planes == 2) return Tet_point_kind::edge;
  if (planes == 1) return Tet_point_kind::face;
  if (c.origin < 0) return Tet_point_kind::sampled;
  return in.steiner[static_cast<std::size_t>(c.origin)] ? Tet_point_kind::steiner : Tet_point_kind::original;
}

// The old mesh for point location: a tetrahedron of each point and the
// neighbour across each face (-1 on the boundary).
class Old_mesh {
 public:
  explicit Old_mesh(const Tet_step_input& in) : in_(in), tet_of_point_(in.points.size(), -1), neighbour_(in.tets.size()) {
    struct Facet { std::array<Index, 3> key; Index tet; int face; };
    std::vector<Facet> facets;
    facets.reserve(4 * in.tets.size());
    for (std::size_t t = 0; t < in.tets.size(); ++t) {
      for (int i = 0; i < 4; ++i) {
        tet_of_point_[static_cast<std::size_t>(in.tets[t][i])] = static_cast<Index>(t);
        std::array<Index, 3> key{in.tets[t][(i + 1) % 4], in.tets[t][(i + 2) % 4], in.tets[t][(i + 3) % 4]};
        std::sort(key.begin(), key.end());
        facets.push_back({key, static_cast<Index>(t), i});
      }
      neighbour_[t].fill(-1);
    }
    std::sort(facets.begin(), facets.end(), [](const Facet& a, const Facet& b) { return a.key < b.key; });
    for (std::size_t k = 0; k + 1 < facets.size(); ++k) {
      if (facets[k].key != facets[k + 1].key) continue;
      neighbour_[static_cast<std::size_t>(facets[k].tet)][facets[k].face] = facets[k + 1].tet;
      neighbour_[static_cast<std::size_t>(facets[k + 1].tet)][facets[k + 1].face] = facets[k].tet;
    }
  }

  Index tet_of_point(Index p) const { return tet_of_point_[static_cast<std::size_t>(p)]; }

  // An old tetrahedron holding x (on its boundary counts): a visibility walk
  // from `start` with exact orientations, the face to cross tried in a
  // rotating order (so the walk cannot cycle); a scan of every tetrahedron if
  // it has not arrived after as many steps as there are tetrahedra.
  Index locate(const Vec3& x, Index start) const {
    const Point_3 q = to_cgal(x);
    Index t = start;
    for (std::size_t step = 0; step < in_.tets.size() + 8; ++step) {
      int exit = -1;
      for (int r = 0; r < 4 && exit < 0; ++r) {
        const int i = static_cast<int>((step + static_cast<std::size_t>(r)) % 4);
        if (side(t, i, q) == CGAL::NEGATIVE) exit = i;
      }
      if (exit < 0) return t;
      const Index next = neighbour_[static_cast<std::size_t>(t)][exit];
      if (next < 0) break;
      t = next;
    }
    for (std::size_t u = 0; u < in_.tets.size(); ++u) {
      bool holds = true;
      for (int i = 0; i < 4 && holds; ++i) holds = side(static_cast<Index>(u), i, q) != CGAL::NEGATIVE;
      if (holds) return static_cast<Index>(u);
    }
    throw Input_error("a new point lies outside the old mesh");
  }

 private:
  // The orientation of the tetrahedron with its vertex i replaced by q
  // (negative: q lies beyond face i).
  CGAL::Orientation side(Index t, int i, const Point_3& q) const {
    Point_3 p[4];
    for (int k = 0; k < 4; ++k) {
      p[k] = k == i ? q : to_cgal(in_.points[static_cast<std::size_t>(in_.tets[static_cast<std::size_t>(t)][k])]);
    }
    return CGAL::orientation(p[0], p[1], p[2], p[3]);
  }

  const Tet_step_input& in_;
  std::vector<Index> tet_of_point_;
  std::vector<std::array<Index, 4>> neighbour_;
};

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

std::vector<double> tet_nn_spacing(const std::vector<Vec3>& points, int threads) {
  return nd::nearest_neighbour_distances<3>(points, threads);
}

std::vector<std::int8_t> tet_orientations(const std::vector<Vec3>& points, const std::vector<Tet>& tets) {
  std::vector<std::int8_t> out(tets.size());
  for (std::size_t t = 0; t < tets.size(); ++t) {
    const auto& v = tets[t];
    out[t] = static_cast<std::int8_t>(CGAL::orientation(to_cgal(points[static_cast<std::size_t>(v[0])]),
                                                        to_cgal(points[static_cast<std::size_t>(v[1])]),
                                                        to_cgal(points[static_cast<std::size_t>(v[2])]),
                                                        to_cgal(points[static_cast<std::size_t>(v[3])])));
  }
  return out;
}

std::vector<double> cone_envelope_3(const std::vector<Vec3>& sites, const std::vector<double>& weights,
                                    const std::vector<Vec3>& queries, bool brute_force, std::size_t& evaluations,
                                    int threads) {
  std::vector<double> out(queries.size());
  if (brute_force) {
    parallel_for(queries.size(), threads, [&](std::size_t q) { out[q] = Envelope::brute_force(sites, weights, queries[q]); });
    evaluations = sites.size() * queries.size();
    return out;
  }
  const Envelope envelope(sites, weights);
  constexpr std::size_t kChunk = 1024;
  const std::size_t n_chunks = (queries.size() + kChunk - 1) / kChunk;
  std::vector<std::size_t> counts(n_chunks, 0);
  parallel_for(n_chunks, threads, [&](std::size_t c) {
    for (std::size_t q = c * kChunk; q < std::min(queries.size(), (c + 1) * kChunk); ++q) {
      out[q] = envelope(queries[q], std::numeric_limits<double>::infinity(), counts[c]);
    }
  });
  evaluations = std::accumulate(counts.begin(), counts.end(), std::size_t{0});
  return out;
}

Tet_step_result tet_step(const Tet_step_input& in, const Tet_step_options& options, const Size_cap& cap) {
  const auto start = std::chrono::steady_clock::now();
  const std::size_t n = in.points.size();
  if (in.weight.size() != n || in.steiner.size() != n || in.required.size() != n) {
    throw Input_error("weight, steiner and required need one value per point");
  }
  if (in.boundary_tet.size() != in.boundary.size()) throw Input_error("one tetrahedron per boundary triangle");
  for (double w : in.weight) {
    if (!(w > 0) || !std::isfinite(w)) throw Input_error("weights must be finite and positive");
  }
  options.validate();
  Thread_limit limit(options.threads);
  Tet_step_result result;
  auto stat = [&](const char* name, double value) { result.stats.emplace_back(name, value); };

  // f at the old points (the search starts from the point's own value w_p).
  const Envelope envelope(in.points, in.weight);
  std::vector<double> f_old(n);
  std::size_t old_evaluations = 0;
  {
    constexpr std::size_t kChunk = 1024;
    const std::size_t n_chunks = (n + kChunk - 1) / kChunk;
    std::vector<std::size_t> counts(n_chunks, 0);
    parallel_for(n_chunks, options.threads, [&](std::size_t c) {
      for (std::size_t p = c * kChunk; p < std::min(n, (c + 1) * kChunk); ++p) {
        f_old[p] = envelope(in.points[p], in.weight[p], counts[c]);
      }
    });
    old_evaluations = std::accumulate(counts.begin(), counts.end(), std::size_t{0});
  }
  stat("evaluations_per_old_point", n ? static_cast<double>(old_evaluations) / static_cast<double>(n) : 0.0);

  // The old points and the boundary's samples, packed first.
  std::vector<Candidate> candidates(n);
  std::vector<Mask> on_old(n);
  {
    constexpr std::size_t kChunk = 4096;
    parallel_for((n + kChunk - 1) / kChunk, options.threads, [&](std::size_t c) {
      for (std::size_t p = c * kChunk; p < std::min(n, (c + 1) * kChunk); ++p) on_old[p] = in.domain.incidences(in.points[p]);
    });
  }
  for (std::size_t p = 0; p < n; ++p) {
    const Mask on = on_old[p];
    const int planes = Polyhedral_domain::count(on);
    int cls = planes >= 3 ? corner_class : planes == 2 ? old_edge_class : planes == 1 ? old_face_class
              : in.steiner[p] ? steiner_class : original_class;
    if (in.required[p]) cls = required_class;
    candidates[p] = {in.points[p], f_old[p], cls, static_cast<Index>(p), static_cast<Index>(p), -1, false, on};
  }
  sample_edges(in, on_old, f_old, options, candidates);
  const std::size_t n_edge_samples = candidates.size() - n;
  sample_faces(in, f_old, options, candidates);
  const std::size_t n_boundary_samples = candidates.size() - n;
  for (std::size_t k = n; k < candidates.size(); ++k) candidates[k].id = static_cast<Index>(k);
  std::size_t sample_evaluations = 0;
  evaluate_f(envelope, in, candidates, n, cap, options.threads, sample_evaluations);
  apply_clearance(in.domain, options.boundary_clearance, candidates, 0);
  // The lexical-first MIS of the 2-D step (packing.hpp), required points and
  // corners forced (the lowest classes: first in the order, never rejected).
  const std::vector<Index> first_order = packing_order_of(candidates, 0);
  const auto n_forced = static_cast<std::size_t>(std::count_if(
      candidates.begin(), candidates.end(), [](const Candidate& c) { return c.cls <= corner_class; }));
  std::vector<std::uint8_t> kept_flags = lexical_first_mis_3(centres(candidates), radii(candidates, options.radius_scale),
                                                             first_order, n_forced, options.threads);
  const Spheres first_spheres = kept_spheres(candidates, kept_flags, options.radius_scale, options.threads);
  stat("edge_samples", static_cast<double>(n_edge_samples));
  stat("face_samples", static_cast<double>(n_boundary_samples - n_edge_samples));

  // The interior samples, packed after every old point.
  const std::size_t first_sample = candidates.size();
  const std::size_t n_dropped = sample_tets(in, f_old, first_spheres, options, candidates);
  for (std::size_t k = first_sample; k < candidates.size(); ++k) candidates[k].id = static_cast<Index>(k);
  evaluate_f(envelope, in, candidates, first_sample, cap, options.threads, sample_evaluations);
  apply_clearance(in.domain, options.boundary_clearance, candidates, first_sample);
  // The samples after every sphere the first pass kept (extend_packing).
  kept_flags = extend_packing_3(centres(candidates), radii(candidates, options.radius_scale), first_order, kept_flags,
                                packing_order_of(candidates, first_sample), options.threads);
  const std::size_t n_queries = candidates.size() - n;
  stat("interior_samples", static_cast<double>(candidates.size() - first_sample));
  stat("samples_dropped", static_cast<double>(n_dropped));
  stat("evaluations_per_sample", n_queries ? static_cast<double>(sample_evaluations) / static_cast<double>(n_queries) : 0.0);
  stat("packing_seconds", seconds_since(start));

  // The kept points: old ones in their order, then the new ones by id.
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    if (!kept_flags[k]) continue;
    const Candidate& c = candidates[k];
    result.points.push_back(c.x);
    result.origin.push_back(c.origin);
    result.parent_tet.push_back(c.origin >= 0 ? -1 : c.parent);
    result.kind.push_back(static_cast<std::uint8_t>(output_kind(c, in)));
    result.facets.push_back(c.on);
    result.f.push_back(c.f);
  }
  const auto triangulation_start = std::chrono::steady_clock::now();
  if (options.max_radius_edge > 0) {
    Refinement_report report;
    const std::size_t n_kept = result.points.size();
    Sliver_options slivers;
    slivers.min_dihedral = options.sliver_angle;
    slivers.max_radius_edge = options.max_radius_edge;
    slivers.first_movable = static_cast<std::size_t>(
        std::count_if(result.origin.begin(), result.origin.end(), [](Index o) { return o >= 0; }));
    slivers.seed = mix(options.seed ^ 0x51u);
    result.tets = refined_delaunay(result.points, in.domain, options.max_radius_edge, n_kept / 10 + 100, slivers,
                                   report);
    // The refinement's points: located in the old mesh by a walk from the
    // old tetrahedron of a vertex of the tetrahedron they split.
    const Old_mesh old(in);
    for (std::size_t k = n_kept; k < result.points.size(); ++k) {
      const auto hint = static_cast<std::size_t>(report.hints[k - n_kept]);
      const Index start = result.origin[hint] >= 0 ? old.tet_of_point(result.origin[hint]) : result.parent_tet[hint];
      const Candidate c{result.points[k], 0, sampled_class, 0, -1, old.locate(result.points[k], start), false,
                        in.domain.incidences(result.points[k])};
      result.origin.push_back(-1);
      result.parent_tet.push_back(c.parent);
      result.kind.push_back(static_cast<std::uint8_t>(output_kind(c, in)));
      result.facets.push_back(c.on);
      result.f.push_back(0.0);
    }
    // Points the sliver pass moved: located again, from where they were.
    for (Index k : report.moved) {
      const auto j = static_cast<std::size_t>(k);
      result.parent_tet[j] = old.locate(result.points[j], result.parent_tet[j]);
    }
    stat("sliver_points_moved", static_cast<double>(report.moved.size()));
    stat("sliver_off_centres", static_cast<double>(report.off_centres));
    stat("slivers_before", static_cast<double>(report.slivers_before));
    stat("slivers_after", static_cast<double>(report.slivers_after));
    stat("refinement_points", static_cast<double>(report.inserted));
    stat("refinement_rounds", static_cast<double>(report.rounds));
    stat("radius_edge_unresolved", static_cast<double>(report.unresolved));
  } else {
    result.tets = delaunay_tetrahedra(result.points);
  }
  stat("triangulation_seconds", seconds_since(triangulation_start));
  stat("step_seconds", seconds_since(start));
  return result;
}

}  // namespace evomesh::tet
