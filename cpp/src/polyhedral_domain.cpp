// The convex polyhedral domain of a tetrahedral step (tet/polyhedral_domain.hpp).
#include "evomesh/tet/polyhedral_domain.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "evomesh/kernel.hpp"

namespace evomesh::tet {

namespace {

using Point_3 = Kernel::Point_3;

Point_3 to_point(const Vec3& p) { return Point_3(p[0], p[1], p[2]); }
Vec3 minus(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
int largest_component(const Vec3& v) {
  int k = 0;
  for (int i = 1; i < 3; ++i) {
    if (std::abs(v[i]) > std::abs(v[k])) k = i;
  }
  return k;
}

// l rounded to the nearest multiple of 2^-bits.
double snapped(double l, int bits) { return std::ldexp(std::nearbyint(std::ldexp(l, bits)), -bits); }

// Test parameters in (0, 1) that use every one of the lattice's bits (odd
// multiples of 2^-bits), spread by the golden ratios.
double test_parameter(int k, double ratio, int bits) {
  const double u = std::fmod((k + 1) * ratio, 1.0);
  double m = std::floor(std::ldexp(u, bits));
  if (std::fmod(m, 2.0) == 0) m += 1;
  return std::ldexp(m, -bits);
}

// The finest lattice resolution 2^-bits (bits = 40, 36, ..., 12) at which
// exact(bits, k) holds for the 16 test points k; 0 when none does.
template <class Exact>
int lattice_bits(Exact exact) {
  for (const int bits : {40, 36, 32, 28, 24, 20, 16, 12}) {
    bool all = true;
    for (int k = 0; k < 16 && all; ++k) all = exact(bits, k);
    if (all) return bits;
  }
  return 0;
}

}  // namespace

Polyhedral_domain::Polyhedral_domain(const std::vector<std::array<Vec3, 3>>& facets,
                                     const std::vector<std::array<int, 2>>& edge_facets,
                                     const std::vector<std::array<Vec3, 2>>& edge_ends,
                                     const std::vector<Mask>& neighbours) {
  if (facets.empty() || facets.size() > max_facets) {
    throw Input_error("a domain needs 1 to " + std::to_string(max_facets) + " planar facets, got " +
                      std::to_string(facets.size()));
  }
  if (neighbours.size() != facets.size() || edge_ends.size() != edge_facets.size()) {
    throw Input_error("one neighbour mask per facet and two end corners per edge");
  }
  for (std::size_t f = 0; f < facets.size(); ++f) {
    Facet facet;
    facet.a = facets[f][0], facet.b = facets[f][1], facet.c = facets[f][2];
    if (CGAL::collinear(to_point(facet.a), to_point(facet.b), to_point(facet.c))) {
      throw Input_error("facet " + std::to_string(f) + ": its three points are collinear");
    }
    facet.e1 = minus(facet.b, facet.a), facet.e2 = minus(facet.c, facet.a);
    const Vec3 normal = cross(facet.e1, facet.e2);  // outward: inside points see (a, b, c) clockwise
    const double length = std::sqrt(dot(normal, normal));
    facet.inward = {-normal[0] / length, -normal[1] / length, -normal[2] / length};
    for (int k = 0; k < 3; ++k) {
      if (facet.a[k] == facet.b[k] && facet.a[k] == facet.c[k]) facet.axis = k;
    }
    facet.projection_axis = largest_component(facet.inward);
    facet.projection_scale = std::abs(facet.inward[facet.projection_axis]);
    facet.gram[0] = dot(facet.e1, facet.e1), facet.gram[1] = dot(facet.e1, facet.e2), facet.gram[2] = dot(facet.e2, facet.e2);
    facet.neighbours = neighbours[f];
    facets_.push_back(facet);
    if (facet.axis >= 0) continue;
    Facet& added = facets_.back();
    added.bits = lattice_bits([&](int bits, int k) {
      Vec3 x;
      return lattice_point(added, test_parameter(k, 0.6180339887498949, bits), test_parameter(k, 0.7548776662466927, bits), x);
    });
    if (added.bits == 0) {
      throw Input_error("facet " + std::to_string(f) + " is not normal to an axis and holds no float64 lattice of points "
                        "exactly on its plane: give its corners fewer significant bits (e.g. multiples of a power of two)");
    }
  }
  for (std::size_t e = 0; e < edge_facets.size(); ++e) {
    Domain_edge edge;
    edge.facets = edge_facets[e];
    for (int f : edge.facets) {
      if (f < 0 || static_cast<std::size_t>(f) >= facets_.size()) throw Input_error("edge facet out of range");
    }
    edge.p = edge_ends[e][0], edge.q = edge_ends[e][1], edge.d = minus(edge.q, edge.p);
    edge.axis = largest_component(edge.d);
    if (edge.d[edge.axis] == 0) throw Input_error("edge " + std::to_string(e) + " has equal end corners");
    edge.aligned = edge.d[(edge.axis + 1) % 3] == 0 && edge.d[(edge.axis + 2) % 3] == 0;
    edge.axis_scale = std::abs(edge.d[edge.axis]) / std::sqrt(dot(edge.d, edge.d));
    edges_.push_back(edge);
    if (edge.aligned) continue;
    Domain_edge& added = edges_.back();
    added.bits = lattice_bits([&](int bits, int k) {
      const double l = test_parameter(k, 0.6180339887498949, bits);
      const Vec3 x{added.p[0] + l * added.d[0], added.p[1] + l * added.d[1], added.p[2] + l * added.d[2]};
      return CGAL::collinear(to_point(added.p), to_point(added.q), to_point(x));
    });
    if (added.bits == 0) {
      throw Input_error("edge " + std::to_string(e) + " holds no float64 lattice of points exactly on it: give its "
                        "corners fewer significant bits (e.g. multiples of a power of two)");
    }
  }
}

bool Polyhedral_domain::on_plane(std::size_t f, const Vec3& x) const {
  const Facet& facet = facets_[f];
  if (facet.axis >= 0) return x[facet.axis] == facet.a[facet.axis];
  return CGAL::orientation(to_point(facet.a), to_point(facet.b), to_point(facet.c), to_point(x)) == CGAL::COPLANAR;
}

bool Polyhedral_domain::lattice_point(const Facet& facet, double s, double t, Vec3& x) const {
  for (int i = 0; i < 3; ++i) x[i] = (facet.a[i] + s * facet.e1[i]) + t * facet.e2[i];
  return CGAL::orientation(to_point(facet.a), to_point(facet.b), to_point(facet.c), to_point(x)) == CGAL::COPLANAR;
}

Polyhedral_domain::Mask Polyhedral_domain::incidences(const Vec3& x) const {
  Mask on = 0;
  for (std::size_t f = 0; f < facets_.size(); ++f) {
    if (on_plane(f, x)) on |= Mask{1} << f;
  }
  return on;
}

int Polyhedral_domain::edge_of(Mask m) const {
  for (std::size_t e = 0; e < edges_.size(); ++e) {
    if ((m >> edges_[e].facets[0] & 1u) && (m >> edges_[e].facets[1] & 1u)) return static_cast<int>(e);
  }
  return -1;
}

double Polyhedral_domain::distance(std::size_t f, const Vec3& x) const {
  const Facet& facet = facets_[f];
  if (facet.axis >= 0) return facet.inward[facet.axis] * (x[facet.axis] - facet.a[facet.axis]);
  return dot(facet.inward, minus(x, facet.a));
}

double Polyhedral_domain::clearance(const Vec3& x, Mask on) const {
  Mask allowed = ~on;
  for (std::size_t f = 0; f < facets_.size(); ++f) {
    if (on >> f & 1u) allowed &= facets_[f].neighbours;
  }
  double c = std::numeric_limits<double>::infinity();
  for (std::size_t f = 0; f < facets_.size(); ++f) {
    if (allowed >> f & 1u) c = std::min(c, distance(f, x));
  }
  return c;
}

bool Polyhedral_domain::strictly_inside(const Vec3& x, Mask except) const {
  for (std::size_t f = 0; f < facets_.size(); ++f) {
    if (except >> f & 1u) continue;
    const Facet& facet = facets_[f];
    if (facet.axis >= 0) {
      if (!(distance(f, x) > 0)) return false;
    } else if (CGAL::orientation(to_point(facet.a), to_point(facet.b), to_point(facet.c), to_point(x)) != CGAL::NEGATIVE) {
      return false;
    }
  }
  return true;
}

bool Polyhedral_domain::snap_to_facet(std::size_t f, Vec3& x) const {
  const Facet& facet = facets_[f];
  if (facet.axis >= 0) {
    x[facet.axis] = facet.a[facet.axis];
    return true;
  }
  const Vec3 d = minus(x, facet.a);
  const double r1 = dot(facet.e1, d), r2 = dot(facet.e2, d);
  const double det = facet.gram[0] * facet.gram[2] - facet.gram[1] * facet.gram[1];
  const double s = (facet.gram[2] * r1 - facet.gram[1] * r2) / det;
  const double t = (facet.gram[0] * r2 - facet.gram[1] * r1) / det;
  if (!std::isfinite(s) || !std::isfinite(t)) return false;
  return lattice_point(facet, snapped(s, facet.bits), snapped(t, facet.bits), x);
}

bool Polyhedral_domain::edge_point(std::size_t e, double value, Vec3& x) const {
  const Domain_edge& edge = edges_[e];
  x = edge.p;
  if (edge.aligned) {
    x[edge.axis] = value;
    return true;
  }
  const double l = snapped((value - edge.p[edge.axis]) / edge.d[edge.axis], edge.bits);
  for (int i = 0; i < 3; ++i) x[i] = edge.p[i] + l * edge.d[i];
  return CGAL::collinear(to_point(edge.p), to_point(edge.q), to_point(x));
}

}  // namespace evomesh::tet
