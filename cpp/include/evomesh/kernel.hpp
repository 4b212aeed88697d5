// Kernel typedefs in one place: exact predicates, inexact constructions.
#pragma once

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include "evomesh/types.hpp"

namespace evomesh {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point_2 = Kernel::Point_2;

inline Point_2 to_cgal(const Vec2& p) { return Point_2(p[0], p[1]); }

// Exact sign of the orientation of (a, b, c): +1 counter-clockwise, -1 clockwise, 0 collinear.
inline int orientation(const Vec2& a, const Vec2& b, const Vec2& c) {
  return static_cast<int>(CGAL::orientation(to_cgal(a), to_cgal(b), to_cgal(c)));
}

}  // namespace evomesh
