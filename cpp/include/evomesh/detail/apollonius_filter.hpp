// The interval filter of the Apollonius graph's predicates, without exceptions.
//
// CGAL's filtered traits evaluate every predicate in interval arithmetic first
// and, where a comparison cannot be decided, throw (Uncertain_conversion_exception)
// out of the predicate and evaluate it again exactly. On inputs with exact
// degeneracies (lattices, equal weights on cocircular sites: meshes that start
// from a structured grid) that happens about once per inserted site, and a throw
// and its unwinding cost more than the exact evaluation: a fifth of the graph's
// construction on the front benchmark (971,843 throws in one 1e6 step).
//
// Here the same interval evaluation runs on `Flagged_interval`, whose comparisons
// return a plain bool: an undecided one sets a per-thread flag and answers false.
// The filtered predicate (the specialisation of CGAL::Filtered_predicate below,
// selected by the converter type To_flagged_interval) returns the interval
// answer only when no comparison was undecided, else the exact one. So every
// predicate returns what CGAL's filtered traits return (the interval answer when
// it is certain, the exact one otherwise): the same graph, bit for bit.
// Internal: include from spacing.cpp only.
#pragma once

#include <CGAL/Apollonius_graph_filtered_traits_2.h>
#include <CGAL/Cartesian_converter.h>
#include <CGAL/FPU.h>
#include <CGAL/Interval_nt.h>
#include <CGAL/Simple_cartesian.h>

#include <cstddef>
#include <utility>

namespace evomesh::detail {

// Set when a comparison of Flagged_interval values could not be decided (the
// predicate's interval answer is then not trusted). Per thread: graphs are
// built and queried on several threads. (The default TLS model: the
// initial-exec one would save a __tls_get_addr call per predicate, 2-4 % of
// the graph on random sites, but can make a dlopen'ed module fail to load.)
inline thread_local bool interval_undecided = false;
// Predicates this thread evaluated exactly because the interval answer was not
// certain (for tests and diagnostics).
inline thread_local std::size_t exact_evaluations = 0;

// Interval arithmetic (CGAL::Interval_nt<false>: needs rounding towards +inf,
// which the filtered predicate sets) whose comparisons never throw.
class Flagged_interval {
 public:
  using Interval = CGAL::Interval_nt<false>;
  Flagged_interval() : value_(0) {}
  Flagged_interval(int i) : value_(i) {}     // NOLINT: literals in CGAL's formulas
  Flagged_interval(double d) : value_(d) {}  // NOLINT
  explicit Flagged_interval(const Interval& v) : value_(v) {}
  const Interval& interval() const { return value_; }

  Flagged_interval& operator+=(const Flagged_interval& o) {
    value_ += o.value_;
    return *this;
  }
  Flagged_interval& operator-=(const Flagged_interval& o) {
    value_ -= o.value_;
    return *this;
  }
  Flagged_interval& operator*=(const Flagged_interval& o) {
    value_ *= o.value_;
    return *this;
  }
  friend Flagged_interval operator+(const Flagged_interval& a, const Flagged_interval& b) {
    return Flagged_interval(a.value_ + b.value_);
  }
  friend Flagged_interval operator-(const Flagged_interval& a, const Flagged_interval& b) {
    return Flagged_interval(a.value_ - b.value_);
  }
  friend Flagged_interval operator*(const Flagged_interval& a, const Flagged_interval& b) {
    return Flagged_interval(a.value_ * b.value_);
  }
  friend Flagged_interval operator-(const Flagged_interval& a) { return Flagged_interval(-a.value_); }
  friend Flagged_interval operator+(const Flagged_interval& a) { return a; }

  friend bool operator<(const Flagged_interval& a, const Flagged_interval& b) { return decide(a.value_ < b.value_); }
  friend bool operator>(const Flagged_interval& a, const Flagged_interval& b) { return decide(a.value_ > b.value_); }
  friend bool operator<=(const Flagged_interval& a, const Flagged_interval& b) {
    return decide(a.value_ <= b.value_);
  }
  friend bool operator>=(const Flagged_interval& a, const Flagged_interval& b) {
    return decide(a.value_ >= b.value_);
  }
  friend bool operator==(const Flagged_interval& a, const Flagged_interval& b) {
    return decide(a.value_ == b.value_);
  }
  friend bool operator!=(const Flagged_interval& a, const Flagged_interval& b) {
    return decide(a.value_ != b.value_);
  }

  // The certain value of `u`, or (undecided) false with the flag set.
  template <class T>
  static T decide(const CGAL::Uncertain<T>& u, T otherwise = T()) {
    if (u.is_certain()) return u.make_certain();
    interval_undecided = true;
    return otherwise;
  }

 private:
  Interval value_;
};

// double -> Flagged_interval (exact: a point interval).
struct To_flagged_interval {
  using argument_type = double;
  using result_type = Flagged_interval;
  Flagged_interval operator()(double d) const { return Flagged_interval(d); }
};

}  // namespace evomesh::detail

namespace CGAL {

template <>
class Algebraic_structure_traits<evomesh::detail::Flagged_interval>
    : public Algebraic_structure_traits_base<evomesh::detail::Flagged_interval, Integral_domain_without_division_tag> {
 public:
  typedef Tag_false Is_exact;
  typedef Tag_true Is_numerical_sensitive;
  // As for Interval_nt: the square of an interval (tighter and cheaper than a
  // product), as CGAL's formulas (CGAL::square) get it there.
  struct Square : CGAL::cpp98::unary_function<evomesh::detail::Flagged_interval, evomesh::detail::Flagged_interval> {
    evomesh::detail::Flagged_interval operator()(const evomesh::detail::Flagged_interval& x) const {
      return evomesh::detail::Flagged_interval(CGAL::square(x.interval()));
    }
  };
  struct Is_zero : CGAL::cpp98::unary_function<evomesh::detail::Flagged_interval, bool> {
    bool operator()(const evomesh::detail::Flagged_interval& x) const {
      return evomesh::detail::Flagged_interval::decide(CGAL::is_zero(x.interval()));
    }
  };
};

template <>
class Real_embeddable_traits<evomesh::detail::Flagged_interval>
    : public INTERN_RET::Real_embeddable_traits_base<evomesh::detail::Flagged_interval, Tag_true> {
  using Type = evomesh::detail::Flagged_interval;

 public:
  struct Sgn : CGAL::cpp98::unary_function<Type, CGAL::Sign> {
    CGAL::Sign operator()(const Type& x) const { return Type::decide(CGAL::sign(x.interval()), CGAL::ZERO); }
  };
  struct Compare : CGAL::cpp98::binary_function<Type, Type, Comparison_result> {
    Comparison_result operator()(const Type& a, const Type& b) const {
      return Type::decide(CGAL::compare(a.interval(), b.interval()), CGAL::EQUAL);
    }
  };
  struct Is_zero : CGAL::cpp98::unary_function<Type, bool> {
    bool operator()(const Type& x) const { return Type::decide(CGAL::is_zero(x.interval())); }
  };
  struct Is_positive : CGAL::cpp98::unary_function<Type, bool> {
    bool operator()(const Type& x) const { return Type::decide(CGAL::is_positive(x.interval())); }
  };
  struct Is_negative : CGAL::cpp98::unary_function<Type, bool> {
    bool operator()(const Type& x) const { return Type::decide(CGAL::is_negative(x.interval())); }
  };
  struct Abs : CGAL::cpp98::unary_function<Type, Type> {
    Type operator()(const Type& x) const { return Type(CGAL::abs(x.interval())); }
  };
  struct To_double : CGAL::cpp98::unary_function<Type, double> {
    double operator()(const Type& x) const { return CGAL::to_double(x.interval()); }
  };
  struct To_interval : CGAL::cpp98::unary_function<Type, std::pair<double, double>> {
    std::pair<double, double> operator()(const Type& x) const { return x.interval().pair(); }
  };
  struct Is_finite : CGAL::cpp98::unary_function<Type, bool> {
    bool operator()(const Type& x) const { return CGAL::is_finite(x.interval()); }
  };
};

}  // namespace CGAL

namespace evomesh::detail {

using Flagged_kernel = CGAL::Simple_cartesian<Flagged_interval>;
// Kernel (doubles) -> Flagged_kernel: the converter type by which the
// Filtered_predicate specialisation below recognises these traits.
template <class Kernel>
using To_flagged_kernel = CGAL::Cartesian_converter<Kernel, Flagged_kernel, To_flagged_interval>;

// The Apollonius graph traits of spacing.cpp: `Kernel` (doubles) filtered by
// Flagged_kernel, exact with `Exact_kernel`.
template <class Kernel, class Exact_kernel>
using Apollonius_traits_without_throws = CGAL::Apollonius_graph_filtered_traits_2<
    Kernel, CGAL::Integral_domain_without_division_tag, Exact_kernel, CGAL::Integral_domain_without_division_tag,
    Flagged_kernel, CGAL::Integral_domain_without_division_tag, CGAL::Cartesian_converter<Kernel, Exact_kernel>,
    To_flagged_kernel<Kernel>>;

}  // namespace evomesh::detail

namespace CGAL {

// CGAL's Filtered_predicate for the predicates of Apollonius_traits_without_throws
// (recognised by their converter to Flagged_kernel): the interval answer when
// every comparison in it was decided, else the exact answer. Any exception from
// the interval evaluation (a CGAL check on a branch taken by an undecided
// comparison) also falls back to the exact one.
template <class EP, class AP, class C2E, class K1, class K2, bool Protection>
class Filtered_predicate<
    EP, AP, C2E,
    ApolloniusGraph_2::Apollonius_graph_cartesian_converter<K1, K2, evomesh::detail::To_flagged_kernel<typename K1::Base>>,
    Protection> {
  using C2A =
      ApolloniusGraph_2::Apollonius_graph_cartesian_converter<K1, K2, evomesh::detail::To_flagged_kernel<typename K1::Base>>;
  C2E c2e;
  C2A c2a;
  EP ep;
  AP ap;

 public:
  typedef AP Approximate_predicate;
  typedef EP Exact_predicate;
  typedef C2E To_exact_converter;
  typedef C2A To_approximate_converter;
  typedef typename EP::result_type result_type;
  // What spacing.cpp checks at compile time: this specialisation, not CGAL's
  // primary template (which would trust an undecided interval answer here).
  static constexpr bool checks_undecided_comparisons = true;

  Filtered_predicate() {}

  template <typename... Args>
  result_type operator()(const Args&... args) const {
    {
      Protect_FPU_rounding<Protection> p;
      bool& undecided = evomesh::detail::interval_undecided;  // one TLS lookup per predicate
      undecided = false;
      try {
        const result_type res = ap(c2a(args)...);
        if (!undecided) return res;
      } catch (...) {
      }
    }
    ++evomesh::detail::exact_evaluations;
    Protect_FPU_rounding<!Protection> p(CGAL_FE_TONEAREST);
    return ep(c2e(args)...);
  }
};

}  // namespace CGAL
