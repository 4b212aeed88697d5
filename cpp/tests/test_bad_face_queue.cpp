// The mesher's queue of bad faces (detail/delaunay_mesher.hpp, Bad_face_queue)
// against a reference kept in a std::set ordered as the queue promises (quality,
// then the three vertices' points in order, lexicographically): random pushes
// (with many equal qualities), removals, pops and clears on the faces of a real
// triangulation, enough removals to make it compact, and faces the
// triangulation destroys and reuses while entries of them are still queued; and
// the face base keeps CGAL's time stamps distinct.
#include <array>
#include <cstdio>
#include <map>
#include <random>
#include <set>
#include <tuple>
#include <utility>
#include <vector>

#include "check.hpp"
#include "evomesh/detail/delaunay_mesher.hpp"

namespace {

using evomesh::detail::Bad_face_queue;
using evomesh::detail::Cdt;
using evomesh::detail::Face_handle;
using evomesh::Point_2;

using Key = std::tuple<double, Point_2, Point_2, Point_2>;

Key key_of(const Face_handle& f, double q) {
  return {q, f->vertex(0)->point(), f->vertex(1)->point(), f->vertex(2)->point()};
}

// The reference: the queued faces by key, and each queued face's key.
struct Reference {
  std::set<std::pair<Key, Face_handle>> order;
  std::map<Face_handle, Key> key;
  void push(const Face_handle& f, double q) {
    if (key.count(f) != 0) return;
    key[f] = key_of(f, q);
    order.insert({key[f], f});
  }
  void erase(const Face_handle& f) {
    const auto it = key.find(f);
    if (it == key.end()) return;
    order.erase({it->second, f});
    key.erase(it);
  }
};

// Pops everything: the faces come out in the reference's order, then the queue is empty.
void drain_in_order(Bad_face_queue& queue, Reference& reference) {
  while (!reference.order.empty()) {
    const Face_handle front = reference.order.begin()->second;
    CHECK(!queue.empty());
    if (queue.empty()) return;
    CHECK(queue.front_face() == front);
    queue.pop_front();
    reference.erase(front);
  }
  CHECK(queue.empty());
}

std::vector<Face_handle> finite_faces(Cdt& cdt) {
  std::vector<Face_handle> faces;
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) faces.push_back(f);
  return faces;
}

// Random operations on a triangulation's faces; the queue's front, emptiness and
// membership checked against the reference after each.
void random_operations(unsigned seed, int n_points, int n_operations, bool with_clears) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> coordinate(0.0, 1.0);
  Cdt cdt;
  // a lattice (cocircular points, equal shapes) plus random points
  for (int i = 0; i < n_points / 2; ++i) cdt.insert(Point_2(i % 30, i / 30));
  for (int i = 0; i < n_points / 2; ++i) cdt.insert(Point_2(30 * coordinate(rng), 30 * coordinate(rng)));
  const auto faces = finite_faces(cdt);
  Bad_face_queue queue;
  Reference reference;
  std::uniform_int_distribution<std::size_t> pick(0, faces.size() - 1);
  std::uniform_int_distribution<int> quality_class(0, 3);  // few values: many ties
  std::uniform_int_distribution<int> operation(0, 99);
  for (int step = 0; step < n_operations; ++step) {
    const int op = operation(rng);
    const Face_handle f = faces[pick(rng)];
    if (op < 45) {
      const double q = 0.1 * quality_class(rng);
      queue.push(f, q);
      reference.push(f, q);
    } else if (op < 75) {
      queue.erase(f);
      reference.erase(f);
    } else if (op < 99 || !with_clears) {
      if (!reference.order.empty()) {
        const Face_handle front = reference.order.begin()->second;
        CHECK(queue.front_face() == front) << "step " << step;
        queue.pop_front();
        reference.erase(front);
      }
    } else {
      queue.clear();
      reference = Reference();
    }
    CHECK(queue.empty() == reference.order.empty()) << "step " << step;
    CHECK(queue.contains(f) == (reference.key.count(f) != 0)) << "step " << step;
    if (!reference.order.empty()) {
      CHECK(queue.front_face() == reference.order.begin()->second) << "step " << step;
      CHECK(queue.front_quality() == std::get<0>(reference.order.begin()->first)) << "step " << step;
    }
  }
  drain_in_order(queue, reference);
}

// Entries of faces that the triangulation destroys (after leaving the queue, as
// the mesher's levels do before an insertion) and then reuses for new faces are
// never given out; the new faces queue and come out in order.
void destroyed_and_reused_faces() {
  Cdt cdt;
  for (int i = 0; i < 400; ++i) cdt.insert(Point_2(i % 20, i / 20));
  Bad_face_queue queue;
  Reference reference;
  for (const Face_handle& f : finite_faces(cdt)) {
    queue.push(f, 0.5);
    reference.push(f, 0.5);
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coordinate(1.0, 18.0);
  for (int round = 0; round < 200; ++round) {
    const Point_2 p(coordinate(rng) + 0.25, coordinate(rng) + 0.125);
    std::vector<Face_handle> conflicts;
    cdt.get_conflicts(p, std::back_inserter(conflicts));
    for (const Face_handle& f : conflicts) {
      queue.erase(f);
      reference.erase(f);
    }
    const auto v = cdt.insert(p);
    auto f = cdt.incident_faces(v), done = f;
    do {
      if (!cdt.is_infinite(f)) {
        const double q = 0.25 * (round % 3);
        queue.push(f, q);
        reference.push(f, q);
      }
    } while (++f != done);
    if (round % 5 == 0 && !reference.order.empty()) {
      const Face_handle front = reference.order.begin()->second;
      CHECK(queue.front_face() == front) << "round " << round;
      queue.pop_front();
      reference.erase(front);
    }
  }
  drain_in_order(queue, reference);
}

// The queue's face base keeps CGAL's time stamps: every face of a triangulation
// (created by any of the container's constructors, also after removals and
// reuse) has its own, so handles compare as CGAL expects (by time stamp).
void faces_have_distinct_time_stamps() {
  Cdt cdt;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> coordinate(0.0, 1.0);
  std::vector<evomesh::detail::Vertex_handle> vertices;
  for (int i = 0; i < 2000; ++i) vertices.push_back(cdt.insert(Point_2(coordinate(rng), coordinate(rng))));
  cdt.insert_constraint(Point_2(0.1, 0.1), Point_2(0.9, 0.8));
  for (int i = 0; i < 500; i += 3) cdt.remove(vertices[i]);
  std::set<std::size_t> stamps;
  std::size_t n_faces = 0;
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) {
    ++n_faces;
    stamps.insert(f->time_stamp());
    CHECK(f->queue_entry == 0);
  }
  CHECK(stamps.size() == n_faces) << stamps.size() << " distinct time stamps for " << n_faces << " faces";
  CHECK(stamps.count(std::size_t(-1)) == 0);
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    for (unsigned seed = 1; seed <= 4; ++seed) random_operations(seed, 400, 20000, seed % 2 == 0);
    // many faces, most of them removed: the heap compacts several times
    random_operations(11, 20000, 200000, false);
    destroyed_and_reused_faces();
    faces_have_distinct_time_stamps();
  });
}
