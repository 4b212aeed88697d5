"""The settle step of Spacing_function::evaluate (docs/distributed-step.md, section 3.2).

f(x) = min_c (w_c + |x - c|). Every answer must be a function of the site set and
x alone: the site of least cone at x, exact ties to the lowest id, and f its cone
in double. So a graph built on any superset of the sites within u(x) of x
(u >= f, the section 3.2 lemma) answers alike, whatever the hint (the previous
query), the thread count, the kd parts, or the walk (certified or not). The cases
are built to tie: Pythagorean triples (exact ties whose double cones differ by an
ulp), lattices with equal weights, and sites moved by one ulp.
"""

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from evomesh import _core


def exact_cone_sign(a, wa, b, wb, x):
    """sign((wa + |x - a|) - (wb + |x - b|)) in rational arithmetic (doubles are exact fractions)."""
    fx, fy = Fraction(x[0]), Fraction(x[1])
    big_a = (fx - Fraction(a[0])) ** 2 + (fy - Fraction(a[1])) ** 2
    big_b = (fx - Fraction(b[0])) ** 2 + (fy - Fraction(b[1])) ** 2
    d = Fraction(wa) - Fraction(wb)

    def sign(v):
        return (v > 0) - (v < 0)

    se, sd = sign(big_a - big_b), sign(d)  # sign(sqrt A - sqrt B), sign(d)
    if se == 0:
        return sd
    if sd == 0 or sd == se:
        return se
    m = big_a + big_b - d * d  # |e|^2 - d^2 = m - 2 sqrt(AB)
    if m > 0:
        return se * sign(m * m - 4 * big_a * big_b)
    return se * (0 if m == 0 and big_a * big_b == 0 else -1)


def cones(sites, weights, x):
    """The double cones at x, by the formula evaluate reports (w + sqrt(dx*dx + dy*dy))."""
    dx = x[0] - sites[:, 0]
    dy = x[1] - sites[:, 1]
    return weights + np.sqrt(dx * dx + dy * dy)


def exact_answer(sites, weights, ids, x):
    """The site of least cone at x (exact), ties to the lowest id, among sites no other hides."""
    c = cones(sites, weights, x)
    # every site that can tie the least cone is within rounding of it
    near = np.flatnonzero(c <= c.min() * (1 + 1e-12) + 1e-300)
    best = None
    for k in near:
        if best is None:
            best = k
            continue
        s = exact_cone_sign(sites[k], weights[k], sites[best], weights[best], x)
        if s < 0 or (s == 0 and ids[k] < ids[best]):
            best = k
    return best


@st.composite
def tie_cases(draw):
    """(sites, weights, queries): sites and queries where cones tie exactly or within an ulp."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kinds = ["square", "pythagorean", "weighted-pythagorean", "lattice", "lattice-ulp", "lattice-weight-ulp"]
    kind = draw(st.sampled_from(kinds))
    if kind.startswith("lattice"):
        k = draw(st.integers(4, 11))
        h = draw(st.sampled_from([0.1, 1 / 3, 0.7, 1.0]))
        i, j = np.meshgrid(np.arange(k), np.arange(k))
        sites = np.column_stack([i.ravel() * h, j.ravel() * h]) + draw(st.sampled_from([0.0, 0.3, 1e3 / 7]))
        weights = np.full(len(sites), draw(st.sampled_from([0.0, 0.25 * h, h / 3])))
        if kind == "lattice-ulp":  # a third of the sites moved by one ulp: ties within an ulp
            moved = rng.random(len(sites)) < 0.33
            sites[moved] = np.nextafter(sites[moved], rng.choice([-np.inf, np.inf], size=(moved.sum(), 2)))
        if kind == "lattice-weight-ulp":
            # Weights a few ulps below 1 - h/4, so w + |x - c| at a cell's centre crosses 1, where the
            # ulp doubles: cones that differ exactly by an ulp of w can round to the same double.
            weights = np.full(len(sites), 1 - h / 4)
            weights -= rng.integers(0, 5, len(sites)) * np.spacing(weights)
        cell = sites.reshape(k, k, 2)
        centres = 0.5 * (cell[:-1, :-1] + cell[1:, 1:]).reshape(-1, 2)
        mids = 0.5 * (cell[:-1, :] + cell[1:, :]).reshape(-1, 2)
        queries = np.r_[centres, mids, centres + rng.uniform(-h, h, centres.shape) * 1e-15]
    elif kind == "square":
        # Squares around centres x (exact corners x + a (+-1, +-1)): every corner at the same distance,
        # weights w0 - k ulp(w0), k in 0..4, so that the cones tie within an ulp or two (w0 + a sqrt 2
        # crosses 1, where the ulp doubles).
        n_centres = draw(st.integers(1, 8))
        base = np.round(rng.uniform(-4, 4, (n_centres, 2)) * 64) / 64
        a = draw(st.sampled_from([2.0**-5, 3 * 2.0**-6, 2.0**-4]))
        w0 = 1 - a * np.sqrt(2) / 2
        corners = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], float) * a
        sites = (base[:, None, :] + corners[None]).reshape(-1, 2)
        weights = w0 - rng.integers(0, 5, len(sites)) * np.spacing(w0)
        queries = np.r_[base, np.nextafter(base, rng.choice([-np.inf, np.inf], size=base.shape))]
    else:
        # Around each of a few centres x: four sites at x + t (3, 4), (5, 0), (0, -5), (-4, 3), centres
        # on a grid of 2^-10 and t = m 2^-36 (m < 2^29): every site is exact and the tie is exact, but
        # the squares round, so the double cones can differ.
        n_centres = draw(st.integers(1, 6))
        base = np.round(rng.uniform(-1, 1, (n_centres, 2)) * draw(st.sampled_from([1.0, 10.0])) * 1024) / 1024
        site_list, weight_list = [], []
        offsets = np.array([[3, 4], [5, 0], [0, -5], [-4, 3]], float)
        for x in base:
            t = float(rng.integers(2**28, 2**29)) * 2.0**-36
            if kind == "weighted-pythagorean":
                # a fifth site at x + (0, 4t) with weight w + t: 4t + (w + t) = 5t + w exactly
                w = 2 * t
                site_list += [x + t * offsets, [x + [0.0, 4 * t]]]
                weight_list += [np.full(4, w), [w + t]]
            else:
                site_list.append(x + t * offsets)
                weight_list.append(np.full(4, draw(st.sampled_from([0.0, 0.005]))))
        sites = np.concatenate([np.asarray(s, float).reshape(-1, 2) for s in site_list])
        weights = np.concatenate([np.asarray(w, float).ravel() for w in weight_list])
        # background sites, away from the centres
        extra = rng.uniform(-12, 12, (draw(st.integers(10, 80)), 2))
        far = np.min(np.linalg.norm(extra[:, None] - base[None], axis=2), axis=1) > 0.5
        sites = np.r_[sites, extra[far]]
        weights = np.r_[weights, rng.uniform(0, 0.05, far.sum())]
        queries = np.r_[base, np.nextafter(base, rng.choice([-np.inf, np.inf], size=base.shape))]
    if draw(st.booleans()):
        # A far site with a large weight (a coarsening point): never the minimum at the queries, but it
        # raises the shift of the graph's weights (shift - w), whose rounding then hides the ulps of w.
        span = np.abs(sites).max() + 1
        sites = np.r_[sites, [[30 * span, -20 * span]]]
        weights = np.r_[weights, draw(st.sampled_from([4.0, 1e3]))]
    _, unique = np.unique(sites, axis=0, return_index=True)
    keep = np.sort(unique)
    return sites[keep], weights[keep], queries


def relevant(sites, weights, x):
    """The sites within u(x) of x, u(x) = the least double cone rounded up (the lemma of section 3.2)."""
    u = cones(sites, weights, x).min() * (1 + 1e-9)
    return np.flatnonzero(np.linalg.norm(sites - x, axis=1) <= u)


@given(tie_cases(), st.integers(0, 2**16), st.sampled_from([0, 4]), st.booleans())
def test_answer_is_the_exact_least_cone_on_any_superset_of_the_relevant_sites(case, seed, min_part, certified):
    """(1) The §3.2 lemma: any graph that holds the sites within u(x) of x gives the same f and site as
    the graph of all sites, and that site is the exact minimiser (ties: lowest id)."""
    sites, weights, queries = case
    n = len(sites)
    ids = np.arange(n)
    full = _core.SpacingFunction(sites, weights, min_part)
    f_full, s_full = full.evaluate(queries, certified=certified)
    rng = np.random.default_rng(seed)
    for q, x in enumerate(queries):
        expected = exact_answer(sites, weights, ids, x)
        assert s_full[q] == expected, (x, s_full[q], expected)
        assert f_full[q] == cones(sites[[expected]], weights[[expected]], x)[0]
    for _ in range(3):
        # a superset of every query's relevant sites, kept in id order (so the lowest index is the lowest id)
        keep = rng.random(n) < rng.uniform(0, 1)
        for x in queries:
            keep[relevant(sites, weights, x)] = True
        subset = np.flatnonzero(keep)
        part = _core.SpacingFunction(sites[subset], weights[subset], min_part)
        f_part, s_part = part.evaluate(queries, certified=certified)
        assert np.array_equal(f_part, f_full)
        assert np.array_equal(subset[s_part], s_full)


@given(tie_cases(), st.integers(0, 2**16), st.sampled_from([0, 4]))
def test_answer_does_not_depend_on_the_hint_threads_or_walk(case, seed, min_part):
    """(2) and (3): a query alone, among others in any order (other hints), on 1 or 2 threads,
    certified or not: the same bits."""
    sites, weights, queries = case
    function = _core.SpacingFunction(sites, weights, min_part)
    reference, reference_site = function.evaluate(queries, threads=1, certified=True)
    rng = np.random.default_rng(seed)
    others = np.r_[sites, rng.uniform(sites.min(axis=0), sites.max(axis=0), (300, 2))]
    for certified in (True, False):
        for threads in (1, 2):
            order = rng.permutation(len(queries) + len(others))
            batch = np.r_[queries, others][order]
            f, s = function.evaluate(batch, threads=threads, certified=certified)
            back = np.argsort(order)[: len(queries)]
            assert np.array_equal(f[back], reference)
            assert np.array_equal(s[back], reference_site)
        for q in range(0, len(queries), max(1, len(queries) // 8)):
            f, s = function.evaluate(queries[q : q + 1], certified=certified)
            assert f[0] == reference[q] and s[0] == reference_site[q]


@given(tie_cases(), st.integers(0, 2**16))
def test_ties_go_to_the_lowest_global_id_in_any_site_order(case, seed):
    """With site_ids, the sites stored in any order (and any superset) give the same site by id."""
    sites, weights, queries = case
    rng = np.random.default_rng(seed)
    ids = rng.permutation(len(sites)) * 7 + 3
    full = _core.SpacingFunction(sites, weights, site_ids=ids)
    f_full, s_full = full.evaluate(queries, certified=False)
    for q, x in enumerate(queries):
        assert s_full[q] == exact_answer(sites, weights, ids, x)
    order = rng.permutation(len(sites))
    shuffled = _core.SpacingFunction(sites[order], weights[order], 4, site_ids=ids[order])
    for certified in (True, False):
        f, s = shuffled.evaluate(queries, certified=certified)
        assert np.array_equal(f, f_full)
        assert np.array_equal(order[s], s_full)


def test_site_ids_are_checked():
    sites = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="one id per site"):
        _core.SpacingFunction(sites, np.zeros(3), site_ids=np.arange(2))
    with pytest.raises(ValueError, match="distinct"):
        _core.SpacingFunction(sites, np.zeros(3), site_ids=np.array([1, 2, 1]))


def test_equidistant_sites_on_a_circle():
    """Many sites tie at the centre (a regular polygon, equal weights): the lowest id wins on every path."""
    k = 64
    angle = 2 * np.pi * np.arange(k) / k
    sites = np.column_stack([np.cos(angle), np.sin(angle)])
    sites = np.r_[sites, [[5.0, 5.0], [-5.0, 4.0]]]
    weights = np.zeros(len(sites))
    x = np.zeros((1, 2))
    expected = exact_answer(sites, weights, np.arange(len(sites)), x[0])
    for min_part in (0, 4):
        function = _core.SpacingFunction(sites, weights, min_part)
        for certified in (True, False):
            assert function.evaluate(x, certified=certified)[1][0] == expected
